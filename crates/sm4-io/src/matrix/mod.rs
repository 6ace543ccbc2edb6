//! Omicron MATRIX image reader: a data file (`<session>--<run>_<cycle>.<channel>_mtrx`, e.g.
//! `20201111--4_1.Z_mtrx`) read together with the session's parameter file
//! (`<session>_0001.mtrx`, continued in `_0002.mtrx` …), which holds the scan size, raster
//! timing and the transfer function from stored counts to physical units.
//!
//! [`crate::read_path`] finds the parameter file beside the data file and names it when it
//! is missing; [`crate::read_bytes`] has only one file and refuses with
//! [`ReadError::Unsupported`] saying so; [`read_pair`] reads both from memory.
//!
//! # Data file
//!
//! After the identifier `ONTMATRX0101`, a `TLKB` block (tag, `u32` length, 8-byte time, 4
//! more bytes) holds sub-blocks: `CSED` (its bytes 24..28 are the count of stored values)
//! and `ATAD` (the values, little-endian `i32`). Other tags carry an 8-byte time too.
//!
//! # Image layout (as in the maintained reader `access2thematrix`)
//!
//! The values are lines of `XYScanner.Points` samples. With `XYScanner.X_Retrace` each
//! forward line is followed by its backward line, stored in acquisition order (right to
//! left, so dhct reverses it). The first `XYScanner.Lines` lines (or line pairs) scan
//! **upwards**: the first is the bottom row. With `XYScanner.Y_Retrace` the next `Lines`
//! scan downwards from the top row. A scan stopped early stores fewer values; lines never
//! completed are NaN. dhct returns one [`ScanPair`] per slow direction: the channel name for
//! the upward frame (slow [`ScanDirection::Up`], frame 0) and `<name> down` for the
//! downward one (frame 1: recorded after it, so another frame of a series).
//!
//! # Calibration and timing
//!
//! Values = transfer function of the channel (the `TCID` entry named like the file's
//! channel, highest key): `TFF_Linear1D` (raw − Offset) / Factor; `TFF_MultiLinear1D`
//! (Raw_1 − PreOffset)(raw − Offset) / (NeutralFactor · PreFactor). Other transfer
//! functions are refused. Pitch = `XYScanner.Width` / `Points` and `Height` / `Lines`;
//! pixel period = `XYScanner.Raster_Time`; turnaround = the mean of `Line_Start_Delay` and
//! `Line_End_Delay`; scan angle = `XYScanner.Angle` (degrees); offset = `X_Offset`,
//! `Y_Offset`.

mod parameters;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use dhct_scan::{FileFormat, ImageChannel, ScanDirection, ScanGeometry, ScanPair};

use crate::bytes::ByteReader;
use crate::limits::{Budget, ReadLimits};
use crate::placeholders::{
    PLAUSIBLE_PITCH_M, PLAUSIBLE_PIXEL_PERIOD_S, PLAUSIBLE_SCAN_ANGLE_RAD, PLAUSIBLE_TURNAROUND_S,
    plausible,
};
use crate::{ReadError, ScanFile};

pub use parameters::{FILE_ID, Parameters, Transfer, Value, replay};

const FORMAT: FileFormat = FileFormat::OmicronMatrix;
/// Largest `Points` or `Lines` dhct accepts.
const MAX_SIDE: f64 = 65536.0;

/// True when `bytes` start like a MATRIX file (data or parameter file).
pub fn looks_like_matrix(bytes: &[u8]) -> bool {
    bytes.starts_with(FILE_ID)
}

/// True when `bytes` are a MATRIX data file (its first block is `TLKB`).
pub fn is_data_file(bytes: &[u8]) -> bool {
    looks_like_matrix(bytes)
        && bytes.get(FILE_ID.len()..FILE_ID.len() + 4) == Some(b"TLKB".as_slice())
}

