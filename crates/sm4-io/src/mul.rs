//! SPECS / Aarhus `.mul` reader (SPM 150 Aarhus, "SpecsProbe"), and its index-less `.flm`
//! ("film") variant: several images recorded one after another, each its own frame.
//!
//! # Format
//!
//! No magic and no text: the file is a sequence of 128-byte blocks, every field a
//! little-endian `i16` unless noted, and every address counts blocks.
//!
//! * `.mul`: blocks 0–2 are an index of 64 entries of 6 bytes, `(id: i16, block: i32)`; the
//!   first is always `(1, 3)`, so a `.mul` starts with `01 00 03 00 00 00`. The first entry
//!   with id 0 ends the list (its block field holds the file size in blocks).
//! * `.flm`: no index; the first image's label is block 0, and each image follows the one
//!   before it (`next block = this block + size`).
//!
//! Each image is a 128-byte label followed by its data. Label fields (byte offset): 0 `id`,
//! 2 `size` (blocks, label included), 4 `xres`, 6 `yres`, 10–20 year, month, day, hour,
//! minute, second, 22 `xdim` and 24 `ydim` (scan size in Å), 26 `xoff`, 28 `yoff` (Å),
//! 30 `zscale` (V), 32 `tilt` (scan rotation, degrees), 34 `speed` (duration of the whole
//! image in 1/100 s), 36 `bias` (−10 V · raw / 32768), 38 `current` (setpoint, 1/100 nA),
//! 40 `sample` and 61 `title` (a length byte and 20 characters each), 86 `mode` (what the
//! image holds), 88 current factor, 90 the number of point spectra appended after the image
//! (not read). The data, `xres × yres` `i16` values row by row, start at the next block.
//!
//! # Calibration and orientation (checked against Gwyddion 2.62 on real files; see
//! `tests/mul.rs`)
//!
//! * height (mode 0, and 7 "different"): metres per count = −zscale · (0.1 / 1.36) · 10⁻¹⁰
//!   / 200 (the sign is the file's: a larger count is lower);
//! * current (mode 1): amperes per count = current factor · 10⁻⁸ / 32768;
//! * voltage (mode 8): volts per count = −10 / 32768;
//! * the spectroscopy maps (modes 2, 3, 5, 6) are left out, with a note in the metadata.
//!
//! The first stored line is the bottom line of the image as Gwyddion shows it, so rows are
//! reversed into display orientation (row 0 at the top); columns are as stored, the trace
//! running left to right.
//!
//! # Timing
//!
//! The label gives only the duration of the whole image. Each line is taken as a trace and
//! a retrace of equal length with no turnaround: line time per direction = duration / (2 ·
//! yres). The file does not record the slow-scan direction; the lines are read as
//! acquired in storage order (bottom to top), and the timing is marked assumed for that
//! reason (a `dhct` warning says so). Only the forward image of each line is stored. The
//! label's date is taken as the image's start ([`ScanGeometry::start_time`]; the format does
//! not say whether it marks the start or the end: a series of one file's images keeps
//! their order and spacing either way, to within the differences of their durations).
//!
//! Each image of the file is a separate frame ([`ScanGeometry::frame`] 0, 1, …), named
//! `image <id>` plus its sample and title text when the file has any.

use std::collections::BTreeMap;

use dhct_scan::{FileFormat, ImageChannel, ScanDirection, ScanGeometry, ScanPair, ValueSource};

use crate::limits::{Budget, ReadLimits};
use crate::placeholders::{
    ASSUMED_PITCH, ASSUMED_PIXEL_PERIOD, ASSUMED_SCALE_KEY, ASSUMED_TIMING_KEY, PLAUSIBLE_PITCH_M,
    PLAUSIBLE_PIXEL_PERIOD_S, PLAUSIBLE_SCAN_ANGLE_RAD, note, plausible,
};
use crate::{ReadError, ScanFile};

const FORMAT: FileFormat = FileFormat::AarhusMul;
/// Every address and size counts blocks of this many bytes.
const BLOCK: usize = 128;
/// The index of a `.mul` file: 64 entries of 6 bytes in blocks 0–2.
const INDEX_ENTRIES: usize = 64;
const INDEX_BLOCKS: usize = 3;
/// The first index entry of every `.mul` file: image 1 at block 3.
const MUL_START: [u8; 6] = [1, 0, 3, 0, 0, 0];
/// Largest pixel count per side dhct accepts from a label.
const MAX_SIDE: usize = 1 << 14;

/// True when `bytes` have the structure of a `.mul` (index, then a plausible first label)
/// or a `.flm` (a plausible first label of image 1 at block 0, with a real date).
pub fn looks_like_mul(bytes: &[u8]) -> bool {
    looks_like_mul_of_length(bytes, bytes.len() as u64)
}

