//! ISO 28600:2011 "SPM data transfer format" (text) reader for regular single- and
//! multi-channel maps.
//!
//! # Format
//!
//! A text file (ASCII, LF or CRLF line ends) whose first 128 lines are a fixed-position
//! header: every line is one field, identified by its line number, and eleven lines hold
//! fixed labels (`ISO/TC 201 SPM data transfer format` on line 1, `general information` on 2,
//! `scan information` on 16, …, `end of header` on 128). The fields dhct uses:
//!
//! | line | field |
//! |---|---|
//! | 7 | comment (SPM summary) |
//! | 8 | experiment mode: `MAP_SC`, `MAP_MC`, `SPEC_SC`, `SPEC_MC` |
//! | 9–15 | year, month, day, hours, minutes, seconds, hours ahead of GMT (−1 = unknown) |
//! | 17 | scan mode: `REGULAR MAPPING` or `IRREGULAR MAPPING` |
//! | 20, 21 | fast scan axis (`X`/`Y`) and direction (`left to right`, …) |
//! | 22, 23 | slow scan axis and direction (`top to bottom`, …) |
//! | 24, 25 | number of points along X and Y |
//! | 26, 27 | unit of X and Y (an SI unit, possibly prefixed, e.g. `m`, `nm`) |
//! | 28, 29 | field of view along X and Y, in those units |
//! | 30–33 | units and values of the X and Y offsets |
//! | 34 | rotation angle, degrees counter-clockwise |
//! | 35–38 | units and values of scan speed and scan rate |
//! | 39–41 | SPM technique, bias contact, bias voltage (V) |
//! | 50–52 | sample temperature (K), pressure (Pa), humidity (%) |
//! | 69–71 | single-channel map: channel name, z unit, comment |
//! | 88 | data treatment: `raw data`, `pre-treated data`, `post-treated data` |
//! | 94 | multi-channel map: number of channels (up to 8) |
//! | 95 + 3i, 96 + 3i, 97 + 3i | multi-channel map: name, unit and comment of channel i |
//!
//! After the header come the data, one point per line (for a multi-channel map, the channels
//! of a point on one line separated by commas or blanks), then a line `end of experiment`.
//! Values may be written as integers or reals; either way they are in the channel's unit,
//! whose SI prefix (e.g. `nm`) dhct folds into the values (there is no separate z scale in the
//! map format). The units `d` (dimensionless) and `n` (none) mean no unit.
//!
//! Sources: the ISO 28600:2011 field list as implemented by Gwyddion's `iso28600.c`
//! (module 0.4, 2019), which also fixes the point order: the points run row by row from the
//! top-left corner, row 0 at the top, exactly dhct's display orientation.
//!
//! # Geometry
//!
//! * Pixel pitch: field of view / number of points when the axis unit is a length and the
//!   field of view is non-zero ([`ValueSource::Stated`]); otherwise [`ASSUMED_PITCH`]
//!   ([`ValueSource::Assumed`]).
//! * Scan directions: from the fast and slow direction lines (default fast right, slow down).
//! * Pixel period: the format has no line time. When the file states a scan speed in m/s and
//!   its data are not "post-treated", the pixel period is fast pitch / speed
//!   ([`ValueSource::Stated`]); otherwise [`ASSUMED_PIXEL_PERIOD`] and the whole timing
//!   (period and directions) is [`ValueSource::Assumed`]. Files written by image-processing
//!   software (Gwyddion's exporter writes "post-treated data" and "Bogus acquisition
//!   parameters") always get assumed timing.
//! * Offsets are kept in the metadata only: the standard does not say which point of the
//!   frame they locate.
//!
//! Irregular maps and spectroscopy files are rejected as unsupported.

use std::collections::BTreeMap;

use dhct_scan::{
    Axis, FileFormat, ImageChannel, ScanDirection, ScanGeometry, ScanPair, ValueSource,
};

use crate::{ReadError, ScanFile};

