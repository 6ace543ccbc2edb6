//! WSxM image reader (`.top`, `.stp`, `.ch1` …: Nanotec Electrónica / WSxM software).
//!
//! # Format
//!
//! A latin-1 text header: the line `WSxM file copyright …`, the line `SxM Image file`, the
//! line `Image header size: N`, then `[Section]` lines and `key: value` lines, ending with
//! the line `[Header end]`. The binary image follows that line (the stated header size is
//! not trusted, since some programs miscalculate it): `Number of columns × Number of rows`
//! little-endian values of `Image Data Type` (`short` or `integer`: `i16`; `float`: `f32`;
//! `double`: `f64`). One file holds one image of one channel in one direction.
//!
//! # Orientation (as Gwyddion's `wsxmfile.c` and SciFiReaders' `WSxM2DReader` read it)
//!
//! The stored image is rotated by 180° from the display: the first stored value is the
//! bottom-right pixel. dhct rotates it back, so row 0 is the top row.
//!
//! # Values, size and timing
//!
//! * z: the stored values span exactly `General Info: Z Amplitude` (e.g. `18.8851 nm`),
//!   so z = value × amplitude / (max − min) over the finite values, as Gwyddion does (the
//!   header's `Maximum`/`Minimum` can belong to another data type of the same scan, so they
//!   are not used). Length units become metres; `a.u.` becomes unitless.
//! * pitch = `Control: X Amplitude` / columns and `Y Amplitude` / rows (lengths with a
//!   unit; a missing or unitless amplitude gives the placeholder pitch, marked assumed).
//! * `General Info: X scanning direction` `Forward` is a trace (fast direction right),
//!   `Backward` a retrace; `Y scanning direction` `Up` or `Down` is the slow direction.
//! * `Control: X-Frequency` is the line frequency: one period scans a line forward and
//!   back, so the time of one line in one direction is 1 / (2 · frequency).
//! * `Control: Angle` is the scan angle in degrees; `X Offset`, `Y Offset` the offset.

use std::collections::BTreeMap;

use dhct_scan::{FileFormat, ImageChannel, ScanDirection, ScanGeometry, ScanPair, ValueSource};

use crate::bytes::checked_data_len;
use crate::iso28600::{parse_number, parse_unit};
use crate::limits::{Budget, ReadLimits};
use crate::placeholders::{
    ASSUMED_PITCH, ASSUMED_PIXEL_PERIOD, ASSUMED_SCALE_KEY, ASSUMED_TIMING_KEY, PLAUSIBLE_PITCH_M,
    PLAUSIBLE_PIXEL_PERIOD_S, PLAUSIBLE_SCAN_ANGLE_RAD, note, plausible,
};
use crate::{ReadError, ScanFile};

const FORMAT: FileFormat = FileFormat::Wsxm;
const MAGIC: &[u8] = b"WSxM file copyright";
const IMAGE_LINE: &[u8] = b"SxM Image file";
const HEADER_END: &[u8] = b"[Header end]";
/// How far into the file `[Header end]` may lie.
const MAX_HEADER: usize = 1 << 20;

/// True when `bytes` start like a WSxM image file.
pub fn looks_like_wsxm(bytes: &[u8]) -> bool {
    bytes.starts_with(MAGIC)
        && bytes
            .iter()
            .take(200)
            .position(|b| *b == b'\n')
            .and_then(|i| bytes.get(i + 1..))
            .is_some_and(|rest| rest.starts_with(IMAGE_LINE))
}

/// `Section::key` → value, from the text header.
struct Header(BTreeMap<String, String>);

impl Header {
    fn parse(text: &[u8]) -> Header {
        let text: String = text.iter().map(|&b| b as char).collect();
        let mut entries = BTreeMap::new();
        let mut section = String::new();
        for line in text.lines().map(str::trim) {
            if let Some(name) = line.strip_prefix('[').and_then(|l| l.strip_suffix(']')) {
                section = name.to_string();
            } else if let Some((key, value)) = line.split_once(':')
                && !section.is_empty()
            {
                entries
                    .entry(format!("{section}::{}", key.trim()))
                    .or_insert_with(|| value.trim().to_string());
            }
        }
        Header(entries)
    }

    fn get(&self, key: &str) -> Option<&str> {
        self.0
            .get(key)
            .map(String::as_str)
            .filter(|v| !v.is_empty())
    }

    /// A value like `18.8851 nm`: the number and its unit text.
    fn quantity(&self, key: &str) -> Option<(f64, &str)> {
        let value = self.get(key)?;
        let (number, unit) = value.split_once(' ').unwrap_or((value, ""));
        parse_number(number)
            .filter(|v| v.is_finite())
            .map(|v| (v, unit.trim()))
    }
}

