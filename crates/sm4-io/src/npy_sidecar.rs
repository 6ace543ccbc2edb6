//! Reading back the JSON sidecar dhct writes beside a `.npy` (`NAME.json` for `NAME.npy`,
//! see [`crate::npy::Sidecar`]): the pixel size, timing, directions, pass, channel name and
//! unit that NPY has no place for. A trace is paired with its retrace when the file named
//! like it with `retrace` for `trace` (or the reverse) has a sidecar of the other pass with
//! the same shape, pixel size, timing and directions.
//!
//! A `NAME.json` without dhct's keys is not a sidecar and is left alone (the geometry stays
//! an assumption, reported as one); one with dhct's keys that contradicts the array (another
//! shape, a non-positive pixel size) is an error that names the file.

use std::path::{Path, PathBuf};

use dhct_scan::{
    FileFormat, ImageChannel, ScanDirection, ScanFile, ScanGeometry, ScanPair, ScanPass,
    ValueSource,
};
use serde::Deserialize;

use crate::limits::{ReadLimits, read_regular_file, read_regular_text};
use crate::placeholders::{ASSUMED_SCALE_KEY, ASSUMED_TIMING_KEY};
use crate::{ReadError, npy};

const FORMAT: FileFormat = FileFormat::Npy;

/// Largest sidecar read, bytes (dhct's are about 500).
pub const MAX_SIDECAR_BYTES: u64 = 65_536;

/// The sidecar's keys that dhct reads back.
#[derive(Debug, Clone, PartialEq, Deserialize)]
struct SidecarFields {
    shape: [usize; 2],
    channel: String,
    unit: String,
    pixel_size_m: [f64; 2],
    pixel_size_source: ValueSource,
    pixel_period_s: f64,
    timing_source: ValueSource,
    pass: String,
    fast_direction: ScanDirection,
    slow_direction: ScanDirection,
}

impl SidecarFields {
    fn pass(&self, path: &Path) -> Result<ScanPass, ReadError> {
        ScanPass::from_name(&self.pass).ok_or_else(|| {
            sidecar_error(
                path,
                format!("pass is {:?}, not \"trace\" or \"retrace\"", self.pass),
            )
        })
    }

    /// The scan geometry the sidecar states (the trace's fast direction is this pass's,
    /// reversed for a retrace).
    fn geometry(&self, path: &Path) -> Result<ScanGeometry, ReadError> {
        let trace_fast = match self.pass(path)? {
            ScanPass::Trace => self.fast_direction,
            ScanPass::Retrace => self.fast_direction.reversed(),
        };
        let [rows, columns] = self.shape;
        ScanGeometry::new(
            columns,
            rows,
            self.pixel_size_m[0],
            self.pixel_size_m[1],
            self.pixel_period_s,
            trace_fast,
            self.slow_direction,
        )
        .map(|g| {
            g.with_scale_source(self.pixel_size_source)
                .with_timing_source(self.timing_source)
        })
        .map_err(|e| sidecar_error(path, e.to_string()))
    }

    /// Whether `other` describes the other pass of the same scan.
    fn pairs_with(&self, other: &SidecarFields) -> bool {
        self.pass != other.pass
            && self.shape == other.shape
            && self.pixel_size_m == other.pixel_size_m
            && self.pixel_period_s == other.pixel_period_s
            && self.slow_direction == other.slow_direction
            && self.fast_direction == other.fast_direction.reversed()
    }
}

/// `path` (an NPY file whose bytes are `bytes`) read with its sidecar, paired with the
/// other pass when that has one; without a sidecar, as [`npy::read_limited`] reads it.
pub(crate) fn read_with_sidecar(
    path: &Path,
    bytes: &[u8],
    limits: &ReadLimits,
) -> Result<ScanFile, ReadError> {
    let mut file = npy::read_limited(bytes, limits)?;
    let sidecar_path = path.with_extension("json");
    let Some(fields) = read_sidecar(&sidecar_path)? else {
        return Ok(file);
    };
    let pass = fields.pass(&sidecar_path)?;
    let geometry = fields.geometry(&sidecar_path)?;
    let (_, image, _) = file.pairs.remove(0).into_parts();
    let image = image.expect("the NPY reader gives a trace");
    check_shape(&sidecar_path, &fields, &image)?;
    let channel = ImageChannel::new(fields.channel.clone(), fields.unit.clone(), image.z);
    let other = other_pass(path, &fields, limits, &mut file)?;
    let (trace, retrace) = match pass {
        ScanPass::Trace => (Some(channel), other),
        ScanPass::Retrace => (other, Some(channel)),
    };
    let pair = ScanPair::from_parts(geometry, trace, retrace)
        .map_err(|source| ReadError::geometry(FORMAT, source))?;
    file.pairs = vec![pair];
    record_sources(&mut file, &fields, &sidecar_path);
    Ok(file)
}

/// For an NPY retrace written by dhct (`path`, with its sidecar), the trace file it is read
/// with: the `…trace…` file beside it whose sidecar describes the same scan. `None` for
/// anything else (a trace, a retrace alone, a file that is no NPY or has no sidecar).
pub fn paired_trace(path: &Path) -> Option<PathBuf> {
    match other_pass_file(path)? {
        (trace, ScanPass::Trace) => Some(trace),
        _ => None,
    }
}

