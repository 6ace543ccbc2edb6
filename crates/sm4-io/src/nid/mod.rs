//! Nanosurf `.nid` image reader.
//!
//! # Format
//!
//! A UTF-8 text header in INI form (see [`ini`]), then the two bytes `#!`, then the data of
//! every data set back to back. The `[DataSet]` section lists the data sets: groups
//! `Gr{g}-Name` (e.g. `Scan forward`, `Scan backward`) with channels `Gr{g}-Ch{c}` whose
//! values name a section `[DataSet-g:c]`. The data are stored in the order of (g, c). Each
//! data-set section gives:
//!
//! | key | meaning |
//! |---|---|
//! | `Frame` | `Scan forward`, `Scan backward`, or a spectroscopy frame |
//! | `Points`, `Lines` | pixels per line (x) and number of lines (y) |
//! | `Dim0Range`, `Dim1Range`, `Dim0Unit`, `Dim1Unit` | frame size along x and y |
//! | `Dim2Name`, `Dim2Unit`, `Dim2Min`, `Dim2Range` | channel name, unit and value range |
//! | `SaveBits`, `SaveSign`, `SaveOrder`, `SaveMode` | 16 or 32, `Signed`, `Intel` (little-endian), `Binary` |
//!
//! A stored integer `n` of `b` bits is the value `Dim2Min + Dim2Range · (n + 2^(b−1)) / 2^b`,
//! in `Dim2Unit` with its prefix folded into the value (`°` is written `deg`).
//!
//! # Orientation (matches Gwyddion's import and the header's `CurLine`)
//!
//! Data are stored by position, not in acquisition order: the first stored line is the
//! bottom of the frame (y = `Dim1Min`) and every line runs left to right, for the forward
//! and the backward images alike. dhct flips the rows so that row 0 is the top. The trace
//! (`Scan forward`) runs right, the retrace (`Scan backward`) left; the slow direction is the
//! header's `Scan direction` (`Up` or `Down`).
//!
//! # Geometry
//!
//! Pitch = `Dim0Range / Points`, `Dim1Range / Lines` (metres). The time of one line in one
//! direction is the first value of `ScanTime` in `[DataSet\Parameters\Imaging]` (seconds,
//! listed for forward and backward), else `Time/Line` of `[DataSet-Info]`; pixel period =
//! that / `Points`, no turnaround. `Rotation` (degrees) is the scan angle. Without a timing
//! or a scan direction the placeholder [`ASSUMED_PIXEL_PERIOD`] or slow direction down is
//! used and the timing marked [`ValueSource::Assumed`], reason under
//! [`ASSUMED_TIMING_KEY`]. `Date` (`DD-MM-YYYY`) and `Time` (`HH:MM:SS`) of `[DataSet-Info]`
//! are the frame's start ([`ScanGeometry::start_time`]: frames of a series are ordered by
//! it). Spectroscopy data sets are skipped (their bytes are counted).

pub mod ini;

use std::collections::BTreeMap;

use dhct_scan::{FileFormat, ImageChannel, ScanDirection, ScanGeometry, ScanPair, ValueSource};

use crate::bytes::checked_data_len;
use crate::iso28600::{parse_number, parse_unit};
use crate::limits::{Budget, ReadLimits};
use crate::placeholders::{
    ASSUMED_PIXEL_PERIOD, ASSUMED_TIMING_KEY, PLAUSIBLE_PITCH_M, PLAUSIBLE_PIXEL_PERIOD_S,
    PLAUSIBLE_SCAN_ANGLE_RAD, note, plausible,
};
use crate::{ReadError, ScanFile};
use ini::Ini;

const FORMAT: FileFormat = FileFormat::NanosurfNid;
/// The first line of every `.nid` file.
pub const MAGIC: &[u8] = b"[DataSet]";
const DATA_MARKER: &[u8] = b"#!";
const INFO: &str = "DataSet-Info";
const IMAGING: &str = "DataSet\\Parameters\\Imaging";