/// The parameter files of the data file at `path`: `<session>_0001.mtrx`, `_0002.mtrx` …
/// beside it, for as long as they exist (the first is returned even if missing, so the
/// caller can name it).
pub fn parameter_paths(path: &Path) -> Result<Vec<PathBuf>, ReadError> {
    let name = file_name(path)?;
    let session = name.rsplit_once("--").map(|(s, _)| s).ok_or_else(|| {
        ReadError::unsupported(
            FORMAT,
            format!(
                "the data file name \"{name}\" lacks the \"<session>--<run>_<cycle>.<channel>_mtrx\" \
                 form that links it to its parameter file"
            ),
        )
    })?;
    let link = |k: usize| path.with_file_name(format!("{session}_{k:04}.mtrx"));
    let mut paths = vec![link(1)];
    while paths.len() < 1000 && link(paths.len() + 1).is_file() {
        paths.push(link(paths.len() + 1));
    }
    Ok(paths)
}

fn file_name(path: &Path) -> Result<&str, ReadError> {
    path.file_name()
        .and_then(|n| n.to_str())
        .ok_or_else(|| ReadError::unsupported(FORMAT, "the data file name is not valid UTF-8 text"))
}

/// The channel named by a data file name: `…--4_1.Z_mtrx` → `Z`.
fn channel_of(data_file: &str) -> Result<&str, ReadError> {
    let tail = data_file.rsplit_once("--").map_or(data_file, |(_, t)| t);
    tail.split_once('.')
        .and_then(|(_, ext)| ext.strip_suffix("_mtrx"))
        .filter(|c| !c.is_empty())
        .ok_or_else(|| {
            ReadError::unsupported(
                FORMAT,
                format!("cannot tell the channel from the file name \"{data_file}\""),
            )
        })
}

/// Reads the data file `data` named `data_file` (its file name, which the parameter file
/// refers to) with the session's parameter file(s) `parameters` (the continuation files
/// appended without their 12-byte identifiers, or given whole: see [`read_files`]).
pub fn read_pair(
    data: &[u8],
    data_file: &str,
    parameters: &[u8],
    limits: &ReadLimits,
) -> Result<ScanFile, ReadError> {
    let mut budget = Budget::new(limits, data.len().saturating_add(parameters.len()))?;
    let channel = channel_of(data_file)?;
    if channel.contains('(') {
        return Err(ReadError::unsupported(
            FORMAT,
            format!("\"{channel}\" is a spectroscopy channel, not an image"),
        ));
    }
    let params = replay(parameters, data_file)?;
    if !params.found_data_file {
        return Err(ReadError::corrupt(
            FORMAT,
            format!("the parameter file never mentions the data file \"{data_file}\""),
        ));
    }
    let raw = stored_values(data)?;
    let layout = Layout::from_parameters(&params, raw.len())?;
    let images = if layout.x_retrace { 2 } else { 1 } * if layout.y_retrace { 2 } else { 1 };
    // Each image, plus the f64 copy of every stored value it is cut from.
    budget.charge_images(FORMAT, layout.columns as u64, layout.rows as u64, images, 8)?;
    let (unit, scale, offset) = transfer_for(&params, channel)?;
    let values: Vec<f64> = raw
        .chunks_exact(4)
        .map(|c| (f64::from(i32_of(c)) - offset) * scale)
        .collect();
    let mut pairs = Vec::new();
    for (up, name) in [
        (true, channel.to_string()),
        (false, format!("{channel} down")),
    ] {
        if !up && !layout.y_retrace {
            continue;
        }
        let slow = if up {
            ScanDirection::Up
        } else {
            ScanDirection::Down
        };
        // The downward frame is recorded after the upward one: the file's second frame.
        let geometry = layout.geometry(&params, slow)?.with_frame(usize::from(!up));
        let trace = layout.image(&values, up, false, &name, &unit)?;
        let retrace = if layout.x_retrace {
            Some(layout.image(&values, up, true, &name, &unit)?)
        } else {
            None
        };
        pairs.push(
            ScanPair::new(geometry, trace, retrace)
                .map_err(|source| ReadError::geometry(FORMAT, source))?,
        );
    }
    Ok(ScanFile {
        format: FORMAT,
        pairs,
        metadata: metadata(&params, &layout, channel),
    })
}

