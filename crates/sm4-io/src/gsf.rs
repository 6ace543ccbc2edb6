//! Gwyddion Simple Field (`.gsf`) reader and writer.
//!
//! # Format (Gwyddion user guide, "Simple Field Files")
//!
//! 1. The magic line `Gwyddion Simple Field 1.0` and a line feed.
//! 2. Header lines `name = value` (LF-terminated, UTF-8; whitespace around names and values
//!    is ignored; names are case-sensitive). `XRes` and `YRes` (pixels along x and y) are
//!    mandatory; `XReal`, `YReal` (physical size), `XOffset`, `YOffset`, `XYUnits`, `ZUnits`
//!    and `Title` are optional. Readers ignore names they do not know.
//! 3. One to four NUL bytes, so that the data start at a multiple of 4 bytes.
//! 4. `XRes · YRes` little-endian IEEE 32-bit floats, row by row, the first row at the top.
//!
//! # dhct keys
//!
//! GSF has no scan timing. dhct's writer adds keys Gwyddion ignores, so that a file written by
//! dhct reads back with the same [`ScanGeometry`]:
//!
//! | key | value |
//! |---|---|
//! | `DHCT_Pass` | `trace` or `retrace` |
//! | `DHCT_PixelPeriod` | seconds per pixel along the fast axis |
//! | `DHCT_TurnaroundTime` | seconds at each end of a line |
//! | `DHCT_TraceFast`, `DHCT_SlowDirection` | `right`, `left`, `down` or `up` |
//! | `DHCT_ScanAngle` | radians, counter-clockwise |
//! | `DHCT_OffsetX`, `DHCT_OffsetY` | scan-frame centre, metres |
//! | `DHCT_StartTime` | start of the frame's first line, seconds since 1970 (optional) |
//! | `DHCT_ScaleSource`, `DHCT_TimingSource` | `stated` or `assumed` |
//!
//! A GSF file without them (e.g. written by Gwyddion) gets the placeholder pixel period
//! [`ASSUMED_PIXEL_PERIOD`], fast direction right, slow direction down, timing
//! [`ValueSource::Assumed`]. Its scale is [`ValueSource::Stated`] when `XReal`/`YReal` are
//! given in a length unit (or without `XYUnits`); when both are missing or `XYUnits` is not
//! a length it is [`ASSUMED_PITCH`], assumed, with the reason under
//! [`crate::ASSUMED_SCALE_KEY`]. An `XReal`/`YReal` that is present but not a number, not
//! finite, zero, or gives a pitch outside [`crate::PLAUSIBLE_PITCH_M`], or only one of the
//! two, is an error: a corrupt size never silently becomes 1 Å per pixel. `DHCT_*` numbers
//! outside their plausible ranges (`PLAUSIBLE_*` in the crate root) are errors too.
//! Unit prefixes (`XYUnits = nm`, `ZUnits = pA`) are folded into the values.

use std::collections::BTreeMap;
use std::io::Write;
use std::ops::RangeInclusive;

use dhct_scan::{
    FileFormat, ImageChannel, ScanDirection, ScanGeometry, ScanPair, ScanPass, ValueSource,
};

use crate::bytes::checked_data_len;
use crate::iso28600::{parse_number, parse_unit};
use crate::{ReadError, ScanFile, WriteError};

use crate::limits::{Budget, ReadLimits};
use crate::placeholders::{
    ASSUMED_PITCH, ASSUMED_PIXEL_PERIOD, ASSUMED_SCALE_KEY, ASSUMED_TIMING_KEY, PLAUSIBLE_PITCH_M,
    PLAUSIBLE_PIXEL_PERIOD_S, PLAUSIBLE_SCAN_ANGLE_RAD, PLAUSIBLE_TURNAROUND_S, note, plausible,
};

const FORMAT: FileFormat = FileFormat::Gsf;
const MAGIC: &[u8] = b"Gwyddion Simple Field 1.0\n";