/// One data set of the header, checked against the data before anything is decoded.
#[derive(Debug)]
struct DataSet {
    section: String,
    /// `Some(false)` forward, `Some(true)` backward, `None` not an image.
    backward: Option<bool>,
    columns: usize,
    rows: usize,
    bits: u32,
    name: String,
    unit: String,
    size: (f64, f64),
    value_min: f64,
    value_range: f64,
    /// Byte range of the stored values in the file.
    start: usize,
    len: usize,
}

/// Reads a Nanosurf `.nid` file: one [`ScanPair`] per channel (see the module docs).
pub fn read(bytes: &[u8]) -> Result<ScanFile, ReadError> {
    read_limited(bytes, &ReadLimits::default())
}

/// [`read`] under `limits` (see [`crate::limits`]).
pub fn read_limited(bytes: &[u8], limits: &ReadLimits) -> Result<ScanFile, ReadError> {
    let mut budget = Budget::new(limits, bytes.len())?;
    let body = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
    if !body.starts_with(MAGIC) {
        return Err(ReadError::wrong_format(
            FORMAT,
            "the file does not start with [DataSet]",
        ));
    }
    let marker = find(bytes, DATA_MARKER).ok_or_else(|| ReadError::Truncated {
        format: FORMAT,
        what: "the data marker #! after the header".to_string(),
        offset: bytes.len() as u64,
        needed: DATA_MARKER.len() as u64,
        len: bytes.len() as u64,
    })?;
    let ini = Ini::parse(&String::from_utf8_lossy(&bytes[..marker]));
    let data_start = marker + DATA_MARKER.len();
    let sets = data_sets(&ini, data_start, bytes.len())?;
    let images: Vec<&DataSet> = sets.iter().filter(|s| s.backward.is_some()).collect();
    if images.is_empty() {
        return Err(ReadError::NoImage {
            format: FORMAT,
            reason: format!(
                "none of the {} data sets is a forward or backward scan",
                sets.len()
            ),
        });
    }
    for set in &images {
        budget.charge_images(FORMAT, set.columns as u64, set.rows as u64, 1, 0)?;
    }
    let mut metadata = metadata(&ini);
    let (slow, line_time) = scan_timing(&ini, &mut metadata)?;
    let angle = scan_angle(&ini)?;
    let start =
        dhct_scan::clock::seconds_from_day_first(ini.get(INFO, "Date"), ini.get(INFO, "Time"));
    let mut pairs = Vec::new();
    let mut used = vec![false; images.len()];
    for i in 0..images.len() {
        if used[i] {
            continue;
        }
        used[i] = true;
        let partner = (0..images.len()).find(|&j| {
            !used[j]
                && images[j].name == images[i].name
                && images[j].backward != images[i].backward
                && (images[j].columns, images[j].rows, images[j].size)
                    == (images[i].columns, images[i].rows, images[i].size)
        });
        if let Some(j) = partner {
            used[j] = true;
        }
        let (trace, retrace) = match (images[i].backward, partner) {
            (Some(true), Some(j)) => (Some(images[j]), Some(images[i])),
            (Some(true), None) => (None, Some(images[i])),
            (_, j) => (Some(images[i]), j.map(|j| images[j])),
        };
        let first = trace.or(retrace).expect("one of the two is set");
        let geometry = geometry(first, slow, line_time, angle)?.with_start_time(start);
        let decode = |set: Option<&DataSet>| set.map(|s| decode(bytes, s)).transpose();
        pairs.push(
            ScanPair::from_parts(geometry, decode(trace)?, decode(retrace)?)
                .map_err(|source| ReadError::geometry(FORMAT, source))?,
        );
    }
    Ok(ScanFile {
        format: FORMAT,
        pairs,
        metadata,
    })
}

