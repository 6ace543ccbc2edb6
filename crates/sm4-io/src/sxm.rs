//! Nanonis SXM image reader.
//!
//! # Format
//!
//! An ASCII (latin-1) header of tagged entries, each a line `:TAG:` followed by one or more
//! value lines, ending with the tag `:SCANIT_END:`; then the two bytes `\x1A\x04`; then the
//! images as 32-bit IEEE floats (big-endian, `SCANIT_TYPE` = `FLOAT MSBFIRST`; `LSBFIRST` is
//! accepted too). The tags dhct uses:
//!
//! | tag | value |
//! |---|---|
//! | `SCAN_PIXELS` | pixels along x (columns) and y (rows) |
//! | `SCAN_RANGE` | scan frame size along x and y, metres |
//! | `SCAN_OFFSET` | scan frame centre x and y, metres |
//! | `SCAN_ANGLE` | scan frame rotation, degrees |
//! | `SCAN_DIR` | `down` or `up`: the slow scan direction |
//! | `SCAN_TIME` | time per line, forward and backward, seconds |
//! | `DATA_INFO` | a table `Channel Name Unit Direction Calibration Offset`, one row per channel; `Direction` is `both`, `forward` or `backward` |
//! | `REC_DATE`, `REC_TIME`, `BIAS`, `COMMENT`, … | metadata |
//!
//! The data hold, for each `DATA_INFO` row in order, the forward image and then (for
//! `both`) the backward image, each `columns × rows` values in acquisition order: the first
//! acquired line first, each line in the order its pixels were acquired. The values are
//! already in the channel's unit (the calibration column documents the conversion from the
//! ADC voltage and is not applied again). NaN marks pixels never acquired (an aborted scan)
//! and is kept.
//!
//! # Orientation (matches Gwyddion's `nanonis.c`)
//!
//! * Forward lines run left to right: the trace, fast direction [`ScanDirection::Right`].
//! * Backward lines are stored in their own acquisition order (right to left), so dhct flips
//!   them left-right; the retrace runs [`ScanDirection::Left`].
//! * `SCAN_DIR = down`: the first line is the top row (slow [`ScanDirection::Down`]).
//!   `SCAN_DIR = up`: the first line is the bottom row, so the rows are flipped top-bottom
//!   (slow [`ScanDirection::Up`]). A missing `SCAN_DIR` is taken as `down`.
//!
//! # Geometry
//!
//! Pitch = `SCAN_RANGE` / `SCAN_PIXELS`; pixel period = forward `SCAN_TIME` / columns (no
//! turnaround: Nanonis includes none in the line time); scan angle = `SCAN_ANGLE` in radians,
//! with the sign as written in the header; offset = `SCAN_OFFSET`. A missing `SCAN_RANGE`
//! gives the placeholder pitch [`ASSUMED_PITCH`], a missing `SCAN_TIME` the placeholder
//! pixel period [`ASSUMED_PIXEL_PERIOD`], each marked [`ValueSource::Assumed`]. A backward
//! line time more than 1 % off the forward one (a backward/forward speed ratio) also marks
//! the timing assumed, with the reason: dhct times both passes with one line time.

use std::collections::BTreeMap;

use dhct_scan::{FileFormat, ImageChannel, ScanDirection, ScanGeometry, ScanPair, ValueSource};

use crate::bytes::checked_data_len;
use crate::iso28600::parse_number;
use crate::{ReadError, ScanFile};

use crate::limits::{Budget, ReadLimits};
use crate::placeholders::{
    ASSUMED_PITCH, ASSUMED_PIXEL_PERIOD, ASSUMED_SCALE_KEY, ASSUMED_TIMING_KEY, PLAUSIBLE_PITCH_M,
    PLAUSIBLE_PIXEL_PERIOD_S, PLAUSIBLE_SCAN_ANGLE_RAD, note, plausible,
};