/// Name given to the channel when the file has no `Title`.
pub const DEFAULT_TITLE: &str = "GSF image";

/// Reads a GSF file as one image (see the module docs for the geometry rules).
pub fn read(bytes: &[u8]) -> Result<ScanFile, ReadError> {
    read_limited(bytes, &ReadLimits::default())
}

/// [`read`] under `limits` (see [`crate::limits`]).
pub fn read_limited(bytes: &[u8], limits: &ReadLimits) -> Result<ScanFile, ReadError> {
    let mut budget = Budget::new(limits, bytes.len())?;
    let (header_start, nul, data_start) = header_extent(bytes)?;
    let header_text = String::from_utf8_lossy(bytes.get(header_start..nul).unwrap_or(&[]));
    let fields = parse_fields(&header_text)?;
    let get = |name: &str| {
        fields
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v.as_str())
    };
    let (x_res, y_res) = (resolution(&get, "XRes")?, resolution(&get, "YRes")?);
    budget.charge_images(FORMAT, x_res, y_res, 1, 0)?;
    let data_len = checked_data_len(FORMAT, y_res, x_res, 4)?;
    let data = bytes
        .get(data_start..)
        .and_then(|rest| rest.get(..usize::try_from(data_len).ok()?))
        .ok_or_else(|| ReadError::Truncated {
            format: FORMAT,
            what: format!("{x_res} x {y_res} float32 values"),
            offset: data_start as u64,
            needed: data_len,
            len: bytes.len() as u64,
        })?;
    // Both fit: their product times 4 was just sliced out of the file.
    let (columns, rows) = match (usize::try_from(x_res), usize::try_from(y_res)) {
        (Ok(c), Ok(r)) => (c, r),
        _ => {
            return Err(ReadError::corrupt(
                FORMAT,
                "image too large for this machine",
            ));
        }
    };

    let (z_unit, z_factor) = parse_unit(get("ZUnits").unwrap_or(""));
    let values: Vec<f64> = data
        .chunks_exact(4)
        .map(|c| {
            let mut raw = [0u8; 4];
            for (dst, src) in raw.iter_mut().zip(c) {
                *dst = *src;
            }
            f64::from(f32::from_le_bytes(raw)) * z_factor
        })
        .collect();
    let name = get("Title")
        .filter(|t| !t.is_empty())
        .unwrap_or(DEFAULT_TITLE);
    let channel = ImageChannel::from_row_major(name, z_unit, rows, columns, values)
        .map_err(|source| ReadError::geometry(FORMAT, source))?;

    let mut metadata = BTreeMap::new();
    let geometry = build_geometry(&get, columns, rows, &mut metadata)?;
    let pair = match pass(get("DHCT_Pass"))? {
        ScanPass::Trace => ScanPair::new(geometry, channel, None),
        ScanPass::Retrace => ScanPair::retrace_only(geometry, channel),
    }
    .map_err(|source| ReadError::geometry(FORMAT, source))?;
    add_unknown_fields(&fields, &mut metadata);
    Ok(ScanFile {
        format: FORMAT,
        pairs: vec![pair],
        metadata,
    })
}

/// Checks the magic line and the NUL padding; returns where the header text starts, the
/// offset of its first NUL and where the data start (the next multiple of 4).
fn header_extent(bytes: &[u8]) -> Result<(usize, usize, usize), ReadError> {
    let start = if bytes.starts_with(b"\xEF\xBB\xBF") {
        3
    } else {
        0
    };
    let header_start = start + MAGIC.len();
    if bytes.get(start..header_start) != Some(MAGIC) {
        let reason = "the file does not start with the line \"Gwyddion Simple Field 1.0\"";
        return Err(ReadError::wrong_format(FORMAT, reason));
    }
    let nul = bytes
        .get(header_start..)
        .and_then(|rest| rest.iter().position(|&b| b == 0))
        .map(|i| header_start + i)
        .ok_or_else(|| ReadError::Truncated {
            format: FORMAT,
            what: "NUL padding that ends the header".to_string(),
            offset: bytes.len() as u64,
            needed: 1,
            len: bytes.len() as u64,
        })?;
    let data_start = nul + (4 - nul % 4);
    match bytes.get(nul..data_start) {
        Some(padding) if padding.iter().all(|&b| b == 0) => Ok((header_start, nul, data_start)),
        Some(_) => Err(ReadError::corrupt(
            FORMAT,
            format!("header padding at bytes {nul}..{data_start} is not all NUL"),
        )),
        None => Err(ReadError::Truncated {
            format: FORMAT,
            what: "NUL padding that ends the header".to_string(),
            offset: nul as u64,
            needed: (data_start - nul) as u64,
            len: bytes.len() as u64,
        }),
    }
}