/// The data sets in storage order, each with its byte range checked against the file.
fn data_sets(ini: &Ini, data_start: usize, file_len: usize) -> Result<Vec<DataSet>, ReadError> {
    let listing = ini
        .section("DataSet")
        .ok_or_else(|| ReadError::corrupt(FORMAT, "the header has no [DataSet] section"))?;
    let mut keyed: Vec<((u64, u64), &str)> = listing
        .iter()
        .filter_map(|(key, value)| {
            let (group, channel) = key.strip_prefix("Gr")?.split_once("-Ch")?;
            Some(((group.parse().ok()?, channel.parse().ok()?), value.as_str()))
        })
        .collect();
    keyed.sort_by_key(|(order, _)| *order);
    let mut sets = Vec::with_capacity(keyed.len());
    let mut offset = data_start;
    for (_, section) in keyed {
        let set = data_set(ini, section, offset)?;
        let end = offset.checked_add(set.len).filter(|end| *end <= file_len);
        let Some(end) = end else {
            return Err(ReadError::Truncated {
                format: FORMAT,
                what: format!("data set {section} ({} x {} values)", set.columns, set.rows),
                offset: offset as u64,
                needed: set.len as u64,
                len: file_len as u64,
            });
        };
        offset = end;
        sets.push(set);
    }
    Ok(sets)
}

/// One `[DataSet-g:c]` section whose data start at `start`.
fn data_set(ini: &Ini, section: &str, start: usize) -> Result<DataSet, ReadError> {
    let get = |key: &str| ini.get(section, key);
    let corrupt = |what: String| ReadError::corrupt(FORMAT, format!("[{section}]: {what}"));
    let count = |key: &str| -> Result<u64, ReadError> {
        get(key)
            .and_then(|v| v.parse::<u64>().ok())
            .filter(|n| *n > 0)
            .ok_or_else(|| {
                corrupt(format!(
                    "{key} must be a positive integer, got {:?}",
                    get(key)
                ))
            })
    };
    let number = |key: &str| get(key).and_then(parse_number).filter(|v| v.is_finite());
    let (columns, rows) = (count("Points")?, count("Lines")?);
    let bits = match get("SaveBits") {
        Some("16") => 16,
        Some("32") => 32,
        other => {
            return Err(ReadError::unsupported(
                FORMAT,
                format!("[{section}] SaveBits {other:?} (dhct reads 16 and 32)"),
            ));
        }
    };
    for (key, wanted) in [
        ("SaveSign", "Signed"),
        ("SaveOrder", "Intel"),
        ("SaveMode", "Binary"),
    ] {
        if let Some(value) = get(key).filter(|v| !v.eq_ignore_ascii_case(wanted)) {
            return Err(ReadError::unsupported(
                FORMAT,
                format!("[{section}] {key}={value} (dhct reads {wanted})"),
            ));
        }
    }
    let len = checked_data_len(FORMAT, rows, columns, u64::from(bits / 8))?;
    let frame = get("Frame").unwrap_or("").to_ascii_lowercase();
    let backward = match (frame.starts_with("scan"), frame.contains("backward")) {
        (false, _) => None,
        (true, backward) => Some(backward),
    };
    let unit = match get("Dim2Unit").unwrap_or("") {
        "°" | "º" => "deg",
        unit => unit,
    };
    let (unit, scale) = parse_unit(unit);
    let value_min = number("Dim2Min").ok_or_else(|| corrupt("Dim2Min is missing".into()))?;
    let value_range = number("Dim2Range").ok_or_else(|| corrupt("Dim2Range is missing".into()))?;
    let size = lateral_size(ini, section)?;
    Ok(DataSet {
        section: section.to_string(),
        backward: if rows > 1 { backward } else { None },
        columns: usize::try_from(columns).map_err(|_| corrupt("too many points".into()))?,
        rows: usize::try_from(rows).map_err(|_| corrupt("too many lines".into()))?,
        bits,
        name: get("Dim2Name").unwrap_or(section).to_string(),
        unit,
        size,
        value_min: value_min * scale,
        value_range: value_range * scale,
        start,
        len: usize::try_from(len).map_err(|_| corrupt("data too large".into()))?,
    })
}