const FORMAT: FileFormat = FileFormat::NanonisSxm;
const MAGIC: &[u8] = b":NANONIS_VERSION:";
const END_TAG: &[u8] = b":SCANIT_END:";
const DATA_MARKER: &[u8] = b"\x1A\x04";
/// How far after `:SCANIT_END:` the data marker may lie (only line ends are expected there).
const MARKER_SEARCH: usize = 256;

/// Which images a `DATA_INFO` row has.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Directions {
    Forward,
    Backward,
    Both,
}

#[derive(Debug)]
struct ChannelInfo {
    name: String,
    unit: String,
    directions: Directions,
}

/// Reads a Nanonis SXM file: one [`ScanPair`] per `DATA_INFO` row (see the module docs).
pub fn read(bytes: &[u8]) -> Result<ScanFile, ReadError> {
    read_limited(bytes, &ReadLimits::default())
}

/// [`read`] under `limits` (see [`crate::limits`]).
pub fn read_limited(bytes: &[u8], limits: &ReadLimits) -> Result<ScanFile, ReadError> {
    let mut budget = Budget::new(limits, bytes.len())?;
    let layout = find_layout(bytes)?;
    let header_bytes = bytes.get(layout.body_start..layout.end_tag).unwrap_or(&[]);
    let header = parse_header(header_bytes)?;
    let big_endian = big_endian(header.get("SCANIT_TYPE").unwrap_or("FLOAT MSBFIRST"))?;
    let pixels = header
        .get("SCAN_PIXELS")
        .ok_or_else(|| ReadError::corrupt(FORMAT, "header lacks SCAN_PIXELS"))?;
    let (columns, rows) = parse_pixels(pixels)?;
    let channels = channels(&header)?;

    // Check the whole data length against the file before allocating anything.
    let image_len = checked_data_len(FORMAT, rows as u64, columns as u64, 4)?;
    let image_count: u64 = channels
        .iter()
        .map(|c| {
            if c.directions == Directions::Both {
                2
            } else {
                1
            }
        })
        .sum();
    let total = image_len.checked_mul(image_count).ok_or_else(|| {
        ReadError::corrupt(
            FORMAT,
            format!("{image_count} images of {columns} x {rows} px are too large"),
        )
    })?;
    budget.charge_images(FORMAT, columns as u64, rows as u64, image_count, 0)?;
    let data_start = layout.data_start;
    let available = bytes.len().saturating_sub(data_start) as u64;
    if total > available {
        return Err(ReadError::Truncated {
            format: FORMAT,
            what: format!("{image_count} image(s) of {columns} x {rows} float32 values"),
            offset: data_start as u64,
            needed: total,
            len: bytes.len() as u64,
        });
    }

    let scan_up = header
        .get("SCAN_DIR")
        .is_some_and(|d| d.trim().eq_ignore_ascii_case("up"));
    let mut geometry = build_geometry(&header, columns, rows, scan_up)?;
    let mut metadata = metadata(&header);
    note_assumptions(&geometry, &mut metadata);
    if let Some(reason) = unequal_line_times(&header, geometry.timing_source()) {
        geometry = geometry.with_timing_source(ValueSource::Assumed);
        note(&mut metadata, ASSUMED_TIMING_KEY, &reason);
    }
    let stored = StoredImages {
        bytes,
        data_start,
        image_len: usize::try_from(image_len)
            .map_err(|_| ReadError::corrupt(FORMAT, "image too large for this machine"))?,
        total,
        columns,
        rows,
        big_endian,
        scan_up,
    };
    let pairs = stored.decode_channels(&channels, &geometry)?;
    Ok(ScanFile {
        format: FORMAT,
        pairs,
        metadata,
    })
}

/// Where the header and the data lie in the file.
struct Layout {
    /// Start of the header text (after a UTF-8 byte-order mark, if any).
    body_start: usize,
    /// Offset of `:SCANIT_END:`.
    end_tag: usize,
    /// First data byte (after the `\x1A\x04` marker).
    data_start: usize,
}