/// Reads the data file at `path` and its parameter file(s) beside it, under `limits`.
pub fn read_files(path: &Path, data: &[u8], limits: &ReadLimits) -> Result<ScanFile, ReadError> {
    let mut parameters = Vec::new();
    for (k, parameter_path) in parameter_paths(path)?.iter().enumerate() {
        let left = limits
            .max_bytes
            .saturating_sub((data.len() + parameters.len()) as u64);
        let bytes =
            crate::limits::read_regular_file(parameter_path, left).map_err(|e| match e {
                ReadError::Open { path, source }
                    if source.kind() == std::io::ErrorKind::NotFound =>
                {
                    ReadError::MissingCompanion {
                        format: FORMAT,
                        path,
                        what: "parameter file",
                    }
                }
                other => other,
            })?;
        let body = if k == 0 {
            &bytes[..]
        } else {
            bytes.get(FILE_ID.len()..).unwrap_or(&[])
        };
        parameters.extend_from_slice(body);
    }
    read_pair(data, file_name(path)?, &parameters, limits)
}

/// What reading a MATRIX file from memory alone gives: always an error, since a data file
/// needs its parameter file (use [`crate::read_path`] or [`read_pair`]) and a parameter file
/// holds no image.
pub fn read_alone(bytes: &[u8]) -> Result<ScanFile, ReadError> {
    stored_values(bytes)?;
    Err(ReadError::unsupported(
        FORMAT,
        "a MATRIX data file cannot be read alone: its size, timing and z calibration are in          the session's parameter file (<session>_0001.mtrx); read it by path so dhct finds          that file beside it",
    ))
}

fn i32_of(c: &[u8]) -> i32 {
    i32::from_le_bytes([c[0], c[1], c[2], c[3]])
}

/// The `ATAD` bytes of a data file (whole `i32` values only), after checking the blocks.
fn stored_values(data: &[u8]) -> Result<&[u8], ReadError> {
    if !data.starts_with(FILE_ID) {
        return Err(ReadError::wrong_format(
            FORMAT,
            "the data file does not start with ONTMATRX0101",
        ));
    }
    if !is_data_file(data) {
        return Err(ReadError::unsupported(
            FORMAT,
            "this is a MATRIX parameter file, not a data file: open one of the session's \
             *_mtrx data files (e.g. …--1_1.Z_mtrx), which dhct reads with this file",
        ));
    }
    let mut reader = ByteReader::new(data, FORMAT);
    reader.seek(FILE_ID.len() as u64 + 4, "data block")?;
    let len = u64::from(reader.u32_le("data block length")?);
    let start = reader.position() as u64;
    let block = reader.slice_at(start, len.saturating_add(8), "data block")?;
    let mut inner = ByteReader::new(block, FORMAT);
    inner.seek(12, "data block header")?;
    let mut count: Option<u64> = None;
    while inner.position() < block.len() {
        let tag = inner.take(4, "data sub-block tag")?;
        let len = u64::from(inner.u32_le("data sub-block length")?);
        let untimed = tag == b"CSED" || tag == b"ATAD";
        let content = inner.take(
            if untimed { len } else { len.saturating_add(8) },
            "data sub-block",
        )?;
        match tag {
            b"CSED" => {
                let mut desc = ByteReader::new(content, FORMAT);
                desc.seek(24, "stored value count")?;
                let n = desc.i32_le("stored value count")?;
                count = Some(u64::try_from(n).map_err(|_| {
                    ReadError::corrupt(FORMAT, format!("stored value count {n} is negative"))
                })?);
            }
            b"ATAD" => {
                let n = count.ok_or_else(|| {
                    ReadError::corrupt(FORMAT, "the data come before their description")
                })?;
                let bytes = n.saturating_mul(4);
                return content
                    .get(..bytes as usize)
                    .filter(|_| bytes <= content.len() as u64)
                    .ok_or(ReadError::Truncated {
                        format: FORMAT,
                        what: format!("{n} stored values"),
                        offset: 0,
                        needed: bytes,
                        len: content.len() as u64,
                    });
            }
            _ => {}
        }
    }
    Err(ReadError::NoImage {
        format: FORMAT,
        reason: "the data file holds no ATAD data block".to_string(),
    })
}