/// [`looks_like_mul`] from the first bytes of a file of `file_len` bytes (at least the
/// first four blocks: the index and the first label).
pub fn looks_like_mul_of_length(bytes: &[u8], file_len: u64) -> bool {
    let Ok(file_len) = usize::try_from(file_len) else {
        return false;
    };
    if !file_len.is_multiple_of(BLOCK) || file_len < 2 * BLOCK {
        return false;
    }
    let blocks = file_len / BLOCK;
    if bytes.starts_with(&MUL_START) {
        return Label::at(bytes, INDEX_BLOCKS).is_some_and(|l| l.fits(INDEX_BLOCKS, blocks));
    }
    Label::at(bytes, 0).is_some_and(|l| l.id == 1 && l.fits(0, blocks) && l.has_date())
}

/// Reads a `.mul` or `.flm` file: one trace-only [`ScanPair`] per image (see the module
/// docs).
pub fn read(bytes: &[u8]) -> Result<ScanFile, ReadError> {
    read_limited(bytes, &ReadLimits::default())
}

/// [`read`] under `limits` (see [`crate::limits`]).
pub fn read_limited(bytes: &[u8], limits: &ReadLimits) -> Result<ScanFile, ReadError> {
    let mut budget = Budget::new(limits, bytes.len())?;
    if !bytes.len().is_multiple_of(BLOCK) {
        return Err(ReadError::corrupt(
            FORMAT,
            format!(
                "{} bytes is not a whole number of 128-byte blocks (a cut or foreign file)",
                bytes.len()
            ),
        ));
    }
    if !looks_like_mul(bytes) {
        return Err(ReadError::wrong_format(
            FORMAT,
            "neither a .mul index nor a .flm image label at the start of the file",
        ));
    }
    let mut metadata = BTreeMap::new();
    let mut pairs = Vec::new();
    for (frame, (start, label)) in records(bytes, &mut metadata)?.into_iter().enumerate() {
        if let Some(pair) = image(bytes, start, &label, frame, &mut budget, &mut metadata)? {
            pairs.push(pair);
        }
    }
    if pairs.is_empty() {
        return Err(ReadError::NoImage {
            format: FORMAT,
            reason: metadata
                .get("skipped images")
                .cloned()
                .unwrap_or_else(|| "the file lists no image".to_string()),
        });
    }
    Ok(ScanFile {
        format: FORMAT,
        pairs,
        metadata,
    })
}

/// The images' label blocks and labels, in file order: from the index of a `.mul`, or by
/// walking a `.flm` from block 0.
fn records(
    bytes: &[u8],
    metadata: &mut BTreeMap<String, String>,
) -> Result<Vec<(usize, Label)>, ReadError> {
    let blocks = bytes.len() / BLOCK;
    if !bytes.starts_with(&MUL_START) {
        let mut records = Vec::new();
        let mut block = 0;
        while block < blocks {
            let label = Label::at(bytes, block).ok_or_else(|| truncated(bytes, block))?;
            if !label.fits(block, blocks) {
                metadata.insert(
                    "skipped data".to_string(),
                    format!("the bytes from block {block} on are not an image"),
                );
                break;
            }
            let next = block + label.size as usize;
            records.push((block, label));
            block = next;
        }
        return Ok(records);
    }
    let mut records = Vec::new();
    for entry in bytes[..INDEX_BLOCKS * BLOCK]
        .chunks_exact(6)
        .take(INDEX_ENTRIES)
    {
        let id = i16::from_le_bytes([entry[0], entry[1]]);
        let block = i32::from_le_bytes([entry[2], entry[3], entry[4], entry[5]]);
        if id == 0 {
            break;
        }
        if block < INDEX_BLOCKS as i32 || block as usize >= blocks {
            return Err(ReadError::corrupt(
                FORMAT,
                format!("the index puts image {id} at block {block}, outside the file"),
            ));
        }
        let block = block as usize;
        let label = Label::at(bytes, block).ok_or_else(|| truncated(bytes, block))?;
        records.push((block, label));
    }
    Ok(records)
}

fn truncated(bytes: &[u8], block: usize) -> ReadError {
    ReadError::Truncated {
        format: FORMAT,
        what: format!("the image label at block {block}"),
        offset: (block * BLOCK) as u64,
        needed: BLOCK as u64,
        len: bytes.len() as u64,
    }
}