use crate::limits::{Budget, ReadLimits};
use crate::placeholders::{
    ASSUMED_PITCH, ASSUMED_PIXEL_PERIOD, ASSUMED_SCALE_KEY, ASSUMED_TIMING_KEY, PLAUSIBLE_PITCH_M,
    PLAUSIBLE_PIXEL_PERIOD_S, PLAUSIBLE_SCAN_ANGLE_RAD, note, plausible,
};

const FORMAT: FileFormat = FileFormat::Iso28600;

/// Number of header lines fixed by the standard (line 128 is `end of header`).
pub const HEADER_LINES: usize = 128;

/// The line that ends the data section.
pub const END_OF_DATA: &str = "end of experiment";

/// Largest number of channels of a multi-channel map.
pub const MAX_CHANNELS: usize = 8;

/// Lines that must hold these exact labels (1-based line numbers).
const FIXED_LABELS: [(usize, &str); 11] = [
    (1, "ISO/TC 201 SPM data transfer format"),
    (2, "general information"),
    (16, "scan information"),
    (48, "environment description"),
    (54, "probe description"),
    (64, "sample description"),
    (68, "single-channel mapping description"),
    (72, "spectroscopy description"),
    (87, "data treatment description"),
    (93, "multi-channel mapping description"),
    (128, "end of header"),
];

/// Reads an ISO 28600 regular map: one trace image per channel (see the module docs).
pub fn read(bytes: &[u8]) -> Result<ScanFile, ReadError> {
    read_limited(bytes, &ReadLimits::default())
}

/// [`read`] under `limits` (see [`crate::limits`]).
pub fn read_limited(bytes: &[u8], limits: &ReadLimits) -> Result<ScanFile, ReadError> {
    let mut budget = Budget::new(limits, bytes.len())?;
    let body = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
    let mut lines = body
        .split(|&b| b == b'\n')
        .map(|line| line.strip_suffix(b"\r").unwrap_or(line));

    let h = read_header(bytes, &mut lines)?;
    let experiment = h.line(8).to_ascii_uppercase();
    let channel_count = channel_count(&h, &experiment)?;
    check_scan_mode(&h)?;

    let columns = h.count(24, "number of X points")?;
    let rows = h.count(25, "number of Y points")?;
    if columns == 0 || rows == 0 {
        return Err(ReadError::NoImage {
            format: FORMAT,
            reason: format!("the map has {columns} x {rows} points"),
        });
    }

    let channels = channel_names(&h, &experiment, channel_count);

    budget.charge_images(FORMAT, columns as u64, rows as u64, channel_count as u64, 0)?;
    let values = read_data(bytes, &mut lines, columns, rows, channel_count, &channels)?;

    let mut metadata = metadata(&h);
    let geometry = build_geometry(&h, columns, rows, &mut metadata)?;
    let mut pairs = Vec::with_capacity(channel_count);
    for ((name, unit, _), z) in channels.into_iter().zip(values) {
        let channel = ImageChannel::from_row_major(name, unit, rows, columns, z)
            .map_err(|source| ReadError::geometry(FORMAT, source))?;
        pairs.push(
            ScanPair::new(geometry.clone(), channel, None)
                .map_err(|source| ReadError::geometry(FORMAT, source))?,
        );
    }
    Ok(ScanFile {
        format: FORMAT,
        pairs,
        metadata,
    })
}