/// The `name = value` lines of the header, in order.
fn parse_fields(header_text: &str) -> Result<Vec<(String, String)>, ReadError> {
    let mut fields: Vec<(String, String)> = Vec::new();
    for line in header_text.split('\n') {
        let line = line.trim();
        if line.is_empty() {
            continue;
        }
        let (name, value) = line.split_once('=').ok_or_else(|| {
            ReadError::corrupt(
                FORMAT,
                format!(
                    "header line \"{}\" is not of the form name = value",
                    shorten(line)
                ),
            )
        })?;
        fields.push((name.trim().to_string(), value.trim().to_string()));
    }
    Ok(fields)
}

/// The mandatory positive pixel count `name` (`XRes` or `YRes`).
fn resolution<'a>(get: &impl Fn(&str) -> Option<&'a str>, name: &str) -> Result<u64, ReadError> {
    let text = get(name).ok_or_else(|| {
        ReadError::corrupt(FORMAT, format!("header lacks the mandatory field {name}"))
    })?;
    match text.parse::<u64>() {
        Ok(n) if n > 0 => Ok(n),
        _ => Err(ReadError::corrupt(
            FORMAT,
            format!(
                "{name} must be a positive integer, got \"{}\"",
                shorten(text)
            ),
        )),
    }
}

/// The pass `DHCT_Pass` names (trace when absent).
fn pass(text: Option<&str>) -> Result<ScanPass, ReadError> {
    match text {
        None => Ok(ScanPass::Trace),
        Some(p) if p.eq_ignore_ascii_case("trace") => Ok(ScanPass::Trace),
        Some(p) if p.eq_ignore_ascii_case("retrace") => Ok(ScanPass::Retrace),
        Some(p) => Err(ReadError::corrupt(
            FORMAT,
            format!("DHCT_Pass must be trace or retrace, got \"{}\"", shorten(p)),
        )),
    }
}

/// Copies the header fields dhct does not interpret into the metadata.
fn add_unknown_fields(fields: &[(String, String)], metadata: &mut BTreeMap<String, String>) {
    for (name, value) in fields {
        let known = matches!(
            name.as_str(),
            "XRes" | "YRes" | "XReal" | "YReal" | "XYUnits" | "ZUnits" | "Title"
        ) || name.starts_with("DHCT_");
        if !known {
            metadata.insert(name.clone(), value.clone());
        }
    }
}