/// One image's 128-byte label.
struct Label {
    id: i16,
    size: i16,
    xres: i16,
    yres: i16,
    date: [i16; 6],
    dims_angstrom: [i16; 2],
    zscale: i16,
    tilt: i16,
    speed: i16,
    bias: i16,
    current: i16,
    sample: String,
    title: String,
    mode: i16,
    current_factor: i16,
    point_spectra: i16,
}

impl Label {
    /// The label at `block`, or `None` past the end of `bytes`.
    fn at(bytes: &[u8], block: usize) -> Option<Label> {
        let raw = bytes.get(block * BLOCK..(block + 1) * BLOCK)?;
        let field = |offset: usize| i16::from_le_bytes([raw[offset], raw[offset + 1]]);
        let text = |offset: usize| {
            let chars = &raw[offset + 1..offset + 21];
            let end = chars.iter().position(|&c| c == 0).unwrap_or(chars.len());
            let shown: String = chars[..end].iter().map(|&c| c as char).collect();
            shown.trim().to_string()
        };
        Some(Label {
            id: field(0),
            size: field(2),
            xres: field(4),
            yres: field(6),
            date: [10, 12, 14, 16, 18, 20].map(field),
            dims_angstrom: [field(22), field(24)],
            zscale: field(30),
            tilt: field(32),
            speed: field(34),
            bias: field(36),
            current: field(38),
            sample: text(40),
            title: text(61),
            mode: field(86),
            current_factor: field(88),
            point_spectra: field(90),
        })
    }

    /// Whether the label's image, starting at `block`, has a sensible size that holds its
    /// data and ends inside a file of `blocks` blocks.
    fn fits(&self, block: usize, blocks: usize) -> bool {
        let sides = [self.xres, self.yres].map(|s| s as usize);
        let sane = self.id > 0 && sides.iter().all(|&s| (1..=MAX_SIDE).contains(&s));
        let data_blocks = (2 * sides[0] * sides[1]).div_ceil(BLOCK);
        sane && self.size > 0
            && self.size as usize > data_blocks
            && block + self.size as usize <= blocks
    }

    /// The label's date as seconds since 1970 (the file's clock), taken as the frame's
    /// start; `None` without a plausible date.
    fn start_time(&self) -> Option<f64> {
        let [year, month, day, hour, minute, second] = self.date;
        let field = |v: i16| u32::try_from(v).ok();
        self.has_date()
            .then(|| {
                dhct_scan::clock::seconds_from_civil(
                    (i64::from(year), field(month)?, field(day)?),
                    (field(hour)?, field(minute)?, f64::from(second)),
                )
            })
            .flatten()
    }

    fn has_date(&self) -> bool {
        let [year, month, day, hour, minute, second] = self.date;
        (1980..=2100).contains(&year)
            && (1..=12).contains(&month)
            && (1..=31).contains(&day)
            && (0..24).contains(&hour)
            && (0..60).contains(&minute)
            && (0..61).contains(&second)
    }

    /// `image <id>`, with the sample and title when the file has them.
    fn name(&self) -> String {
        let text: Vec<&str> = [self.sample.as_str(), self.title.as_str()]
            .into_iter()
            .filter(|t| !t.is_empty())
            .collect();
        match text.is_empty() {
            true => format!("image {}", self.id),
            false => format!("image {} ({})", self.id, text.join(", ")),
        }
    }

    /// What the image holds: (name, unit, value per count), or why it is not read.
    fn signal(&self) -> Result<(&'static str, &'static str, f64), String> {
        match self.mode {
            0 | 7 if self.zscale == 0 => Err("Z-scale 0 V: no height calibration".into()),
            0 | 7 => Ok((
                "height",
                "m",
                -f64::from(self.zscale) * 0.1 / 1.36 * 1e-10 / 200.0,
            )),
            1 => Ok((
                "current",
                "A",
                f64::from(self.current_factor.max(1)) * 1e-8 / 32768.0,
            )),
            8 => Ok(("voltage", "V", -10.0 / 32768.0)),
            mode => Err(format!("mode {mode} (a spectroscopy map), not an image")),
        }
    }
}