/// The channel's unit, and the scale and offset of its transfer function:
/// value = (counts − offset) · scale.
fn transfer_for(params: &Parameters, channel: &str) -> Result<(String, f64, f64), ReadError> {
    let (key, (_, unit)) = params
        .channels
        .iter()
        .filter(|(_, (name, _))| name == channel)
        .max_by_key(|(key, _)| **key)
        .ok_or_else(|| {
            ReadError::corrupt(
                FORMAT,
                format!("the channel dictionary has no channel \"{channel}\""),
            )
        })?;
    let transfer = params.transfers.get(key).ok_or_else(|| {
        ReadError::corrupt(
            FORMAT,
            format!("no transfer function for channel \"{channel}\""),
        )
    })?;
    let p = |name: &str| {
        transfer
            .parameters
            .get(name)
            .copied()
            .filter(|v| v.is_finite())
            .ok_or_else(|| {
                ReadError::corrupt(
                    FORMAT,
                    format!("transfer function {} lacks a finite {name}", transfer.name),
                )
            })
    };
    let (scale, offset) = match transfer.name.as_str() {
        "TFF_Linear1D" => (1.0 / p("Factor")?, p("Offset")?),
        "TFF_MultiLinear1D" => (
            (p("Raw_1")? - p("PreOffset")?) / (p("NeutralFactor")? * p("PreFactor")?),
            p("Offset")?,
        ),
        other => {
            return Err(ReadError::unsupported(
                FORMAT,
                format!("transfer function \"{other}\" of channel \"{channel}\""),
            ));
        }
    };
    if !(scale.is_finite() && scale != 0.0) {
        return Err(ReadError::corrupt(
            FORMAT,
            format!("transfer function {} has no usable scale", transfer.name),
        ));
    }
    Ok((unit.clone(), scale, offset))
}

/// How the stored values fill the frame.
#[derive(Debug, Clone)]
struct Layout {
    columns: usize,
    rows: usize,
    x_retrace: bool,
    y_retrace: bool,
    /// Complete lines (or forward/backward line pairs) stored.
    lines_stored: usize,
}

impl Layout {
    fn from_parameters(params: &Parameters, stored_bytes: usize) -> Result<Layout, ReadError> {
        let count = |key: &str| {
            params
                .number(key)
                .filter(|v| v.fract() == 0.0 && (1.0..=MAX_SIDE).contains(v))
                .map(|v| v as usize)
                .ok_or_else(|| {
                    ReadError::corrupt(
                        FORMAT,
                        format!("{key} is missing or not a count from 1 to {MAX_SIDE}"),
                    )
                })
        };
        let flag = |key: &str| params.number(key).is_some_and(|v| v != 0.0);
        let (columns, rows) = (count("XYScanner.Points")?, count("XYScanner.Lines")?);
        let x_retrace = flag("XYScanner.X_Retrace");
        let per_line = columns * if x_retrace { 2 } else { 1 };
        let lines_stored = stored_bytes / 4 / per_line;
        Ok(Layout {
            columns,
            rows,
            x_retrace,
            y_retrace: flag("XYScanner.Y_Retrace") && lines_stored > rows,
            lines_stored,
        })
    }

    /// One image in display orientation; lines never stored are NaN.
    fn image(
        &self,
        values: &[f64],
        up: bool,
        backward: bool,
        name: &str,
        unit: &str,
    ) -> Result<ImageChannel, ReadError> {
        let (columns, rows) = (self.columns, self.rows);
        let per_line = columns * if self.x_retrace { 2 } else { 1 };
        let mut z = vec![f64::NAN; columns * rows];
        for k in 0..rows {
            let stored = if up { k } else { rows + k };
            if stored >= self.lines_stored {
                break;
            }
            let row = if up { rows - 1 - k } else { k };
            let start = stored * per_line + if backward { columns } else { 0 };
            let line = &values[start..start + columns];
            let target = &mut z[row * columns..(row + 1) * columns];
            if backward {
                target
                    .iter_mut()
                    .zip(line.iter().rev())
                    .for_each(|(t, v)| *t = *v);
            } else {
                target.copy_from_slice(line);
            }
        }
        ImageChannel::from_row_major(name, unit, rows, columns, z)
            .map_err(|source| ReadError::geometry(FORMAT, source))
    }