/// The scan geometry from the header fields (`get`); assumptions are noted in `metadata`.
fn build_geometry<'a>(
    get: &impl Fn(&str) -> Option<&'a str>,
    columns: usize,
    rows: usize,
    metadata: &mut BTreeMap<String, String>,
) -> Result<ScanGeometry, ReadError> {
    let geometry_error = |source| ReadError::geometry(FORMAT, source);
    let (pitch_x, pitch_y, scale_source) = pitches(get, columns, rows, metadata)?;
    let mut scale_source = scale_source;
    let dhct_number = |name: &str| -> Result<Option<f64>, ReadError> {
        match get(name) {
            None => Ok(None),
            Some(text) => parse_number(text)
                .filter(|v| v.is_finite())
                .map(Some)
                .ok_or_else(|| {
                    ReadError::corrupt(
                        FORMAT,
                        format!("{name} must be a number, got \"{}\"", shorten(text)),
                    )
                }),
        }
    };
    let dhct_direction = |name: &str, default: ScanDirection| match get(name) {
        None => Ok(default),
        Some(text) => ScanDirection::parse(text).ok_or_else(|| {
            ReadError::corrupt(
                FORMAT,
                format!(
                    "{name} must be right, left, down or up, got \"{}\"",
                    shorten(text)
                ),
            )
        }),
    };
    let dhct_source = |name: &str, default: ValueSource| match get(name) {
        None => Ok(default),
        Some(text) if text.eq_ignore_ascii_case("stated") => Ok(ValueSource::Stated),
        Some(text) if text.eq_ignore_ascii_case("assumed") => Ok(ValueSource::Assumed),
        Some(text) => Err(ReadError::corrupt(
            FORMAT,
            format!(
                "{name} must be stated or assumed, got \"{}\"",
                shorten(text)
            ),
        )),
    };

    let in_range =
        |name: &str, value: Option<f64>, range: &RangeInclusive<f64>, unit: &str| match value {
            Some(v) if !plausible(v, range) => Err(ReadError::corrupt(
                FORMAT,
                format!(
                    "{name} = {v} {unit} lies outside {:e}..={:e} {unit}",
                    range.start(),
                    range.end()
                ),
            )),
            other => Ok(other),
        };
    let pixel_period = in_range(
        "DHCT_PixelPeriod",
        dhct_number("DHCT_PixelPeriod")?,
        &PLAUSIBLE_PIXEL_PERIOD_S,
        "s",
    )?;
    let (pixel_period, mut timing_source) = match pixel_period {
        Some(p) => (p, ValueSource::Stated),
        None => {
            note(metadata, ASSUMED_TIMING_KEY, "GSF carries no scan timing");
            (ASSUMED_PIXEL_PERIOD, ValueSource::Assumed)
        }
    };
    timing_source = dhct_source("DHCT_TimingSource", timing_source)?;
    if scale_source == ValueSource::Stated {
        scale_source = dhct_source("DHCT_ScaleSource", scale_source)?;
    }
    let trace_fast = dhct_direction("DHCT_TraceFast", ScanDirection::Right)?;
    let slow = dhct_direction("DHCT_SlowDirection", ScanDirection::Down)?;
    let mut geometry = ScanGeometry::new(
        columns,
        rows,
        pitch_x,
        pitch_y,
        pixel_period,
        trace_fast,
        slow,
    )
    .map_err(geometry_error)?;
    let turnaround = dhct_number("DHCT_TurnaroundTime")?;
    if let Some(turnaround) = in_range(
        "DHCT_TurnaroundTime",
        turnaround,
        &PLAUSIBLE_TURNAROUND_S,
        "s",
    )? {
        geometry = geometry
            .with_turnaround(turnaround)
            .map_err(geometry_error)?;
    }
    let angle = dhct_number("DHCT_ScanAngle")?;
    if let Some(angle) = in_range("DHCT_ScanAngle", angle, &PLAUSIBLE_SCAN_ANGLE_RAD, "rad")? {
        geometry = geometry.with_scan_angle(angle).map_err(geometry_error)?;
    }
    let offset_x = dhct_number("DHCT_OffsetX")?;
    let offset_y = dhct_number("DHCT_OffsetY")?;
    if offset_x.is_some() || offset_y.is_some() {
        geometry = geometry
            .with_offset(offset_x.unwrap_or(0.0), offset_y.unwrap_or(0.0))
            .map_err(geometry_error)?;
    }
    let start = dhct_number("DHCT_StartTime")?;
    Ok(geometry
        .with_scale_source(scale_source)
        .with_timing_source(timing_source)
        .with_start_time(start))
}