/// Checks the magic and finds the end tag and the data marker.
fn find_layout(bytes: &[u8]) -> Result<Layout, ReadError> {
    let body_start = if bytes.starts_with(b"\xEF\xBB\xBF") {
        3
    } else {
        0
    };
    if !bytes
        .get(body_start..)
        .is_some_and(|b| b.starts_with(MAGIC))
    {
        return Err(ReadError::wrong_format(
            FORMAT,
            "the file does not start with :NANONIS_VERSION:",
        ));
    }
    let end_tag = find(bytes, END_TAG, 0).ok_or_else(|| ReadError::Truncated {
        format: FORMAT,
        what: "header end tag :SCANIT_END:".to_string(),
        offset: bytes.len() as u64,
        needed: END_TAG.len() as u64,
        len: bytes.len() as u64,
    })?;
    let after_tag = end_tag + END_TAG.len();
    let search_end = after_tag.saturating_add(MARKER_SEARCH).min(bytes.len());
    let marker = bytes
        .get(after_tag..search_end)
        .and_then(|window| find(window, DATA_MARKER, 0))
        .map(|i| after_tag + i)
        .ok_or_else(|| {
            if search_end == bytes.len() {
                ReadError::Truncated {
                    format: FORMAT,
                    what: "data start marker \\x1A\\x04".to_string(),
                    offset: after_tag as u64,
                    needed: DATA_MARKER.len() as u64,
                    len: bytes.len() as u64,
                }
            } else {
                ReadError::corrupt(FORMAT, "no data start marker \\x1A\\x04 after :SCANIT_END:")
            }
        })?;
    Ok(Layout {
        body_start,
        end_tag,
        data_start: marker + DATA_MARKER.len(),
    })
}

/// Whether `SCANIT_TYPE` says big-endian floats (`FLOAT MSBFIRST`) or little-endian.
fn big_endian(scan_type: &str) -> Result<bool, ReadError> {
    let mut words = scan_type.split_whitespace();
    match (words.next(), words.next()) {
        (Some(t), Some(order)) if t.eq_ignore_ascii_case("FLOAT") => {
            if order.eq_ignore_ascii_case("MSBFIRST") {
                Ok(true)
            } else if order.eq_ignore_ascii_case("LSBFIRST") {
                Ok(false)
            } else {
                Err(unsupported_type(scan_type))
            }
        }
        _ => Err(unsupported_type(scan_type)),
    }
}

/// The channels of the `DATA_INFO` table (at least one).
fn channels(header: &Header) -> Result<Vec<ChannelInfo>, ReadError> {
    let table = header
        .get_raw("DATA_INFO")
        .ok_or_else(|| ReadError::NoImage {
            format: FORMAT,
            reason: "header has no DATA_INFO table".to_string(),
        })?;
    let channels = parse_data_info(table)?;
    if channels.is_empty() {
        return Err(ReadError::NoImage {
            format: FORMAT,
            reason: "the DATA_INFO table lists no channel".to_string(),
        });
    }
    Ok(channels)
}

/// Records why scale or timing were assumed.
fn note_assumptions(geometry: &ScanGeometry, metadata: &mut BTreeMap<String, String>) {
    if geometry.scale_source() == ValueSource::Assumed {
        note(metadata, ASSUMED_SCALE_KEY, "no SCAN_RANGE in the header");
    }
    if geometry.timing_source() == ValueSource::Assumed {
        note(metadata, ASSUMED_TIMING_KEY, "no SCAN_TIME in the header");
    }
}

/// Backward lines slower or faster than forward ones by more than this fraction cannot be
/// timed by one line time.
const UNEQUAL_LINE_TIMES: f64 = 0.01;