/// The 128 header lines (latin-1 decoded, trimmed), with the fixed labels checked.
fn read_header<'a>(
    bytes: &[u8],
    lines: &mut impl Iterator<Item = &'a [u8]>,
) -> Result<Header, ReadError> {
    let mut header: Vec<String> = Vec::with_capacity(HEADER_LINES);
    for number in 1..=HEADER_LINES {
        let line = lines
            .next()
            .ok_or_else(|| truncated(bytes, format!("header line {number} of {HEADER_LINES}")))?;
        header.push(
            line.iter()
                .map(|&b| char::from(b))
                .collect::<String>()
                .trim()
                .to_string(),
        );
        if number == 1 && header.first().map(String::as_str) != Some(FIXED_LABELS[0].1) {
            return Err(ReadError::wrong_format(
                FORMAT,
                "the first line is not \"ISO/TC 201 SPM data transfer format\"",
            ));
        }
    }
    let h = Header { lines: header };
    for (number, label) in FIXED_LABELS {
        if !h.line(number).eq_ignore_ascii_case(label) {
            // A short file whose text ran out makes every later line empty.
            return Err(ReadError::corrupt(
                FORMAT,
                format!(
                    "line {number} should read \"{label}\" but reads \"{}\"",
                    h.line(number)
                ),
            ));
        }
    }
    Ok(h)
}

/// The number of channels the experiment mode (line 8, upper case) implies.
fn channel_count(h: &Header, experiment: &str) -> Result<usize, ReadError> {
    match experiment {
        "MAP_SC" => Ok(1),
        "MAP_MC" => {
            let n = h.count(94, "number of data channels")?;
            if n == 0 || n > MAX_CHANNELS {
                return Err(ReadError::corrupt(
                    FORMAT,
                    format!(
                        "number of data channels (line 94) is {n}; it must be 1 to {MAX_CHANNELS}"
                    ),
                ));
            }
            Ok(n)
        }
        "SPEC_SC" | "SPEC_MC" => Err(ReadError::unsupported(
            FORMAT,
            format!("experiment mode {experiment} holds spectra, not images"),
        )),
        other => Err(ReadError::corrupt(
            FORMAT,
            format!("unknown experiment mode \"{other}\" on line 8"),
        )),
    }
}

/// Refuses scan modes other than `REGULAR MAPPING` (line 17).
fn check_scan_mode(h: &Header) -> Result<(), ReadError> {
    if !h.line(17).eq_ignore_ascii_case("REGULAR MAPPING") {
        return Err(ReadError::unsupported(
            FORMAT,
            format!(
                "scan mode \"{}\" (only REGULAR MAPPING is an image)",
                h.line(17)
            ),
        ));
    }
    Ok(())
}

/// Name, unit and unit-prefix factor of every channel.
fn channel_names(h: &Header, experiment: &str, count: usize) -> Vec<(String, String, f64)> {
    let mut channels = Vec::with_capacity(count);
    for i in 0..count {
        let (name_line, unit_line) = if experiment == "MAP_SC" {
            (69, 70)
        } else {
            (95 + 3 * i, 96 + 3 * i)
        };
        let name = match h.line(name_line) {
            "" => format!("channel {}", i + 1),
            name => name.to_string(),
        };
        let (unit, factor) = parse_unit(h.line(unit_line));
        channels.push((name, unit, factor));
    }
    channels
}

/// The 128 header lines, 1-based access.
struct Header {
    lines: Vec<String>,
}

impl Header {
    fn line(&self, number: usize) -> &str {
        number
            .checked_sub(1)
            .and_then(|i| self.lines.get(i))
            .map_or("", String::as_str)
    }

    /// A non-negative integer field.
    fn count(&self, number: usize, what: &str) -> Result<usize, ReadError> {
        let text = self.line(number);
        text.parse::<usize>().map_err(|_| {
            ReadError::corrupt(
                FORMAT,
                format!("{what} (line {number}) must be a non-negative integer that fits memory, got \"{text}\""),
            )
        })
    }

    /// A real-number field, or `None` when empty or not a number.
    fn real(&self, number: usize) -> Option<f64> {
        parse_number(self.line(number)).filter(|v| v.is_finite())
    }
}