/// For an NPY written by dhct (`path`, with its sidecar), the file its other pass is read
/// from (`…trace…` ↔ `…retrace…` beside it, with a sidecar of the same scan) and that
/// pass; `None` when there is none (or `path` is no NPY or has no sidecar).
pub fn other_pass_file(path: &Path) -> Option<(PathBuf, ScanPass)> {
    // Only a regular file is opened (a FIFO would block).
    if !path.is_file() {
        return None;
    }
    let mut magic = [0u8; 6];
    std::io::Read::read_exact(&mut std::fs::File::open(path).ok()?, &mut magic).ok()?;
    if magic != *b"\x93NUMPY" {
        return None;
    }
    let fields = read_sidecar(&path.with_extension("json")).ok()??;
    let (other, other_fields) = partner(path)?;
    let pass = other_fields.pass(&other).ok()?;
    (fields.pairs_with(&other_fields) && other.is_file()).then_some((other, pass))
}

/// The file named like `path` with `trace` ↔ `retrace` and its sidecar, when it has one
/// (whether it describes the same scan is for [`SidecarFields::pairs_with`] to say).
fn partner(path: &Path) -> Option<(PathBuf, SidecarFields)> {
    let other = counterpart(path)?;
    let fields = read_sidecar(&other.with_extension("json")).ok()??;
    Some((other, fields))
}

/// The sidecar at `path`: `None` when there is no regular file, or it is not dhct's (larger
/// than [`MAX_SIDECAR_BYTES`], not JSON text, or without a `pixel_size_m` key); an error
/// when it is dhct's but its values cannot be read.
fn read_sidecar(path: &Path) -> Result<Option<SidecarFields>, ReadError> {
    if !path.is_file() {
        return Ok(None);
    }
    let Ok(text) = read_regular_text(path, MAX_SIDECAR_BYTES) else {
        return Ok(None);
    };
    let Ok(value) = serde_json::from_str::<serde_json::Value>(&text) else {
        return Ok(None);
    };
    if value.get("pixel_size_m").is_none() {
        return Ok(None);
    }
    serde_json::from_value(value)
        .map(Some)
        .map_err(|e| sidecar_error(path, e.to_string()))
}

/// An error when the sidecar's shape is not the array's.
fn check_shape(path: &Path, fields: &SidecarFields, image: &ImageChannel) -> Result<(), ReadError> {
    let [rows, columns] = fields.shape;
    if (rows, columns) == (image.rows(), image.columns()) {
        return Ok(());
    }
    Err(sidecar_error(
        path,
        format!(
            "it describes a {columns} x {rows} px image but the array is {} x {} px",
            image.columns(),
            image.rows()
        ),
    ))
}

/// The other pass's image, when the file named like `path` with `trace` ↔ `retrace` has a
/// sidecar of the other pass of the same scan; a note in the metadata when it is there but
/// does not pair.
fn other_pass(
    path: &Path,
    fields: &SidecarFields,
    limits: &ReadLimits,
    file: &mut ScanFile,
) -> Result<Option<ImageChannel>, ReadError> {
    let Some((other_path, other)) = partner(path) else {
        return Ok(None);
    };
    let name = other_path.display().to_string();
    if !fields.pairs_with(&other) {
        file.metadata.insert(
            "npy pairing".into(),
            format!("{name} not paired: its sidecar describes another scan or the same pass"),
        );
        return Ok(None);
    }
    let bytes = read_regular_file(&other_path, limits.max_bytes)?;
    let (_, image, _) = npy::read_limited(&bytes, limits)?
        .pairs
        .remove(0)
        .into_parts();
    let image = image.expect("the NPY reader gives a trace");
    check_shape(&other_path.with_extension("json"), &other, &image)?;
    file.metadata
        .insert("npy pairing".into(), format!("other pass read from {name}"));
    Ok(Some(ImageChannel::new(other.channel, other.unit, image.z)))
}

/// `path` with the last `retrace` in its file stem replaced by `trace`, or else the last
/// `trace` by `retrace` (`a_trace.npy` ↔ `a_retrace.npy`).
fn counterpart(path: &Path) -> Option<PathBuf> {
    let stem = path.file_stem()?.to_str()?;
    let swapped = if let Some(at) = stem.rfind("retrace") {
        format!("{}trace{}", &stem[..at], &stem[at + "retrace".len()..])
    } else {
        let at = stem.rfind("trace")?;
        format!("{}retrace{}", &stem[..at], &stem[at + "trace".len()..])
    };
    Some(path.with_file_name(format!("{swapped}.npy")))
}

/// Replaces the "NPY carries no scale/timing" notes by where the values came from.
fn record_sources(file: &mut ScanFile, fields: &SidecarFields, sidecar: &Path) {
    let name = sidecar.display().to_string();
    file.metadata.insert("npy sidecar".into(), name.clone());
    for (key, source) in [
        (ASSUMED_SCALE_KEY, fields.pixel_size_source),
        (ASSUMED_TIMING_KEY, fields.timing_source),
    ] {
        match source {
            ValueSource::Stated => {
                file.metadata.remove(key);
            }
            ValueSource::Assumed => {
                file.metadata.insert(
                    key.into(),
                    format!("{name} says it was assumed by the file it came from"),
                );
            }
        }
    }
}

fn sidecar_error(path: &Path, reason: String) -> ReadError {
    ReadError::corrupt(
        FORMAT,
        format!("the sidecar {} cannot be used: {reason}", path.display()),
    )
}