/// Why the timing cannot be used as stated when `SCAN_TIME` gives the backward lines
/// another time than the forward ones (Nanonis' backward/forward speed ratio): dhct's
/// timing has one line time for both passes ([`ScanGeometry`]), so the forward one is
/// used, and the time between lines and the retrace's pixel times are then off. `None`
/// when the times agree, or the timing is assumed already.
fn unequal_line_times(header: &Header, timing: ValueSource) -> Option<String> {
    if timing == ValueSource::Assumed {
        return None;
    }
    let mut times = header
        .get("SCAN_TIME")?
        .split_whitespace()
        .map(parse_number);
    let (forward, backward) = (times.next()??, times.next()??);
    let unequal = backward.is_finite()
        && backward > 0.0
        && (backward / forward - 1.0).abs() > UNEQUAL_LINE_TIMES;
    unequal.then(|| {
        format!(
            "SCAN_TIME gives {forward} s per forward line and {backward} s per backward line, \
             but dhct times both passes with one line time: with the forward one, the time \
             between lines is taken as {:.4} s against {:.4} s recorded, and the retrace's \
             pixel times are {:.2}× what they were",
            2.0 * forward,
            forward + backward,
            forward / backward
        )
    })
}

/// The stored images of a file whose length was checked against all of them.
struct StoredImages<'a> {
    bytes: &'a [u8],
    data_start: usize,
    /// Bytes of one image.
    image_len: usize,
    /// Bytes of all images.
    total: u64,
    columns: usize,
    rows: usize,
    big_endian: bool,
    scan_up: bool,
}

impl StoredImages<'_> {
    /// One [`ScanPair`] per channel, its images taken in storage order.
    fn decode_channels(
        &self,
        channels: &[ChannelInfo],
        geometry: &ScanGeometry,
    ) -> Result<Vec<ScanPair>, ReadError> {
        let mut data = self
            .bytes
            .get(self.data_start..)
            .unwrap_or(&[])
            .chunks_exact(self.image_len.max(1));
        let mut next_image = |what: &str| {
            data.next().ok_or_else(|| ReadError::Truncated {
                format: FORMAT,
                what: what.to_string(),
                offset: self.data_start as u64,
                needed: self.total,
                len: self.bytes.len() as u64,
            })
        };
        let mut pairs = Vec::with_capacity(channels.len());
        for channel in channels {
            let forward = match channel.directions {
                Directions::Forward | Directions::Both => Some(self.decode(
                    next_image(&format!("{} forward image", channel.name))?,
                    false,
                    channel,
                )?),
                Directions::Backward => None,
            };
            let backward = match channel.directions {
                Directions::Backward | Directions::Both => Some(self.decode(
                    next_image(&format!("{} backward image", channel.name))?,
                    true,
                    channel,
                )?),
                Directions::Forward => None,
            };
            pairs.push(
                ScanPair::from_parts(geometry.clone(), forward, backward)
                    .map_err(|source| ReadError::geometry(FORMAT, source))?,
            );
        }
        Ok(pairs)
    }

    fn decode(
        &self,
        data: &[u8],
        backward: bool,
        channel: &ChannelInfo,
    ) -> Result<ImageChannel, ReadError> {
        decode_image(
            data,
            self.columns,
            self.rows,
            self.big_endian,
            backward,
            self.scan_up,
            channel,
        )
    }
}

/// Decodes one stored image into display orientation.
fn decode_image(
    data: &[u8],
    columns: usize,
    rows: usize,
    big_endian: bool,
    backward: bool,
    scan_up: bool,
    channel: &ChannelInfo,
) -> Result<ImageChannel, ReadError> {
    let line_len = columns * 4;
    let mut lines: Vec<&[u8]> = data.chunks_exact(line_len.max(1)).collect();
    if scan_up {
        lines.reverse();
    }
    let value = |chunk: &[u8]| {
        let mut raw = [0u8; 4];
        for (dst, src) in raw.iter_mut().zip(chunk) {
            *dst = *src;
        }
        f64::from(if big_endian {
            f32::from_be_bytes(raw)
        } else {
            f32::from_le_bytes(raw)
        })
    };
    let mut values = Vec::with_capacity(columns * rows);
    for line in lines {
        let samples = line.chunks_exact(4);
        if backward {
            values.extend(samples.rev().map(value));
        } else {
            values.extend(samples.map(value));
        }
    }
    ImageChannel::from_row_major(
        channel.name.clone(),
        channel.unit.clone(),
        rows,
        columns,
        values,
    )
    .map_err(|source| ReadError::geometry(FORMAT, source))
}