/// Reads `rows·columns` points of `channel_count` values each, then the end marker.
/// Returns one row-major vector per channel, already multiplied by the unit prefix factor.
fn read_data<'a>(
    bytes: &[u8],
    lines: &mut impl Iterator<Item = &'a [u8]>,
    columns: usize,
    rows: usize,
    channel_count: usize,
    channels: &[(String, String, f64)],
) -> Result<Vec<Vec<f64>>, ReadError> {
    let points = crate::bytes::checked_data_len(FORMAT, rows as u64, columns as u64, 1)?;
    // Every value needs at least one digit and one separator: refuse sizes the file cannot hold
    // before allocating anything.
    let min_bytes = points
        .checked_mul(channel_count as u64)
        .and_then(|n| n.checked_mul(2))
        .unwrap_or(u64::MAX);
    if min_bytes > bytes.len() as u64 {
        return Err(ReadError::Truncated {
            format: FORMAT,
            what: format!("{columns} x {rows} points of {channel_count} channel(s)"),
            offset: 0,
            needed: min_bytes,
            len: bytes.len() as u64,
        });
    }
    let points = usize::try_from(points).map_err(|_| {
        ReadError::corrupt(
            FORMAT,
            format!("image size {columns} x {rows} px is too large to be real"),
        )
    })?;
    let mut values: Vec<Vec<f64>> = (0..channel_count)
        .map(|_| Vec::with_capacity(points))
        .collect();
    let mut point = 0usize;
    while point < points {
        let line = lines
            .next()
            .ok_or_else(|| truncated(bytes, format!("data point {} of {points}", point + 1)))?;
        let text = std::str::from_utf8(line)
            .map_err(|_| {
                ReadError::corrupt(
                    FORMAT,
                    format!("data point {} is not ASCII text", point + 1),
                )
            })?
            .trim();
        if text.is_empty() {
            continue;
        }
        if text.eq_ignore_ascii_case(END_OF_DATA) {
            return Err(ReadError::corrupt(
                FORMAT,
                format!("the data end after {point} of {points} points ({columns} x {rows} map)"),
            ));
        }
        let mut tokens = text
            .split(|c: char| c == ',' || c.is_ascii_whitespace())
            .filter(|t| !t.is_empty());
        for (channel, (_, _, factor)) in values.iter_mut().zip(channels) {
            let token = tokens.next().ok_or_else(|| {
                ReadError::corrupt(
                    FORMAT,
                    format!(
                        "data point {} has fewer than {channel_count} value(s): \"{text}\"",
                        point + 1
                    ),
                )
            })?;
            let value = parse_number(token).ok_or_else(|| {
                ReadError::corrupt(
                    FORMAT,
                    format!("data point {} is not a number: \"{token}\"", point + 1),
                )
            })?;
            channel.push(value * factor);
        }
        if tokens.next().is_some() {
            return Err(ReadError::corrupt(
                FORMAT,
                format!(
                    "data point {} has more than {channel_count} value(s): \"{text}\" \
                     (one point per line is expected)",
                    point + 1
                ),
            ));
        }
        point += 1;
    }
    loop {
        let line = lines
            .next()
            .ok_or_else(|| truncated(bytes, format!("end-of-data line \"{END_OF_DATA}\"")))?;
        let text = String::from_utf8_lossy(line);
        let text = text.trim();
        if text.is_empty() {
            continue;
        }
        if text.eq_ignore_ascii_case(END_OF_DATA) {
            return Ok(values);
        }
        return Err(ReadError::corrupt(
            FORMAT,
            format!(
                "expected \"{END_OF_DATA}\" after {points} points ({columns} x {rows}) but found \"{}\"",
                text.chars().take(60).collect::<String>()
            ),
        ));
    }
}