/// The pixel pitches from `XReal`/`YReal` (in `XYUnits`). Both missing, or a non-length
/// `XYUnits`: [`ASSUMED_PITCH`], assumed, noted in `metadata`. Present but not a number,
/// not finite, zero, negative-and-zero or giving a pitch outside [`PLAUSIBLE_PITCH_M`]: an
/// error naming the field (a corrupt size must not silently become 1 Å per pixel).
fn pitches<'a>(
    get: &impl Fn(&str) -> Option<&'a str>,
    columns: usize,
    rows: usize,
    metadata: &mut BTreeMap<String, String>,
) -> Result<(f64, f64, ValueSource), ReadError> {
    let (xy_unit, xy_factor) = parse_unit(get("XYUnits").unwrap_or("m"));
    let real = |name: &str, n: usize| -> Result<Option<f64>, ReadError> {
        let Some(text) = get(name) else {
            return Ok(None);
        };
        let pitch = parse_number(text).map(|v| v.abs() * xy_factor / n as f64);
        match pitch {
            Some(p) if xy_unit != "m" || plausible(p, &PLAUSIBLE_PITCH_M) => Ok(Some(p)),
            _ => Err(ReadError::corrupt(
                FORMAT,
                format!(
                    "{name} = \"{}\" is not a size giving a pixel pitch in {:e}..={:e} m",
                    shorten(text),
                    PLAUSIBLE_PITCH_M.start(),
                    PLAUSIBLE_PITCH_M.end()
                ),
            )),
        }
    };
    let (x, y) = (real("XReal", columns)?, real("YReal", rows)?);
    let assumed = |metadata: &mut BTreeMap<String, String>, why: String| {
        note(metadata, ASSUMED_SCALE_KEY, why);
        Ok((ASSUMED_PITCH, ASSUMED_PITCH, ValueSource::Assumed))
    };
    match (x, y) {
        (Some(px), Some(py)) if xy_unit == "m" => Ok((px, py, ValueSource::Stated)),
        (Some(_), Some(_)) => assumed(
            metadata,
            format!("XYUnits \"{}\" is not a length", shorten(&xy_unit)),
        ),
        (None, None) => assumed(metadata, "no XReal/YReal in the header".into()),
        _ => Err(ReadError::corrupt(
            FORMAT,
            "the header gives only one of XReal and YReal",
        )),
    }
}

/// Writes `channel` as the trace image of `geometry` (see [`write_pass`]).
pub fn write<W: Write>(
    channel: &ImageChannel,
    geometry: &ScanGeometry,
    w: &mut W,
) -> Result<(), WriteError> {
    write_pass(channel, geometry, ScanPass::Trace, w)
}

/// Writes `channel` (an image of `pass`) as a GSF file: `XReal`/`YReal` in metres,
/// `ZUnits` = the channel unit, `Title` = the channel name (control characters replaced by
/// spaces), the data as 32-bit floats (NaN kept), plus the `DHCT_*` keys that preserve the
/// rest of `geometry`. Fails if the channel's size differs from the geometry's.
pub fn write_pass<W: Write>(
    channel: &ImageChannel,
    geometry: &ScanGeometry,
    pass: ScanPass,
    w: &mut W,
) -> Result<(), WriteError> {
    check_size(channel, geometry)?;
    write_grid(channel, geometry, pass, None, w)
}

/// Writes `channel`, a corrected image of `pass` on a grid of `geometry`'s pitch whose
/// pixel `(0, 0)` is the scan grid's pixel `origin_px` (`[column, row]`, negative left of
/// or above it), as a GSF file: its own size in `XRes`/`XReal`, the origin in `XOffset`/
/// `YOffset` (metres), the scan's timing and directions in the `DHCT_*` keys.
pub fn write_extended<W: Write>(
    channel: &ImageChannel,
    geometry: &ScanGeometry,
    pass: ScanPass,
    origin_px: [i64; 2],
    w: &mut W,
) -> Result<(), WriteError> {
    let offset = [
        origin_px[0] as f64 * geometry.pitch_x(),
        origin_px[1] as f64 * geometry.pitch_y(),
    ];
    write_grid(channel, geometry, pass, Some(offset), w)
}