fn build_geometry(
    header: &Header,
    columns: usize,
    rows: usize,
    scan_up: bool,
) -> Result<ScanGeometry, ReadError> {
    let geometry_error = |source| ReadError::geometry(FORMAT, source);
    let (pitch_x, pitch_y, scale_source) = match header.get("SCAN_RANGE") {
        Some(range) => {
            let (x, y) = parse_real_pair("SCAN_RANGE", range)?;
            let (px, py) = (x.abs() / columns as f64, y.abs() / rows as f64);
            if !(plausible(px, &PLAUSIBLE_PITCH_M) && plausible(py, &PLAUSIBLE_PITCH_M)) {
                return Err(ReadError::corrupt(
                    FORMAT,
                    format!(
                        "SCAN_RANGE must be two lengths giving a pixel pitch in {:e}..{:e} m, \
                         got \"{}\"",
                        PLAUSIBLE_PITCH_M.start(),
                        PLAUSIBLE_PITCH_M.end(),
                        range.trim()
                    ),
                ));
            }
            (px, py, ValueSource::Stated)
        }
        None => (ASSUMED_PITCH, ASSUMED_PITCH, ValueSource::Assumed),
    };
    let slow = if scan_up {
        ScanDirection::Up
    } else {
        ScanDirection::Down
    };
    let (line_time, timing_source) = match header.get("SCAN_TIME") {
        Some(times) => {
            let forward = times
                .split_whitespace()
                .next()
                .and_then(parse_number)
                .filter(|t| plausible(*t / columns as f64, &PLAUSIBLE_PIXEL_PERIOD_S))
                .ok_or_else(|| {
                    ReadError::corrupt(
                        FORMAT,
                        format!(
                            "SCAN_TIME must start with a time per line giving a pixel period \
                             in {:e}..{:e} s, got \"{}\"",
                            PLAUSIBLE_PIXEL_PERIOD_S.start(),
                            PLAUSIBLE_PIXEL_PERIOD_S.end(),
                            times.trim()
                        ),
                    )
                })?;
            (forward, ValueSource::Stated)
        }
        None => (ASSUMED_PIXEL_PERIOD * columns as f64, ValueSource::Assumed),
    };
    let mut geometry = ScanGeometry::from_line_time(
        columns,
        rows,
        pitch_x,
        pitch_y,
        line_time,
        ScanDirection::Right,
        slow,
    )
    .map_err(geometry_error)?;
    if let Some(angle) = header.get("SCAN_ANGLE").and_then(parse_number) {
        if !plausible(angle.to_radians(), &PLAUSIBLE_SCAN_ANGLE_RAD) {
            return Err(ReadError::corrupt(
                FORMAT,
                format!("SCAN_ANGLE {angle} degrees lies beyond a full turn"),
            ));
        }
        geometry = geometry
            .with_scan_angle(angle.to_radians())
            .map_err(geometry_error)?;
    }
    if let Some(offset) = header.get("SCAN_OFFSET")
        && let Ok((x, y)) = parse_real_pair("SCAN_OFFSET", offset)
    {
        geometry = geometry.with_offset(x, y).map_err(geometry_error)?;
    }
    // REC_DATE "DD.MM.YYYY", REC_TIME "HH:MM:SS".
    let start =
        dhct_scan::clock::seconds_from_day_first(header.get("REC_DATE"), header.get("REC_TIME"));
    Ok(geometry
        .with_scale_source(scale_source)
        .with_timing_source(timing_source)
        .with_start_time(start))
}