/// `Dim0Range`, `Dim1Range` in metres (0 when missing or not a length: checked later for
/// images only).
fn lateral_size(ini: &Ini, section: &str) -> Result<(f64, f64), ReadError> {
    let axis = |dim: u8| {
        let range = ini
            .get(section, &format!("Dim{dim}Range"))
            .and_then(parse_number);
        let (unit, factor) = parse_unit(ini.get(section, &format!("Dim{dim}Unit")).unwrap_or("m"));
        match range {
            Some(r) if unit == "m" => r * factor,
            _ => 0.0,
        }
    };
    Ok((axis(0), axis(1)))
}

/// Decodes one data set into display orientation (rows flipped: storage starts at the
/// bottom).
fn decode(bytes: &[u8], set: &DataSet) -> Result<ImageChannel, ReadError> {
    let data = &bytes[set.start..set.start + set.len];
    let step = (set.bits / 8) as usize;
    let full_scale = 2f64.powi(set.bits as i32);
    let half = full_scale / 2.0;
    let value = |chunk: &[u8]| {
        let raw = match step {
            2 => f64::from(i16::from_le_bytes([chunk[0], chunk[1]])),
            _ => f64::from(i32::from_le_bytes([chunk[0], chunk[1], chunk[2], chunk[3]])),
        };
        set.value_min + set.value_range * (raw + half) / full_scale
    };
    let mut values = Vec::with_capacity(set.columns * set.rows);
    for line in data.chunks_exact(set.columns * step).rev() {
        values.extend(line.chunks_exact(step).map(value));
    }
    ImageChannel::from_row_major(
        set.name.clone(),
        set.unit.clone(),
        set.rows,
        set.columns,
        values,
    )
    .map_err(|source| ReadError::geometry(FORMAT, source))
}

/// The slow direction and the time of one line in one direction (seconds), or the
/// placeholders (with notes) when the header lacks them.
fn scan_timing(
    ini: &Ini,
    metadata: &mut BTreeMap<String, String>,
) -> Result<(Option<ScanDirection>, Option<f64>), ReadError> {
    let info = |key: &str| ini.get(INFO, key);
    let slow = match info("Scan direction")
        .map(str::to_ascii_lowercase)
        .as_deref()
    {
        Some("up") => Some(ScanDirection::Up),
        Some("down") => Some(ScanDirection::Down),
        _ => {
            note(
                metadata,
                ASSUMED_TIMING_KEY,
                "no Scan direction (Up or Down) in [DataSet-Info]; down assumed",
            );
            None
        }
    };
    let from_imaging = ini
        .get(IMAGING, "ScanTime")
        .and_then(|v| v.strip_prefix("V["))
        .and_then(|v| v.split([',', ']']).next())
        .and_then(parse_number);
    let from_info = info("Time/Line")
        .and_then(parse_quantity)
        .and_then(|(value, unit)| {
            let (base, factor) = parse_unit(&unit);
            (base == "s").then_some(value * factor)
        });
    let line_time = from_imaging.or(from_info);
    if line_time.is_none() {
        note(
            metadata,
            ASSUMED_TIMING_KEY,
            "no ScanTime or Time/Line in the header",
        );
    }
    Ok((slow, line_time))
}

/// `Rotation` of `[DataSet-Info]` in radians (0 when absent).
fn scan_angle(ini: &Ini) -> Result<f64, ReadError> {
    let Some(text) = ini.get(INFO, "Rotation") else {
        return Ok(0.0);
    };
    let radians = parse_quantity(text)
        .map(|(value, _)| value.to_radians())
        .filter(|a| plausible(*a, &PLAUSIBLE_SCAN_ANGLE_RAD))
        .ok_or_else(|| {
            ReadError::corrupt(
                FORMAT,
                format!("Rotation \"{text}\" is not an angle in degrees within a turn"),
            )
        })?;
    Ok(radians)
}