fn check_size(channel: &ImageChannel, geometry: &ScanGeometry) -> Result<(), WriteError> {
    if channel.rows() != geometry.rows() || channel.columns() != geometry.columns() {
        return Err(WriteError::Unrepresentable {
            format: FORMAT,
            reason: format!(
                "image is {} x {} px but the geometry says {} x {} px",
                channel.columns(),
                channel.rows(),
                geometry.columns(),
                geometry.rows()
            ),
        });
    }
    Ok(())
}

/// The GSF of `channel` with the scan facts of `geometry` and `pass`; `offset` (metres)
/// places a grid other than the scan's own.
fn write_grid<W: Write>(
    channel: &ImageChannel,
    geometry: &ScanGeometry,
    pass: ScanPass,
    offset: Option<[f64; 2]>,
    w: &mut W,
) -> Result<(), WriteError> {
    let clean = |text: &str| -> String {
        text.chars()
            .map(|c| if c.is_control() { ' ' } else { c })
            .collect::<String>()
            .trim()
            .to_string()
    };
    let direction = |d: ScanDirection| match d {
        ScanDirection::Right => "right",
        ScanDirection::Left => "left",
        ScanDirection::Down => "down",
        ScanDirection::Up => "up",
    };
    let source = |s: ValueSource| match s {
        ValueSource::Stated => "stated",
        ValueSource::Assumed => "assumed",
    };
    let (offset_x, offset_y) = geometry.offset();
    let mut header = String::from_utf8_lossy(MAGIC).into_owned();
    let mut line = |name: &str, value: String| {
        header.push_str(name);
        header.push_str(" = ");
        header.push_str(&value);
        header.push('\n');
    };
    line("XRes", channel.columns().to_string());
    line("YRes", channel.rows().to_string());
    line(
        "XReal",
        format!("{:e}", channel.columns() as f64 * geometry.pitch_x()),
    );
    line(
        "YReal",
        format!("{:e}", channel.rows() as f64 * geometry.pitch_y()),
    );
    if let Some([x, y]) = offset {
        line("XOffset", format!("{x:e}"));
        line("YOffset", format!("{y:e}"));
    }
    line("XYUnits", "m".to_string());
    let unit = clean(&channel.unit);
    if !unit.is_empty() {
        line("ZUnits", unit);
    }
    let title = clean(&channel.name);
    if !title.is_empty() {
        line("Title", title);
    }
    line("DHCT_Pass", pass.name().to_string());
    line("DHCT_PixelPeriod", format!("{:e}", geometry.pixel_period()));
    line(
        "DHCT_TurnaroundTime",
        format!("{:e}", geometry.turnaround_time()),
    );
    line(
        "DHCT_TraceFast",
        direction(geometry.trace_fast()).to_string(),
    );
    line(
        "DHCT_SlowDirection",
        direction(geometry.slow_direction()).to_string(),
    );
    line("DHCT_ScanAngle", format!("{:e}", geometry.scan_angle()));
    line("DHCT_OffsetX", format!("{:e}", offset_x));
    line("DHCT_OffsetY", format!("{:e}", offset_y));
    if let Some(start) = geometry.start_time() {
        line("DHCT_StartTime", format!("{start:.6}"));
    }
    line(
        "DHCT_ScaleSource",
        source(geometry.scale_source()).to_string(),
    );
    line(
        "DHCT_TimingSource",
        source(geometry.timing_source()).to_string(),
    );

    let mut out = header.into_bytes();
    let padding = 4 - out.len() % 4;
    out.extend(std::iter::repeat_n(0u8, padding));
    out.reserve(channel.rows() * channel.columns() * 4);
    for value in channel.z.iter() {
        out.extend_from_slice(&(*value as f32).to_le_bytes());
    }
    w.write_all(&out)?;
    Ok(())
}

fn shorten(text: &str) -> String {
    const MAX: usize = 60;
    if text.chars().count() > MAX {
        format!("{}…", text.chars().take(MAX).collect::<String>())
    } else {
        text.to_string()
    }
}