/// The tagged header: tag → value lines (in file order; the first of repeated tags wins).
struct Header {
    entries: Vec<(String, Vec<String>)>,
}

impl Header {
    /// The first non-empty value line of `tag`, trimmed.
    fn get(&self, tag: &str) -> Option<&str> {
        self.get_raw(tag)
            .and_then(|lines| lines.iter().map(|l| l.trim()).find(|l| !l.is_empty()))
    }

    /// The value lines of `tag`, untrimmed.
    fn get_raw(&self, tag: &str) -> Option<&[String]> {
        self.entries
            .iter()
            .find(|(t, _)| t == tag)
            .map(|(_, v)| v.as_slice())
    }
}

fn parse_header(bytes: &[u8]) -> Result<Header, ReadError> {
    let text: String = bytes.iter().map(|&b| char::from(b)).collect();
    let mut entries: Vec<(String, Vec<String>)> = Vec::new();
    for line in text.split('\n') {
        let line = line.strip_suffix('\r').unwrap_or(line);
        let trimmed = line.trim();
        if trimmed.len() >= 2 && trimmed.starts_with(':') && trimmed.ends_with(':') {
            let tag = trimmed
                .get(1..trimmed.len() - 1)
                .unwrap_or_default()
                .to_string();
            entries.push((tag, Vec::new()));
        } else if let Some((_, values)) = entries.last_mut() {
            values.push(line.to_string());
        } else if !trimmed.is_empty() {
            return Err(ReadError::corrupt(
                FORMAT,
                "header text found before the first :TAG:",
            ));
        }
    }
    Ok(Header { entries })
}

fn parse_pixels(text: &str) -> Result<(usize, usize), ReadError> {
    let invalid = || {
        ReadError::corrupt(
            FORMAT,
            format!(
                "SCAN_PIXELS must be two positive integers, got \"{}\"",
                text.trim()
            ),
        )
    };
    let mut words = text.split_whitespace();
    let (Some(x), Some(y)) = (words.next(), words.next()) else {
        return Err(invalid());
    };
    let x: u64 = x.parse().map_err(|_| invalid())?;
    let y: u64 = y.parse().map_err(|_| invalid())?;
    if x == 0 || y == 0 {
        return Err(ReadError::NoImage {
            format: FORMAT,
            reason: format!("SCAN_PIXELS is {x} x {y}"),
        });
    }
    // The product is checked against the file length later; refuse sizes no file can hold.
    checked_data_len(FORMAT, y, x, 4)?;
    match (usize::try_from(x), usize::try_from(y)) {
        (Ok(x), Ok(y)) => Ok((x, y)),
        _ => Err(invalid()),
    }
}

fn parse_real_pair(tag: &str, text: &str) -> Result<(f64, f64), ReadError> {
    let mut words = text.split_whitespace().map(parse_number);
    match (words.next(), words.next()) {
        (Some(Some(x)), Some(Some(y))) if x.is_finite() && y.is_finite() => Ok((x, y)),
        _ => Err(ReadError::corrupt(
            FORMAT,
            format!("{tag} must be two numbers, got \"{}\"", text.trim()),
        )),
    }
}

