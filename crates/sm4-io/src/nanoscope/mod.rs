//! Bruker/Veeco Nanoscope image reader (`.spm`, `.001`, `.002`, …; Nanoscope 5 and later).
//!
//! # Format
//!
//! A text header (see [`header`]) starting with `\*File list` and ending with
//! `\*File list end`, then the images. Every `\*Ciao image list` section describes one image:
//!
//! | key | meaning |
//! |---|---|
//! | `Data offset`, `Data length` | where its bytes lie in the file |
//! | `Bytes/pixel` | 2 or 4: little-endian signed integers |
//! | `Samps/line`, `Number of lines` | pixels along x (columns) and y (rows) |
//! | `Scan Size` | `x y unit` (e.g. `40 40 ~m`, `~` standing for µ); older files give one size in the `\*Ciao scan list` |
//! | `Aspect ratio` | `fast:slow` extent of the frame |
//! | `Line direction` | `Trace` or `Retrace` |
//! | `Frame direction` | `Down` or `Up`: the slow scan direction |
//! | `Scan line` | `Main` or `Interleave` (a second, lifted pass) |
//! | `@2:Image Data` | `S [internal] "channel name"` |
//! | `@2:Z scale` | `V [soft scale] (…) hard value V` |
//!
//! A stored integer `n` is the value `n · hard value / 2^(8 · bytes per pixel) · soft
//! value`, where the soft value is the parameter named in brackets (`@Sens. Zscan: V
//! 12.75 nm/V` in the scanner list), and the unit is the soft value's without `/V` (metres
//! after folding the prefix). Without a soft scale, or with one that has no unit, the value
//! stays in the hard value's unit.
//! This matches Gwyddion's and pySPM's readings. `@2:Z offset` is not applied (it only
//! shifts the values) but is kept in the metadata when it is not zero.
//!
//! # Orientation (matches Gwyddion's import)
//!
//! Lines are stored by position: the first stored line is the bottom of the frame, each
//! line left to right, for trace and retrace alike. dhct flips the rows so that row 0 is the
//! top. The trace runs right, the retrace left; the slow direction is `Frame direction`.
//!
//! # Geometry
//!
//! Pitch = scan size / pixels; for an `Aspect ratio` other than 1:1 the slow size is the
//! scan size times slow/fast. Readers disagree there (Gwyddion and pySPM differ), so the
//! scale is then marked [`ValueSource::Assumed`] with the reason under
//! [`ASSUMED_SCALE_KEY`]. `Scan rate` of the `\*Ciao scan list` counts trace-and-retrace
//! cycles per second, so one line in one direction takes `1 / (2 · Scan rate)` (this gives
//! the header's `Tip velocity` = 2 · scan size · rate); the pixel period is that /
//! `Samps/line`, no turnaround. Without a scan rate or frame direction the placeholder
//! [`ASSUMED_PIXEL_PERIOD`] or slow direction down is used, timing marked assumed. A trace and
//! a retrace image of one channel, pass and size form one [`ScanPair`]; others stand alone.

pub mod header;

use std::collections::BTreeMap;

use dhct_scan::{FileFormat, ImageChannel, ScanDirection, ScanGeometry, ScanPair, ValueSource};

use crate::bytes::checked_data_len;
use crate::iso28600::{parse_number, parse_unit};
use crate::limits::{Budget, ReadLimits};
use crate::placeholders::{
    ASSUMED_PIXEL_PERIOD, ASSUMED_SCALE_KEY, ASSUMED_TIMING_KEY, PLAUSIBLE_PITCH_M,
    PLAUSIBLE_PIXEL_PERIOD_S, note, plausible,
};
use crate::{ReadError, ScanFile};
use header::{Section, parse_ciao_value, parse_sections, parse_selection};

const FORMAT: FileFormat = FileFormat::Nanoscope;
/// How a Nanoscope header starts (some files use `?` for the backslash).
pub const MAGICS: [&[u8]; 2] = [b"\\*File list", b"?*File list"];
const END: &[u8] = b"*File list end";
const IMAGE_SECTION: &str = "Ciao image list";
const SCAN_SECTION: &str = "Ciao scan list";