    fn geometry(
        &self,
        params: &Parameters,
        slow: ScanDirection,
    ) -> Result<ScanGeometry, ReadError> {
        let size = |key: &str, n: usize| {
            params
                .number(key)
                .map(|v| v.abs() / n as f64)
                .filter(|p| plausible(*p, &PLAUSIBLE_PITCH_M))
                .ok_or_else(|| {
                    ReadError::corrupt(FORMAT, format!("{key} gives no plausible pixel pitch"))
                })
        };
        let period = params
            .number("XYScanner.Raster_Time")
            .filter(|t| plausible(*t, &PLAUSIBLE_PIXEL_PERIOD_S))
            .ok_or_else(|| {
                ReadError::corrupt(
                    FORMAT,
                    "XYScanner.Raster_Time gives no plausible pixel period",
                )
            })?;
        let delay = |key: &str| params.number(key).unwrap_or(0.0);
        let turnaround =
            (delay("XYScanner.Line_Start_Delay") + delay("XYScanner.Line_End_Delay")) / 2.0;
        if !plausible(turnaround, &PLAUSIBLE_TURNAROUND_S) {
            return Err(ReadError::corrupt(
                FORMAT,
                "the line start and end delays are implausible",
            ));
        }
        let geometry_error = |source| ReadError::geometry(FORMAT, source);
        let mut geometry = ScanGeometry::new(
            self.columns,
            self.rows,
            size("XYScanner.Width", self.columns)?,
            size("XYScanner.Height", self.rows)?,
            period,
            ScanDirection::Right,
            slow,
        )
        .and_then(|g| g.with_turnaround(turnaround))
        .map_err(geometry_error)?;
        if let Some(angle) = params
            .number("XYScanner.Angle")
            .filter(|a| plausible(a.to_radians(), &PLAUSIBLE_SCAN_ANGLE_RAD))
        {
            geometry = geometry
                .with_scan_angle(angle.to_radians())
                .map_err(geometry_error)?;
        }
        if let (Some(x), Some(y)) = (
            params.number("XYScanner.X_Offset"),
            params.number("XYScanner.Y_Offset"),
        ) && x.is_finite()
            && y.is_finite()
        {
            geometry = geometry.with_offset(x, y).map_err(geometry_error)?;
        }
        Ok(geometry)
    }
}

fn metadata(params: &Parameters, layout: &Layout, channel: &str) -> BTreeMap<String, String> {
    let mut m = BTreeMap::new();
    let shown = |key: &str| {
        params.values.get(key).map(|(value, unit)| {
            let value = match value {
                Value::Bool(b) => b.to_string(),
                Value::Long(v) => v.to_string(),
                Value::Double(v) => v.to_string(),
                Value::Text(t) => t.clone(),
            };
            if unit.is_empty() || unit == "--" {
                value
            } else {
                format!("{value} {unit}")
            }
        })
    };
    for (label, key) in [
        ("bias", "GapVoltageControl.Voltage"),
        ("setpoint current", "Regulator.Setpoint_1"),
        ("raster time", "XYScanner.Raster_Time"),
        ("scan width", "XYScanner.Width"),
        ("scan height", "XYScanner.Height"),
        ("scan angle", "XYScanner.Angle"),
        ("forward and backward", "XYScanner.X_Retrace"),
        ("up and down", "XYScanner.Y_Retrace"),
    ] {
        if let Some(value) = shown(key) {
            m.insert(label.to_string(), value);
        }
    }
    m.insert("channel".to_string(), channel.to_string());
    let frames = if layout.y_retrace { 2 } else { 1 };
    if layout.lines_stored < layout.rows * frames {
        m.insert(
            "incomplete scan".to_string(),
            format!(
                "{} of {} lines stored; the rest are NaN",
                layout.lines_stored,
                layout.rows * frames
            ),
        );
    }
    m
}