/// The scan geometry; what had to be assumed is noted in `metadata` (see
/// [`crate::ASSUMED_SCALE_KEY`]).
fn build_geometry(
    h: &Header,
    columns: usize,
    rows: usize,
    metadata: &mut BTreeMap<String, String>,
) -> Result<ScanGeometry, ReadError> {
    let geometry_error = |source| ReadError::geometry(FORMAT, source);

    // Scale.
    let pitch = |unit_line: usize, fov_line: usize, n: usize| -> Option<f64> {
        let (unit, factor) = parse_unit(h.line(unit_line));
        let fov = h.real(fov_line)?;
        let pitch = fov.abs() * factor / n as f64;
        (unit == "m" && plausible(pitch, &PLAUSIBLE_PITCH_M)).then_some(pitch)
    };
    let (pitch_x, pitch_y, scale_source) = match (pitch(26, 28, columns), pitch(27, 29, rows)) {
        (Some(px), Some(py)) => (px, py, ValueSource::Stated),
        _ => {
            note(
                metadata,
                ASSUMED_SCALE_KEY,
                format!(
                    "the field of view (lines 26-29: \"{}\" \"{}\" x \"{}\" \"{}\") is \
                     not a plausible length",
                    h.line(28),
                    h.line(26),
                    h.line(29),
                    h.line(27)
                ),
            );
            (ASSUMED_PITCH, ASSUMED_PITCH, ValueSource::Assumed)
        }
    };

    // Directions.
    let fast = direction(h.line(21)).or_else(|| axis_default(h.line(20)));
    let slow = direction(h.line(23)).or_else(|| axis_default(h.line(22)));
    let (trace_fast, slow) = match (fast, slow) {
        (Some(f), Some(s)) if f.axis() != s.axis() => (f, s),
        (Some(f), None) => (f, perpendicular_default(f)),
        _ => (ScanDirection::Right, ScanDirection::Down),
    };

    // Timing: only a stated tip speed on data that were not post-treated gives a pixel period.
    let post_treated = h.line(88).to_ascii_lowercase().contains("post");
    let bogus = h.line(7).to_ascii_lowercase().contains("bogus");
    let fast_pitch = match trace_fast.axis() {
        Axis::Horizontal => pitch_x,
        Axis::Vertical => pitch_y,
    };
    let speed = {
        let (unit, factor) = parse_unit(h.line(35));
        h.real(36)
            .map(|v| v * factor)
            .filter(|v| unit == "m/s" && *v > 0.0)
    };
    let (pixel_period, timing_source) = match speed {
        Some(speed)
            if !post_treated
                && !bogus
                && scale_source == ValueSource::Stated
                && plausible(fast_pitch / speed, &PLAUSIBLE_PIXEL_PERIOD_S) =>
        {
            (fast_pitch / speed, ValueSource::Stated)
        }
        _ => {
            let why = if post_treated || bogus {
                "the data are post-treated or the parameters marked bogus"
            } else {
                "no plausible tip speed (lines 35-36) with a stated scale"
            };
            note(metadata, ASSUMED_TIMING_KEY, why);
            (ASSUMED_PIXEL_PERIOD, ValueSource::Assumed)
        }
    };

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
    if let Some(angle) = h.real(34) {
        if !plausible(angle.to_radians(), &PLAUSIBLE_SCAN_ANGLE_RAD) {
            return Err(ReadError::corrupt(
                FORMAT,
                format!("the scan angle (line 34) {angle} degrees lies beyond a full turn"),
            ));
        }
        geometry = geometry
            .with_scan_angle(angle.to_radians())
            .map_err(geometry_error)?;
    }
    Ok(geometry
        .with_scale_source(scale_source)
        .with_timing_source(timing_source))
}

/// Parses a direction line such as "left to right" or "top to bottom".
fn direction(text: &str) -> Option<ScanDirection> {
    let text = text.to_ascii_lowercase();
    let text = text.trim();
    if text.starts_with("left") {
        Some(ScanDirection::Right)
    } else if text.starts_with("right") {
        Some(ScanDirection::Left)
    } else if text.starts_with("top") {
        Some(ScanDirection::Down)
    } else if text.starts_with("bottom") {
        Some(ScanDirection::Up)
    } else {
        ScanDirection::parse(text)
    }
}

/// The usual direction along an axis named `X` or `Y`.
fn axis_default(axis: &str) -> Option<ScanDirection> {
    match axis.trim().to_ascii_uppercase().as_str() {
        "X" => Some(ScanDirection::Right),
        "Y" => Some(ScanDirection::Down),
        _ => None,
    }
}