/// The geometry of an image data set.
fn geometry(
    set: &DataSet,
    slow: Option<ScanDirection>,
    line_time: Option<f64>,
    angle: f64,
) -> Result<ScanGeometry, ReadError> {
    let pitch = (
        set.size.0 / set.columns as f64,
        set.size.1 / set.rows as f64,
    );
    if !(plausible(pitch.0, &PLAUSIBLE_PITCH_M) && plausible(pitch.1, &PLAUSIBLE_PITCH_M)) {
        return Err(ReadError::corrupt(
            FORMAT,
            format!(
                "[{}] Dim0Range/Dim1Range {:e} x {:e} m give a pixel pitch outside {:e}..{:e} m",
                set.section,
                set.size.0,
                set.size.1,
                PLAUSIBLE_PITCH_M.start(),
                PLAUSIBLE_PITCH_M.end()
            ),
        ));
    }
    let pixel_period = match line_time {
        Some(t) => {
            let period = t / set.columns as f64;
            if !plausible(period, &PLAUSIBLE_PIXEL_PERIOD_S) {
                return Err(ReadError::corrupt(
                    FORMAT,
                    format!(
                        "the line time {t} s gives a pixel period outside {:e}..{:e} s",
                        PLAUSIBLE_PIXEL_PERIOD_S.start(),
                        PLAUSIBLE_PIXEL_PERIOD_S.end()
                    ),
                ));
            }
            period
        }
        None => ASSUMED_PIXEL_PERIOD,
    };
    let timing_source = if slow.is_some() && line_time.is_some() {
        ValueSource::Stated
    } else {
        ValueSource::Assumed
    };
    ScanGeometry::new(
        set.columns,
        set.rows,
        pitch.0,
        pitch.1,
        pixel_period,
        ScanDirection::Right,
        slow.unwrap_or(ScanDirection::Down),
    )
    .and_then(|g| g.with_scan_angle(angle))
    .map(|g| g.with_timing_source(timing_source))
    .map_err(|source| ReadError::geometry(FORMAT, source))
}

/// A number followed by an optional unit, as in `803ms`, `2 s`, `0 °`.
fn parse_quantity(text: &str) -> Option<(f64, String)> {
    let text = text.trim();
    let split = text
        .char_indices()
        .find(|(_, c)| !(c.is_ascii_digit() || matches!(c, '.' | '-' | '+' | 'e' | 'E')))
        .map_or(text.len(), |(i, _)| i);
    // An exponent letter directly before the unit (`1e` of `1em`) is not expected here.
    let value = parse_number(&text[..split])?;
    Some((value, text[split..].trim().to_string()))
}

/// Header values worth showing a user.
fn metadata(ini: &Ini) -> BTreeMap<String, String> {
    let mut m = BTreeMap::new();
    for (key, name) in [
        ("Date", "date"),
        ("Time", "time"),
        ("Op. mode", "operating mode"),
        ("Image size", "image size"),
        ("Scan direction", "scan direction"),
        ("Time/Line", "time per line"),
        ("Rotation", "rotation"),
        ("Setpoint", "setpoint"),
        ("Tip voltage", "tip voltage"),
        ("X-Pos", "x position"),
        ("Y-Pos", "y position"),
        ("Head type", "head type"),
        ("Software ver.", "software version"),
    ] {
        if let Some(value) = ini.get(INFO, key).filter(|v| !v.is_empty()) {
            m.insert(name.to_string(), value.to_string());
        }
    }
    m
}

/// Position of the first `needle` in `haystack`.
fn find(haystack: &[u8], needle: &[u8]) -> Option<usize> {
    haystack.windows(needle.len()).position(|w| w == needle)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantities_with_units() {
        assert_eq!(parse_quantity("803ms"), Some((803.0, "ms".to_string())));
        assert_eq!(parse_quantity("2 s"), Some((2.0, "s".to_string())));
        assert_eq!(parse_quantity("-45 °"), Some((-45.0, "°".to_string())));
        assert_eq!(parse_quantity("1.5e-3 s"), Some((1.5e-3, "s".to_string())));
        assert_eq!(parse_quantity("fast"), None);
    }
}