/// Reads a WSxM image file: one [`ScanPair`] holding its trace or retrace.
pub fn read(bytes: &[u8]) -> Result<ScanFile, ReadError> {
    read_limited(bytes, &ReadLimits::default())
}

/// [`read`] under `limits` (see [`crate::limits`]).
pub fn read_limited(bytes: &[u8], limits: &ReadLimits) -> Result<ScanFile, ReadError> {
    let mut budget = Budget::new(limits, bytes.len())?;
    if !looks_like_wsxm(bytes) {
        return Err(ReadError::wrong_format(
            FORMAT,
            "the file does not start with \"WSxM file copyright\" and \"SxM Image file\"",
        ));
    }
    let data_start = data_start(bytes)?;
    let header = Header::parse(&bytes[..data_start]);
    let columns = count(&header, "General Info::Number of columns")?;
    let rows = count(&header, "General Info::Number of rows")?;
    let data_type = header
        .get("General Info::Image Data Type")
        .unwrap_or("short");
    let size: u64 = match data_type {
        "short" | "integer" => 2,
        "float" => 4,
        "double" => 8,
        other => {
            return Err(ReadError::unsupported(
                FORMAT,
                format!("Image Data Type \"{other}\" (dhct reads short, integer, float, double)"),
            ));
        }
    };
    let len = checked_data_len(FORMAT, rows as u64, columns as u64, size)?;
    budget.charge_images(FORMAT, columns as u64, rows as u64, 1, 0)?;
    let data = bytes
        .get(data_start..)
        .and_then(|d| d.get(..usize::try_from(len).ok()?))
        .ok_or(ReadError::Truncated {
            format: FORMAT,
            what: format!("{columns} x {rows} {data_type} values"),
            offset: data_start as u64,
            needed: len,
            len: bytes.len() as u64,
        })?;
    // Stored values, rotated by 180° into display order.
    let mut values: Vec<f64> = data
        .chunks_exact(size as usize)
        .rev()
        .map(|c| match c.len() {
            2 => f64::from(i16::from_le_bytes([c[0], c[1]])),
            4 => f64::from(f32::from_le_bytes([c[0], c[1], c[2], c[3]])),
            _ => f64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]),
        })
        .collect();
    let unit = scale_values(&header, &mut values)?;
    let mut metadata = metadata(&header);
    let (geometry, backward) = geometry(&header, columns, rows, &mut metadata)?;
    let name = header
        .get("General Info::Acquisition channel")
        .unwrap_or("WSxM image");
    let image = ImageChannel::from_row_major(name, unit, rows, columns, values)
        .map_err(|source| ReadError::geometry(FORMAT, source))?;
    let pair = if backward {
        ScanPair::retrace_only(geometry, image)
    } else {
        ScanPair::new(geometry, image, None)
    }
    .map_err(|source| ReadError::geometry(FORMAT, source))?;
    Ok(ScanFile {
        format: FORMAT,
        pairs: vec![pair],
        metadata,
    })
}

/// The offset just after the `[Header end]` line.
fn data_start(bytes: &[u8]) -> Result<usize, ReadError> {
    let window = &bytes[..bytes.len().min(MAX_HEADER)];
    let at = window
        .windows(HEADER_END.len())
        .position(|w| w == HEADER_END)
        .ok_or_else(|| ReadError::Truncated {
            format: FORMAT,
            what: "the [Header end] line".to_string(),
            offset: window.len() as u64,
            needed: HEADER_END.len() as u64,
            len: bytes.len() as u64,
        })?;
    let mut end = at + HEADER_END.len();
    for terminator in [b'\r', b'\n'] {
        if bytes.get(end) == Some(&terminator) {
            end += 1;
        }
    }
    Ok(end)
}

fn count(header: &Header, key: &str) -> Result<usize, ReadError> {
    let text = header.get(key).unwrap_or("");
    text.parse::<usize>()
        .ok()
        .filter(|n| (1..=1 << 16).contains(n))
        .ok_or_else(|| {
            ReadError::corrupt(
                FORMAT,
                format!("{key} must be a count from 1 to 65536, got \"{text}\""),
            )
        })
}

/// Scales the stored values so they span the Z Amplitude; returns the unit.
fn scale_values(header: &Header, values: &mut [f64]) -> Result<String, ReadError> {
    let (amplitude, unit_text) = header
        .quantity("General Info::Z Amplitude")
        .filter(|(a, _)| *a > 0.0)
        .ok_or_else(|| {
            ReadError::corrupt(
                FORMAT,
                "General Info: Z Amplitude is missing or not positive",
            )
        })?;
    let (unit, factor) = match unit_text {
        "a.u." => (String::new(), 1.0),
        text => parse_unit(text),
    };
    let (lo, hi) = values
        .iter()
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(*v), hi.max(*v))
        });
    let scale = amplitude * factor / (hi - lo);
    if !(scale.is_finite() && scale > 0.0) {
        return Err(ReadError::NoImage {
            format: FORMAT,
            reason: "the image is constant (or has no finite value), so Z Amplitude cannot \
                     scale it"
                .to_string(),
        });
    }
    values.iter_mut().for_each(|v| *v *= scale);
    Ok(unit)
}