/// The image of the label at block `start` as frame `frame`, or `None` (with a note in
/// `metadata`) for an image that is not a height, current or voltage map.
fn image(
    bytes: &[u8],
    start: usize,
    label: &Label,
    frame: usize,
    budget: &mut Budget,
    metadata: &mut BTreeMap<String, String>,
) -> Result<Option<ScanPair>, ReadError> {
    let blocks = bytes.len() / BLOCK;
    if !label.fits(start, blocks) {
        return Err(ReadError::corrupt(
            FORMAT,
            format!(
                "image {} at block {start} claims {} x {} px in {} blocks, which the file \
                 cannot hold",
                label.id, label.xres, label.yres, label.size
            ),
        ));
    }
    let name = label.name();
    let (signal, unit, per_count) = match label.signal() {
        Ok(signal) => signal,
        Err(why) => {
            note(metadata, "skipped images", format!("{name}: {why}"));
            return Ok(None);
        }
    };
    let (columns, rows) = (label.xres as usize, label.yres as usize);
    budget.charge_images(FORMAT, columns as u64, rows as u64, 1, 2)?;
    let data = &bytes[(start + 1) * BLOCK..(start + 1) * BLOCK + 2 * columns * rows];
    let mut values = Vec::with_capacity(columns * rows);
    for row in data.chunks_exact(2 * columns).rev() {
        values.extend(
            row.chunks_exact(2)
                .map(|v| f64::from(i16::from_le_bytes([v[0], v[1]])) * per_count),
        );
    }
    let channel =
        ImageChannel::from_row_major(format!("{name} {signal}"), unit, rows, columns, values)
            .map_err(|source| ReadError::geometry(FORMAT, source))?;
    describe(label, metadata);
    let geometry = geometry(label, frame, metadata)?;
    ScanPair::new(geometry, channel, None)
        .map(Some)
        .map_err(|source| ReadError::geometry(FORMAT, source))
}

/// The frame's geometry; what the label lacks is a placeholder, noted under `image <id>`.
fn geometry(
    label: &Label,
    frame: usize,
    metadata: &mut BTreeMap<String, String>,
) -> Result<ScanGeometry, ReadError> {
    let (columns, rows) = (label.xres as usize, label.yres as usize);
    let who = format!("image {}", label.id);
    let [xdim, ydim] = label.dims_angstrom.map(|d| f64::from(d) * 1e-10);
    let pitch = [xdim / columns as f64, ydim / rows as f64];
    let (pitch, scale_source) = if pitch.iter().all(|p| plausible(*p, &PLAUSIBLE_PITCH_M)) {
        (pitch, ValueSource::Stated)
    } else {
        let why = format!("{who}: scan size {xdim:e} x {ydim:e} m is not usable");
        note(metadata, ASSUMED_SCALE_KEY, why);
        ([ASSUMED_PITCH; 2], ValueSource::Assumed)
    };
    let duration = f64::from(label.speed) / 100.0;
    let line_time = duration / (2.0 * rows as f64);
    let line_time = if plausible(line_time / columns as f64, &PLAUSIBLE_PIXEL_PERIOD_S) {
        note(
            metadata,
            ASSUMED_TIMING_KEY,
            "the file does not record the slow-scan direction: lines read as acquired bottom \
             to top, in storage order",
        );
        line_time
    } else {
        let why = format!("{who}: scan duration {duration} s is not usable");
        note(metadata, ASSUMED_TIMING_KEY, why);
        ASSUMED_PIXEL_PERIOD * columns as f64
    };
    let geometry_error = |source| ReadError::geometry(FORMAT, source);
    let mut geometry = ScanGeometry::from_line_time(
        columns,
        rows,
        pitch[0],
        pitch[1],
        line_time,
        ScanDirection::Right,
        ScanDirection::Up,
    )
    .map_err(geometry_error)?
    .with_scale_source(scale_source)
    .with_timing_source(ValueSource::Assumed)
    .with_frame(frame)
    .with_start_time(label.start_time());
    let tilt = f64::from(label.tilt).to_radians();
    if tilt != 0.0 && plausible(tilt, &PLAUSIBLE_SCAN_ANGLE_RAD) {
        geometry = geometry.with_scan_angle(tilt).map_err(geometry_error)?;
    }
    Ok(geometry)
}

/// The label's date, bias, setpoint and timing under `image <id>: …` keys.
fn describe(label: &Label, metadata: &mut BTreeMap<String, String>) {
    let [year, month, day, hour, minute, second] = label.date;
    let mut put = |key: &str, value: String| {
        metadata.insert(format!("image {}: {key}", label.id), value);
    };
    put(
        "date",
        format!("{year}-{month:02}-{day:02} {hour:02}:{minute:02}:{second:02}"),
    );
    put(
        "scan duration",
        format!("{} s", f64::from(label.speed) / 100.0),
    );
    put(
        "bias",
        format!("{} V", -10.0 * f64::from(label.bias) / 32768.0),
    );
    put(
        "setpoint current",
        format!("{} nA", f64::from(label.current) / 100.0),
    );
    put("scan rotation", format!("{} deg", label.tilt));
    put("mode", label.mode.to_string());
    if label.point_spectra > 0 {
        put("point spectra (not read)", label.point_spectra.to_string());
    }
}