fn parse_data_info(lines: &[String]) -> Result<Vec<ChannelInfo>, ReadError> {
    let mut rows = lines.iter().map(|l| l.trim()).filter(|l| !l.is_empty());
    let columns: Vec<&str> = rows
        .next()
        .ok_or_else(|| ReadError::corrupt(FORMAT, "DATA_INFO has no column header"))?
        .split_whitespace()
        .collect();
    let index = |name: &str| {
        columns
            .iter()
            .position(|c| c.eq_ignore_ascii_case(name))
            .ok_or_else(|| {
                ReadError::corrupt(
                    FORMAT,
                    format!("DATA_INFO lacks the column \"{name}\" (has {columns:?})"),
                )
            })
    };
    let (name_i, unit_i, dir_i) = (index("Name")?, index("Unit")?, index("Direction")?);
    let mut channels = Vec::new();
    for row in rows {
        let mut fields: Vec<&str> = row
            .split('\t')
            .map(str::trim)
            .filter(|f| !f.is_empty())
            .collect();
        if fields.len() < columns.len() {
            fields = row.split_whitespace().collect();
        }
        let field = |i: usize| {
            fields.get(i).copied().ok_or_else(|| {
                ReadError::corrupt(
                    FORMAT,
                    format!(
                        "DATA_INFO row \"{row}\" has fewer than {} fields",
                        columns.len()
                    ),
                )
            })
        };
        let directions = match field(dir_i)?.to_ascii_lowercase().as_str() {
            "both" => Directions::Both,
            "forward" => Directions::Forward,
            "backward" => Directions::Backward,
            other => {
                return Err(ReadError::corrupt(
                    FORMAT,
                    format!("DATA_INFO direction \"{other}\" is not both, forward or backward"),
                ));
            }
        };
        channels.push(ChannelInfo {
            name: field(name_i)?.to_string(),
            unit: field(unit_i)?.to_string(),
            directions,
        });
    }
    Ok(channels)
}

fn metadata(header: &Header) -> BTreeMap<String, String> {
    let mut m = BTreeMap::new();
    let mut put = |key: &str, value: Option<String>| {
        if let Some(value) = value.filter(|v| !v.trim().is_empty()) {
            m.insert(key.to_string(), value);
        }
    };
    let get = |tag: &str| {
        header
            .get(tag)
            .map(|v| v.split_whitespace().collect::<Vec<_>>().join(" "))
    };
    let date = match (header.get("REC_DATE"), header.get("REC_TIME")) {
        (Some(d), Some(t)) => Some(format!("{d} {t}")),
        (Some(d), None) => Some(d.to_string()),
        _ => None,
    };
    put("date", date);
    put("bias", get("BIAS").map(|b| format!("{b} V")));
    put("temperature", get("REC_TEMP").map(|t| format!("{t} K")));
    put(
        "acquisition time",
        get("ACQ_TIME").map(|t| format!("{t} s")),
    );
    put("scan direction", get("SCAN_DIR"));
    put(
        "scan time per line (forward, backward)",
        get("SCAN_TIME").map(|t| format!("{t} s")),
    );
    put("scan range", get("SCAN_RANGE").map(|t| format!("{t} m")));
    put("scan offset", get("SCAN_OFFSET").map(|t| format!("{t} m")));
    put("scan angle", get("SCAN_ANGLE").map(|t| format!("{t} deg")));
    put("nanonis version", get("NANONIS_VERSION"));
    put("software version", get("NanonisMain>SW Version"));
    put("scan file", get("SCAN_FILE"));
    put(
        "comment",
        header.get_raw("COMMENT").map(|lines| {
            lines
                .iter()
                .map(|l| l.trim())
                .filter(|l| !l.is_empty())
                .collect::<Vec<_>>()
                .join("\n")
        }),
    );
    put(
        "z-controller",
        header.get_raw("Z-CONTROLLER").map(|lines| {
            lines
                .iter()
                .map(|l| l.split_whitespace().collect::<Vec<_>>().join(" "))
                .filter(|l| !l.is_empty())
                .collect::<Vec<_>>()
                .join("; ")
        }),
    );
    m
}

fn unsupported_type(scan_type: &str) -> ReadError {
    ReadError::unsupported(
        FORMAT,
        format!(
            "SCANIT_TYPE \"{}\" (dhct reads FLOAT MSBFIRST and FLOAT LSBFIRST)",
            scan_type.trim()
        ),
    )
}

/// Position of the first occurrence of `needle` in `haystack` at or after `from`.
fn find(haystack: &[u8], needle: &[u8], from: usize) -> Option<usize> {
    haystack
        .get(from..)?
        .windows(needle.len())
        .position(|w| w == needle)
        .map(|i| i + from)
}