/// One `\*Ciao image list`, checked against the file before anything is decoded.
#[derive(Debug)]
struct Image {
    name: String,
    interleave: bool,
    retrace: bool,
    columns: usize,
    rows: usize,
    bytes_per_pixel: usize,
    offset: usize,
    /// Metres along x and y.
    size: (f64, f64),
    /// Why the size is an assumption, if it is.
    size_doubt: Option<String>,
    slow: Option<ScanDirection>,
    /// Physical value of one stored unit, and the physical unit.
    factor: f64,
    unit: String,
}

/// Reads a Nanoscope image file: one [`ScanPair`] per channel (see the module docs).
pub fn read(bytes: &[u8]) -> Result<ScanFile, ReadError> {
    read_limited(bytes, &ReadLimits::default())
}

/// [`read`] under `limits` (see [`crate::limits`]).
pub fn read_limited(bytes: &[u8], limits: &ReadLimits) -> Result<ScanFile, ReadError> {
    let mut budget = Budget::new(limits, bytes.len())?;
    if !MAGICS.iter().any(|m| bytes.starts_with(m)) {
        return Err(ReadError::wrong_format(
            FORMAT,
            "the file does not start with \\*File list",
        ));
    }
    let end = find(bytes, END).ok_or_else(|| ReadError::Truncated {
        format: FORMAT,
        what: "the header end \\*File list end".to_string(),
        offset: bytes.len() as u64,
        needed: END.len() as u64,
        len: bytes.len() as u64,
    })?;
    let text: String = bytes[..end + END.len()]
        .iter()
        .map(|&b| char::from(b))
        .collect();
    let sections = parse_sections(&text);
    let mut metadata = metadata(&sections);
    let images = sections
        .iter()
        .filter(|s| s.name.eq_ignore_ascii_case(IMAGE_SECTION))
        .map(|s| image(s, &sections, bytes.len()))
        .collect::<Result<Vec<_>, _>>()?;
    if images.is_empty() {
        return Err(ReadError::NoImage {
            format: FORMAT,
            reason: "the header has no \\*Ciao image list section (force curves and \
                     spectra are not images)"
                .to_string(),
        });
    }
    for image in &images {
        budget.charge_images(FORMAT, image.columns as u64, image.rows as u64, 1, 0)?;
    }
    let line_time = line_time(&sections, &mut metadata)?;
    let mut pairs = Vec::new();
    let mut used = vec![false; images.len()];
    for i in 0..images.len() {
        if used[i] {
            continue;
        }
        used[i] = true;
        let a = &images[i];
        let partner = (0..images.len()).find(|&j| {
            let b = &images[j];
            !used[j]
                && (b.name.as_str(), b.interleave, b.columns, b.rows, b.size)
                    == (a.name.as_str(), a.interleave, a.columns, a.rows, a.size)
                && b.retrace != a.retrace
        });
        if let Some(j) = partner {
            used[j] = true;
        }
        let (trace, retrace) = match (a.retrace, partner) {
            (false, j) => (Some(a), j.map(|j| &images[j])),
            (true, j) => (j.map(|j| &images[j]), Some(a)),
        };
        let geometry = geometry(a, line_time, &mut metadata)?;
        let decode = |image: Option<&Image>| image.map(|im| decode(bytes, im)).transpose();
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

/// Reads one image section's keys and checks its data range against the file.
fn image(section: &Section, all: &[Section], file_len: usize) -> Result<Image, ReadError> {
    let corrupt = |what: String| ReadError::corrupt(FORMAT, format!("image section: {what}"));
    let count = |key: &str| -> Result<u64, ReadError> {
        section
            .get(key)
            .and_then(|v| v.trim().parse::<u64>().ok())
            .ok_or_else(|| {
                corrupt(format!(
                    "{key} must be an integer, got {:?}",
                    section.get(key)
                ))
            })
    };
    let (columns, rows) = (count("Samps/line")?, count("Number of lines")?);
    let (offset, stated_len) = (count("Data offset")?, count("Data length")?);
    if columns == 0 || rows == 0 {
        return Err(ReadError::NoImage {
            format: FORMAT,
            reason: format!("an image of {columns} x {rows} px"),
        });
    }
    let bytes_per_pixel = match section.get("Bytes/pixel").map(str::trim) {
        Some("2") => 2,
        Some("4") => 4,
        None if stated_len == columns.saturating_mul(rows).saturating_mul(2) => 2,
        None if stated_len == columns.saturating_mul(rows).saturating_mul(4) => 4,
        other => {
            return Err(ReadError::unsupported(
                FORMAT,
                format!("Bytes/pixel {other:?} (dhct reads 2 and 4)"),
            ));
        }
    };
    let len = checked_data_len(FORMAT, rows, columns, bytes_per_pixel)?;
    if len > stated_len {
        return Err(corrupt(format!(
            "{columns} x {rows} px of {bytes_per_pixel} bytes need {len} bytes but Data length is {stated_len}"
        )));
    }
    if offset
        .checked_add(len)
        .is_none_or(|end| end > file_len as u64)
    {
        return Err(ReadError::Truncated {
            format: FORMAT,
            what: format!("image of {columns} x {rows} px"),
            offset,
            needed: len,
            len: file_len as u64,
        });
    }
    let (size, size_doubt) = scan_size(section, all)?;
    let (factor, unit) = z_scale(section, all, bytes_per_pixel)?;
    let slow = match section.get("Frame direction").map(str::trim) {
        Some(d) if d.eq_ignore_ascii_case("down") => Some(ScanDirection::Down),
        Some(d) if d.eq_ignore_ascii_case("up") => Some(ScanDirection::Up),
        _ => None,
    };
    Ok(Image {
        name: section
            .get("Image Data")
            .and_then(parse_selection)
            .unwrap_or_else(|| "Image".to_string()),
        interleave: section
            .get("Scan line")
            .is_some_and(|l| l.trim().eq_ignore_ascii_case("interleave")),
        retrace: section
            .get("Line direction")
            .is_some_and(|d| d.trim().eq_ignore_ascii_case("retrace")),
        columns: columns as usize,
        rows: rows as usize,
        bytes_per_pixel: bytes_per_pixel as usize,
        offset: offset as usize,
        size,
        size_doubt,
        slow,
        factor,
        unit,
    })
}

/// The frame size in metres and, for an aspect ratio other than 1:1, why it is in doubt.
fn scan_size(
    section: &Section,
    all: &[Section],
) -> Result<((f64, f64), Option<String>), ReadError> {
    let scan_list = all
        .iter()
        .find(|s| s.name.eq_ignore_ascii_case(SCAN_SECTION));
    let text = section
        .get("Scan Size")
        .or_else(|| scan_list.and_then(|s| s.get("Scan Size")))
        .ok_or_else(|| ReadError::corrupt(FORMAT, "no Scan Size in the header"))?;
    let invalid = || {
        ReadError::corrupt(
            FORMAT,
            format!("Scan Size \"{text}\" is not a size in a length unit"),
        )
    };
    let words: Vec<&str> = text.split_whitespace().collect();
    let numbers: Vec<f64> = words.iter().map_while(|w| parse_number(w)).collect();
    let unit = words.get(numbers.len()).copied().unwrap_or("");
    let (base, prefix) = parse_unit(&normalise_unit(unit));
    if base != "m" || numbers.is_empty() {
        return Err(invalid());
    }
    let x = numbers[0] * prefix;
    let y = numbers.get(1).copied().unwrap_or(numbers[0]) * prefix;
    let aspect = section
        .get("Aspect ratio")
        .or_else(|| scan_list.and_then(|s| s.get("Aspect ratio")));
    let ratio = aspect
        .and_then(|a| a.split_once(':'))
        .and_then(|(fast, slow)| Some((parse_number(fast)?, parse_number(slow)?)))
        .filter(|(f, s)| *f > 0.0 && *s > 0.0);
    match ratio {
        Some((fast, slow)) if fast != slow => Ok((
            (x, y * slow / fast),
            Some(format!(
                "Aspect ratio {} (the slow size is taken as Scan Size x {slow}/{fast}; \
                 readers disagree on such files)",
                aspect.unwrap_or_default()
            )),
        )),
        _ => Ok(((x, y), None)),
    }
}

/// The value of one stored unit and the physical unit (see the module docs).
fn z_scale(
    section: &Section,
    all: &[Section],
    bytes_per_pixel: u64,
) -> Result<(f64, String), ReadError> {
    let text = section
        .get("Z scale")
        .ok_or_else(|| ReadError::corrupt(FORMAT, "an image section has no @2:Z scale"))?;
    let scale = parse_ciao_value(text)
        .filter(|v| v.value.is_finite())
        .ok_or_else(|| {
            ReadError::corrupt(FORMAT, format!("Z scale \"{text}\" is not a CIAO value"))
        })?;
    let per_unit = scale.value / 2f64.powi(8 * bytes_per_pixel as i32);
    let Some(soft_name) = &scale.soft_scale else {
        let (unit, prefix) = parse_unit(&normalise_unit(&scale.unit));
        return Ok((per_unit * prefix, unit));
    };
    let soft_text = all
        .iter()
        .find_map(|s| s.get(&format!("@{soft_name}")))
        .ok_or_else(|| {
            ReadError::corrupt(
                FORMAT,
                format!("Z scale refers to \"{soft_name}\", which the header lacks"),
            )
        })?;
    let soft = parse_ciao_value(soft_text)
        .filter(|v| v.value.is_finite())
        .ok_or_else(|| {
            ReadError::corrupt(
                FORMAT,
                format!("{soft_name} \"{soft_text}\" is not a CIAO value"),
            )
        })?;
    // A soft scale without a unit (`@Sens. Friction: V 1.000000`) leaves the volts.
    let unit = match soft.unit.as_str() {
        "" => scale.unit.as_str(),
        unit => unit.strip_suffix("/V").unwrap_or(unit),
    };
    let (unit, prefix) = parse_unit(&normalise_unit(unit));
    Ok((per_unit * soft.value * prefix, unit))
}

/// Bruker writes µ as `~` and the degree sign as `º`.
fn normalise_unit(unit: &str) -> String {
    let unit = unit.replace('~', "µ");
    match unit.as_str() {
        "º" | "°" => "deg".to_string(),
        _ => unit,
    }
}

/// One line in one direction, seconds, from `Scan rate` (None, with a note, when absent).
fn line_time(
    sections: &[Section],
    metadata: &mut BTreeMap<String, String>,
) -> Result<Option<f64>, ReadError> {
    let rate = sections
        .iter()
        .find(|s| s.name.eq_ignore_ascii_case(SCAN_SECTION))
        .and_then(|s| s.get("Scan rate"));
    match rate {
        None => {
            note(
                metadata,
                ASSUMED_TIMING_KEY,
                "no Scan rate in the \\*Ciao scan list",
            );
            Ok(None)
        }
        Some(text) => match parse_number(text.split_whitespace().next().unwrap_or("")) {
            Some(hz) if hz.is_finite() && hz > 0.0 => Ok(Some(0.5 / hz)),
            _ => Err(ReadError::corrupt(
                FORMAT,
                format!("Scan rate \"{text}\" is not a positive frequency in Hz"),
            )),
        },
    }
}

/// The geometry of an image (shared by its pair).
fn geometry(
    image: &Image,
    line_time: Option<f64>,
    metadata: &mut BTreeMap<String, String>,
) -> Result<ScanGeometry, ReadError> {
    let pitch = (
        image.size.0 / image.columns as f64,
        image.size.1 / image.rows as f64,
    );
    if !(plausible(pitch.0, &PLAUSIBLE_PITCH_M) && plausible(pitch.1, &PLAUSIBLE_PITCH_M)) {
        return Err(ReadError::corrupt(
            FORMAT,
            format!(
                "Scan Size {:e} x {:e} m over {} x {} px gives a pitch outside {:e}..{:e} m",
                image.size.0,
                image.size.1,
                image.columns,
                image.rows,
                PLAUSIBLE_PITCH_M.start(),
                PLAUSIBLE_PITCH_M.end()
            ),
        ));
    }
    let scale_source = match &image.size_doubt {
        Some(why) => {
            note(metadata, ASSUMED_SCALE_KEY, why.clone());
            ValueSource::Assumed
        }
        None => ValueSource::Stated,
    };
    if image.slow.is_none() {
        note(
            metadata,
            ASSUMED_TIMING_KEY,
            "no Frame direction (Up or Down); down assumed",
        );
    }
    let pixel_period = match line_time.map(|t| t / image.columns as f64) {
        Some(p) if plausible(p, &PLAUSIBLE_PIXEL_PERIOD_S) => p,
        Some(p) => {
            return Err(ReadError::corrupt(
                FORMAT,
                format!(
                    "Scan rate gives a pixel period of {p:e} s, outside {:e}..{:e} s",
                    PLAUSIBLE_PIXEL_PERIOD_S.start(),
                    PLAUSIBLE_PIXEL_PERIOD_S.end()
                ),
            ));
        }
        None => ASSUMED_PIXEL_PERIOD,
    };
    let timing_source = if line_time.is_some() && image.slow.is_some() {
        ValueSource::Stated
    } else {
        ValueSource::Assumed
    };
    ScanGeometry::new(
        image.columns,
        image.rows,
        pitch.0,
        pitch.1,
        pixel_period,
        ScanDirection::Right,
        image.slow.unwrap_or(ScanDirection::Down),
    )
    .map(|g| {
        g.with_scale_source(scale_source)
            .with_timing_source(timing_source)
    })
    .map_err(|source| ReadError::geometry(FORMAT, source))
}

/// Decodes an image into display orientation (stored bottom line first).
fn decode(bytes: &[u8], image: &Image) -> Result<ImageChannel, ReadError> {
    let step = image.bytes_per_pixel;
    let len = image.columns * image.rows * step;
    let data = &bytes[image.offset..image.offset + len];
    let value = |chunk: &[u8]| {
        let raw = match step {
            2 => f64::from(i16::from_le_bytes([chunk[0], chunk[1]])),
            _ => f64::from(i32::from_le_bytes([chunk[0], chunk[1], chunk[2], chunk[3]])),
        };
        raw * image.factor
    };
    let mut values = Vec::with_capacity(image.columns * image.rows);
    for line in data.chunks_exact(image.columns * step).rev() {
        values.extend(line.chunks_exact(step).map(value));
    }
    let name = if image.interleave {
        format!("{} (interleave)", image.name)
    } else {
        image.name.clone()
    };
    ImageChannel::from_row_major(name, image.unit.clone(), image.rows, image.columns, values)
        .map_err(|source| ReadError::geometry(FORMAT, source))
}

/// Header values worth showing a user.
fn metadata(sections: &[Section]) -> BTreeMap<String, String> {
    let mut m = BTreeMap::new();
    let find = |section: &str, key: &str| {
        sections
            .iter()
            .find(|s| s.name.eq_ignore_ascii_case(section))
            .and_then(|s| s.get(key))
            .filter(|v| !v.trim().is_empty())
            .map(str::to_string)
    };
    for (section, key, name) in [
        ("File list", "Version", "nanoscope version"),
        ("File list", "Date", "date"),
        ("Equipment list", "Description", "microscope"),
        (SCAN_SECTION, "Operating mode", "operating mode"),
        (SCAN_SECTION, "Scan rate", "scan rate (Hz)"),
        (SCAN_SECTION, "Tip velocity", "tip velocity"),
        (SCAN_SECTION, "Rotate Ang.", "rotate angle"),
        (SCAN_SECTION, "X offset", "x offset"),
        (SCAN_SECTION, "Y offset", "y offset"),
    ] {
        if let Some(value) = find(section, key) {
            m.insert(name.to_string(), value);
        }
    }
    let offsets: Vec<String> = sections
        .iter()
        .filter(|s| s.name.eq_ignore_ascii_case(IMAGE_SECTION))
        .filter_map(|s| s.get("Z offset"))
        .filter(|v| parse_ciao_value(v).is_some_and(|v| v.value != 0.0))
        .map(str::to_string)
        .collect();
    if !offsets.is_empty() {
        m.insert("z offsets (not applied)".to_string(), offsets.join("; "));
    }
    m
}

/// Position of the first `needle` in `haystack`.
fn find(haystack: &[u8], needle: &[u8]) -> Option<usize> {
    haystack.windows(needle.len()).position(|w| w == needle)
}