fn perpendicular_default(fast: ScanDirection) -> ScanDirection {
    match fast.axis() {
        Axis::Horizontal => ScanDirection::Down,
        Axis::Vertical => ScanDirection::Right,
    }
}

fn metadata(h: &Header) -> BTreeMap<String, String> {
    let mut m = BTreeMap::new();
    let mut put = |key: &str, value: String| {
        if !value.trim().is_empty() {
            m.insert(key.to_string(), value);
        }
    };
    put("institution", h.line(3).to_string());
    put("instrument", h.line(4).to_string());
    put("operator", h.line(5).to_string());
    put("experiment", h.line(6).to_string());
    put("comment", h.line(7).to_string());
    put("experiment mode", h.line(8).to_string());
    let date: Vec<i64> = (9..=14)
        .filter_map(|n| h.line(n).parse::<i64>().ok())
        .collect();
    if let [year, month, day, hour, minute, second] = date.as_slice()
        && date.iter().all(|v| *v >= 0)
    {
        let mut text = format!("{year:04}-{month:02}-{day:02} {hour:02}:{minute:02}:{second:02}");
        if let Ok(zone) = h.line(15).parse::<i64>()
            && zone != -1
            && zone != 0
        {
            text.push_str(&format!(" (GMT{zone:+})"));
        }
        put("date", text);
    }
    put("scanning system", h.line(18).to_string());
    put("scanner type", h.line(19).to_string());
    put(
        "fast scan",
        format!("{} {}", h.line(20), h.line(21)).trim().to_string(),
    );
    put(
        "slow scan",
        format!("{} {}", h.line(22), h.line(23)).trim().to_string(),
    );
    let with_unit = |value: &str, unit: &str| format!("{value} {unit}").trim().to_string();
    if h.real(32).is_some_and(|v| v != 0.0) || h.real(33).is_some_and(|v| v != 0.0) {
        put(
            "offset",
            format!(
                "x {}, y {}",
                with_unit(h.line(32), h.line(30)),
                with_unit(h.line(33), h.line(31))
            ),
        );
    }
    if h.real(34).is_some_and(|v| v != 0.0) {
        put("rotation", with_unit(h.line(34), "deg"));
    }
    if h.real(36).is_some_and(|v| v != 0.0) {
        put("scan speed", with_unit(h.line(36), h.line(35)));
    }
    if h.real(38).is_some_and(|v| v != 0.0) {
        put("scan rate", with_unit(h.line(38), h.line(37)));
    }
    put("technique", h.line(39).to_string());
    if h.real(41).is_some_and(|v| v != 0.0) {
        put(
            "bias",
            format!("{} V ({})", h.line(41), h.line(40)).replace(" ()", ""),
        );
    }
    put("environment", h.line(49).to_string());
    if h.real(50).is_some_and(|v| v != 0.0) {
        put("temperature", with_unit(h.line(50), "K"));
    }
    put(
        "probe",
        format!("{} {}", h.line(55), h.line(56)).trim().to_string(),
    );
    put("sample", h.line(65).to_string());
    put("species", h.line(66).to_string());
    put("sample comment", h.line(67).to_string());
    put("data treatment", h.line(88).to_string());
    put("plane correction", h.line(89).to_string());
    put("filtering", h.line(90).to_string());
    put("image reconstruction", h.line(91).to_string());
    put("data treatment comment", h.line(92).to_string());
    m
}

fn truncated(bytes: &[u8], what: String) -> ReadError {
    ReadError::Truncated {
        format: FORMAT,
        what,
        offset: bytes.len() as u64,
        needed: 1,
        len: bytes.len() as u64,
    }
}