/// The scan geometry, and whether the image is a backward (retrace) scan.
fn geometry(
    header: &Header,
    columns: usize,
    rows: usize,
    metadata: &mut BTreeMap<String, String>,
) -> Result<(ScanGeometry, bool), ReadError> {
    let length = |key: &str, n: usize| {
        header
            .quantity(key)
            .and_then(|(v, unit)| match parse_unit(unit) {
                (base, factor) if base == "m" => Some(v.abs() * factor / n as f64),
                _ => None,
            })
            .filter(|p| plausible(*p, &PLAUSIBLE_PITCH_M))
    };
    let (pitch_x, pitch_y, scale_source) = match (
        length("Control::X Amplitude", columns),
        length("Control::Y Amplitude", rows),
    ) {
        (Some(x), Some(y)) => (x, y, ValueSource::Stated),
        _ => {
            note(
                metadata,
                ASSUMED_SCALE_KEY,
                "no X/Y Amplitude with a length unit in the header",
            );
            (ASSUMED_PITCH, ASSUMED_PITCH, ValueSource::Assumed)
        }
    };
    let mut timing_source = ValueSource::Stated;
    let line_time = header
        .quantity("Control::X-Frequency")
        .filter(|(_, unit)| *unit == "Hz")
        .map(|(f, _)| 1.0 / (2.0 * f))
        .filter(|t| plausible(t / columns as f64, &PLAUSIBLE_PIXEL_PERIOD_S))
        .unwrap_or_else(|| {
            note(
                metadata,
                ASSUMED_TIMING_KEY,
                "no usable X-Frequency in the header",
            );
            timing_source = ValueSource::Assumed;
            ASSUMED_PIXEL_PERIOD * columns as f64
        });
    let direction = |key: &str| header.get(key).map(str::to_ascii_lowercase);
    let backward = direction("General Info::X scanning direction").as_deref() == Some("backward");
    let slow = match direction("General Info::Y scanning direction").as_deref() {
        Some("up") => ScanDirection::Up,
        Some("down") => ScanDirection::Down,
        _ => {
            note(
                metadata,
                ASSUMED_TIMING_KEY,
                "no Y scanning direction in the header: down assumed",
            );
            timing_source = ValueSource::Assumed;
            ScanDirection::Down
        }
    };
    let geometry_error = |source| ReadError::geometry(FORMAT, source);
    let mut geometry = ScanGeometry::from_line_time(
        columns,
        rows,
        pitch_x,
        pitch_y,
        line_time,
        ScanDirection::Right,
        slow,
    )
    .map_err(geometry_error)?
    .with_scale_source(scale_source)
    .with_timing_source(timing_source);
    if let Some((angle, _)) = header.quantity("Control::Angle")
        && plausible(angle.to_radians(), &PLAUSIBLE_SCAN_ANGLE_RAD)
    {
        geometry = geometry
            .with_scan_angle(angle.to_radians())
            .map_err(geometry_error)?;
    }
    let offset = |key: &str| {
        header
            .quantity(key)
            .map(|(v, unit)| (v, parse_unit(unit)))
            .filter(|(v, (base, _))| base == "m" && v.is_finite())
            .map(|(v, (_, factor))| v * factor)
    };
    if let (Some(x), Some(y)) = (offset("Control::X Offset"), offset("Control::Y Offset")) {
        geometry = geometry.with_offset(x, y).map_err(geometry_error)?;
    }
    Ok((geometry, backward))
}

fn metadata(header: &Header) -> BTreeMap<String, String> {
    let mut m = BTreeMap::new();
    for (label, key) in [
        ("date", "General Info::Acquisition time"),
        ("channel", "General Info::Acquisition channel"),
        ("head type", "General Info::Head type"),
        ("x scanning direction", "General Info::X scanning direction"),
        ("y scanning direction", "General Info::Y scanning direction"),
        ("z amplitude", "General Info::Z Amplitude"),
        ("x amplitude", "Control::X Amplitude"),
        ("y amplitude", "Control::Y Amplitude"),
        ("line frequency", "Control::X-Frequency"),
        ("scan angle", "Control::Angle"),
        ("bias", "Control::Topography Bias"),
        ("set point", "Control::Set Point"),
        ("comments", "Miscellaneous::Comments"),
        ("software version", "Miscellaneous::Saved with version"),
    ] {
        if let Some(value) = header.get(key) {
            m.insert(label.to_string(), value.to_string());
        }
    }
    m
}