/// Parses a decimal number: an integer or a real, with `e`/`E` (or Fortran `d`/`D`) exponent.
pub(crate) fn parse_number(text: &str) -> Option<f64> {
    let text = text.trim();
    if text.is_empty() {
        return None;
    }
    text.parse::<f64>().ok().or_else(|| {
        if text.contains(['d', 'D']) {
            text.replace(['d', 'D'], "e").parse::<f64>().ok()
        } else {
            None
        }
    })
}

/// Units without an SI prefix that dhct recognises.
const BASE_UNITS: [&str; 20] = [
    "m", "A", "V", "s", "Hz", "N", "Pa", "K", "eV", "N/m", "m/s", "c/s", "cps", "deg", "degree",
    "C", "W", "F", "T", "Ohm",
];

/// Splits a unit such as `nm` into its SI base unit and the factor of its prefix:
/// `nm` → (`m`, 1e-9), `pA` → (`A`, 1e-12), `V` → (`V`, 1). `Å` gives (`m`, 1e-10).
/// The ISO 28600 placeholders `d` (dimensionless), `n` (none) and an empty string give an
/// empty unit. Units dhct does not know are returned unchanged with factor 1.
pub(crate) fn parse_unit(text: &str) -> (String, f64) {
    let text = text.trim();
    match text {
        "" | "d" | "n" => return (String::new(), 1.0),
        "Å" | "Angstrom" | "angstrom" => return ("m".to_string(), 1e-10),
        _ => {}
    }
    if BASE_UNITS.contains(&text) {
        return (text.to_string(), 1.0);
    }
    let mut chars = text.chars();
    let factor = match chars.next() {
        Some('Y') => 1e24,
        Some('Z') => 1e21,
        Some('E') => 1e18,
        Some('P') => 1e15,
        Some('T') => 1e12,
        Some('G') => 1e9,
        Some('M') => 1e6,
        Some('k') => 1e3,
        Some('c') => 1e-2,
        Some('m') => 1e-3,
        Some('u' | 'µ' | 'μ') => 1e-6,
        Some('n') => 1e-9,
        Some('p') => 1e-12,
        Some('f') => 1e-15,
        Some('a') => 1e-18,
        Some('z') => 1e-21,
        Some('y') => 1e-24,
        _ => return (text.to_string(), 1.0),
    };
    let base = chars.as_str();
    if BASE_UNITS.contains(&base) {
        (base.to_string(), factor)
    } else {
        (text.to_string(), 1.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn units_split_into_base_and_prefix() {
        assert_eq!(parse_unit("m"), ("m".to_string(), 1.0));
        assert_eq!(parse_unit("nm"), ("m".to_string(), 1e-9));
        assert_eq!(parse_unit("mm"), ("m".to_string(), 1e-3));
        assert_eq!(parse_unit("pA"), ("A".to_string(), 1e-12));
        assert_eq!(parse_unit("Pa"), ("Pa".to_string(), 1.0));
        assert_eq!(parse_unit("µm"), ("m".to_string(), 1e-6));
        assert_eq!(parse_unit("n"), (String::new(), 1.0));
        assert_eq!(parse_unit("d"), (String::new(), 1.0));
        assert_eq!(parse_unit("furlong"), ("furlong".to_string(), 1.0));
    }

    #[test]
    fn numbers_accept_integers_reals_and_fortran_exponents() {
        assert_eq!(parse_number("12"), Some(12.0));
        assert_eq!(parse_number(" -1.5e-10 "), Some(-1.5e-10));
        assert_eq!(parse_number("2.5D3"), Some(2500.0));
        assert_eq!(parse_number(""), None);
        assert_eq!(parse_number("abc"), None);
    }

    #[test]
    fn direction_lines_map_to_display_directions() {
        assert_eq!(direction("left to right"), Some(ScanDirection::Right));
        assert_eq!(direction("Right to left"), Some(ScanDirection::Left));
        assert_eq!(direction("top to bottom"), Some(ScanDirection::Down));
        assert_eq!(direction("bottom to top"), Some(ScanDirection::Up));
        assert_eq!(direction(""), None);
    }
}
