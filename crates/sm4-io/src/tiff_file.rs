//! Grey-scale TIFF: float32 and scaled 16-bit writers, and a reader for single-channel
//! 8/16/32/64-bit integer and 32/64-bit float images (via the `tiff` crate).
//!
//! Both writers put a small text block in the `ImageDescription` tag (tag 270):
//!
//! ```text
//! dhct image
//! name=Topography
//! unit=m
//! z_offset=-1.2e-10      (16-bit files only)
//! z_step=3.4e-15         (16-bit files only)
//! ```
//!
//! so that dhct's reader restores the channel name, unit and, for 16-bit files, the physical
//! values `z = z_offset + z_step · count`. Other programs show the image and ignore the text.
//!
//! [`write_f32_with_pixel_size`] also stores the pixel size for other programs:
//! `XResolution`/`YResolution` (pixels per centimetre, `ResolutionUnit` = centimetre) and an
//! ImageJ header (`ImageJ=1.11a`, `unit=um`, `vunit=<z unit>`) before dhct's block, which then
//! names the z unit `z_unit` (ImageJ reads `unit` as the length unit). ImageJ/Fiji convert a
//! centimetre resolution only for `unit=um`, so they show µm.
//!
//! A TIFF carries no scan timing, so the reader returns the placeholder geometry of
//! [`crate::npy`]: pixel period [`crate::ASSUMED_PIXEL_PERIOD`], fast right, slow down, timing
//! [`ValueSource::Assumed`](dhct_scan::ValueSource). The pixel size is read from the
//! resolution tags where the description says they are physical (a dhct TIFF, or an ImageJ
//! header with a length unit), and is otherwise the placeholder [`crate::ASSUMED_PITCH`],
//! marked assumed.
//! Only the first image of a multi-page file is read. Row 0 is the top row (TIFF's default
//! orientation; the `Orientation` tag is not interpreted).
//!
//! Decoder limits are set from the file length (a hostile header cannot make the decoder
//! allocate more than [`DECODE_BUDGET_PER_BYTE`] bytes per file byte, at least 1 MiB and at
//! most 1 GiB) and from the [`ReadLimits`] budget, which also counts the 8× larger `f64`
//! copy of the samples: a 16 MB deflate bomb is refused before it is decoded.

use std::collections::BTreeMap;
use std::io::{Cursor, Seek, Write};

use ::tiff::ColorType;
use ::tiff::TiffError;
use ::tiff::decoder::{Decoder, DecodingResult, Limits};
use ::tiff::encoder::{Rational, TiffEncoder, colortype};
use ::tiff::tags::ResolutionUnit;
use ::tiff::tags::Tag;
use dhct_scan::{FileFormat, ImageChannel, ScanPair, ValueSource};

use crate::limits::{Budget, ReadLimits};
use crate::placeholders::{ASSUMED_SCALE_KEY, ASSUMED_TIMING_KEY};
use crate::{ReadError, ScanFile, WriteError};

const FORMAT: FileFormat = FileFormat::Tiff;
const DESCRIPTION_MAGIC: &str = "dhct image";

/// Decoded bytes allowed per byte of file (deflate/LZW can expand data a lot, but not this
/// much for real images).
pub const DECODE_BUDGET_PER_BYTE: usize = 64;

/// Name given to the channel of a TIFF file that was not written by dhct.
pub const DEFAULT_NAME: &str = "TIFF image";

/// The linear map between 16-bit counts and physical values: `z = offset + step · count`.
///
/// [`write_u16`] (and [`crate::png_file::write_gray16`]) map the smallest finite value to
/// count 0 and the largest to 65535; NaN and infinities become count 0.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct U16Scale {
    /// Value of count 0 (the smallest finite value), in the channel's unit.
    pub offset: f64,
    /// Value step per count, in the channel's unit; positive.
    pub step: f64,
}

impl U16Scale {
    /// The scale that maps `low..=high` onto `0..=65535`. A flat or empty range gets step 1
    /// (every count is `low`).
    pub fn for_range(low: f64, high: f64) -> U16Scale {
        let step = (high - low) / f64::from(u16::MAX);
        if low.is_finite() && step.is_finite() && step > 0.0 {
            U16Scale { offset: low, step }
        } else {
            U16Scale {
                offset: if low.is_finite() { low } else { 0.0 },
                step: 1.0,
            }
        }
    }

    /// The scale for the finite values of `channel` (offset 0, step 1 if there are none).
    pub fn for_channel(channel: &ImageChannel) -> U16Scale {
        match channel.finite_range() {
            Some((low, high)) => U16Scale::for_range(low, high),
            None => U16Scale::for_range(0.0, 0.0),
        }
    }

    /// The count of `value`, rounded to nearest and clamped to `0..=65535`; NaN and
    /// infinities give 0.
    pub fn count(&self, value: f64) -> u16 {
        if !value.is_finite() {
            return 0;
        }
        let count = ((value - self.offset) / self.step).round();
        if count.is_nan() {
            0
        } else {
            count.clamp(0.0, f64::from(u16::MAX)) as u16
        }
    }

    /// The physical value of `count`.
    pub fn value(&self, count: u16) -> f64 {
        self.offset + self.step * f64::from(count)
    }
}

/// Writes `channel` as a single-page, uncompressed 32-bit float grey TIFF (values rounded to
/// `f32`, NaN kept), with the name and unit in `ImageDescription`. The file carries no pixel
/// size (see [`write_f32_with_pixel_size`]).
pub fn write_f32<W: Write>(channel: &ImageChannel, w: &mut W) -> Result<(), WriteError> {
    write_f32_pages(&[channel], None, w)
}

/// [`write_f32`] with the physical pixel size `pitch_m` (x, y; metres per pixel) stored so
/// other programs show lengths: `XResolution`/`YResolution` in pixels per centimetre with
/// `ResolutionUnit` = centimetre (TIFF 6.0), and an ImageJ header in `ImageDescription`
/// (`ImageJ=…`, `unit=um`: ImageJ and Fiji convert centimetre resolutions only for µm)
/// followed by dhct's own block, whose z unit is then `z_unit=` (ImageJ's `unit` is the
/// length unit). Fails when a pitch is not positive and finite or does not fit a 32-bit
/// rational in pixels per centimetre (pitch below about 2.3 pm).
pub fn write_f32_with_pixel_size<W: Write>(
    channel: &ImageChannel,
    pitch_m: [f64; 2],
    w: &mut W,
) -> Result<(), WriteError> {
    write_f32_pages_with_pixel_size(&[channel], pitch_m, w)
}

/// The TIFF rational nearest to `1 / pitch` in pixels per centimetre (numerator and
/// denominator at most `u32::MAX`).
fn pixels_per_centimetre(pitch_m: f64) -> Result<Rational, WriteError> {
    let per_cm = 0.01 / pitch_m;
    let max = f64::from(u32::MAX);
    if !(pitch_m.is_finite() && pitch_m > 0.0 && per_cm.is_finite() && per_cm <= max) {
        return Err(WriteError::Unrepresentable {
            format: FORMAT,
            reason: format!(
                "a pixel size of {pitch_m:e} m is not a TIFF resolution (positive, at most \
                 2^32 - 1 pixels per centimetre)"
            ),
        });
    }
    // The largest denominator that keeps the numerator in range: the finest rational.
    let denominator = (max / per_cm.max(1.0)).floor().clamp(1.0, max);
    let numerator = (per_cm * denominator).round().clamp(1.0, max);
    Ok(Rational {
        n: numerator as u32,
        d: denominator as u32,
    })
}

/// [`write_f32_with_pixel_size`] for several images of one size, one page each, in order
/// (e.g. a displacement field's `dx` and `dy`); each page carries its own name and unit.
pub fn write_f32_pages_with_pixel_size<W: Write>(
    pages: &[&ImageChannel],
    pitch_m: [f64; 2],
    w: &mut W,
) -> Result<(), WriteError> {
    let resolution = [
        pixels_per_centimetre(pitch_m[0])?,
        pixels_per_centimetre(pitch_m[1])?,
    ];
    write_f32_pages(pages, Some(resolution), w)
}

fn write_f32_pages<W: Write>(
    pages: &[&ImageChannel],
    resolution: Option<[Rational; 2]>,
    w: &mut W,
) -> Result<(), WriteError> {
    let mut cursor = Cursor::new(Vec::new());
    {
        let mut stack = F32Pages::start(&mut cursor, resolution)?;
        for channel in pages {
            stack.push(channel)?;
        }
    }
    w.write_all(cursor.get_ref())?;
    Ok(())
}

/// A multi-page float32 TIFF written a page at a time, each page as
/// [`write_f32_pages_with_pixel_size`] writes it: a long stack never has to be held whole,
/// neither as images nor as bytes. The writer must seek (a file, or a buffered file).
pub struct F32Pages<W: Write + Seek> {
    encoder: TiffEncoder<W>,
    resolution: Option<[Rational; 2]>,
}

impl<W: Write + Seek> F32Pages<W> {
    /// Starts a stack whose pages have the pixel size `pitch_m` (x, y; metres per pixel).
    pub fn with_pixel_size(w: W, pitch_m: [f64; 2]) -> Result<F32Pages<W>, WriteError> {
        let resolution = [
            pixels_per_centimetre(pitch_m[0])?,
            pixels_per_centimetre(pitch_m[1])?,
        ];
        F32Pages::start(w, Some(resolution))
    }

    fn start(w: W, resolution: Option<[Rational; 2]>) -> Result<F32Pages<W>, WriteError> {
        Ok(F32Pages {
            encoder: TiffEncoder::new(w).map_err(encoder_error)?,
            resolution,
        })
    }

    /// Appends `channel` as the next page, with its own name and unit.
    pub fn push(&mut self, channel: &ImageChannel) -> Result<(), WriteError> {
        let (width, height) = dimensions(channel)?;
        let data: Vec<f32> = channel.z.iter().map(|&v| v as f32).collect();
        let description = match self.resolution {
            Some(_) => imagej_description(channel),
            None => description(channel, None),
        };
        let mut image = self
            .encoder
            .new_image::<colortype::Gray32Float>(width, height)
            .map_err(encoder_error)?;
        let tags = image.encoder();
        tags.write_tag(Tag::ImageDescription, description.as_str())
            .map_err(encoder_error)?;
        if let Some([x, y]) = &self.resolution {
            let copy = |r: &Rational| Rational { n: r.n, d: r.d };
            tags.write_tag(Tag::XResolution, copy(x))
                .map_err(encoder_error)?;
            tags.write_tag(Tag::YResolution, copy(y))
                .map_err(encoder_error)?;
            tags.write_tag(Tag::ResolutionUnit, ResolutionUnit::Centimeter.to_u16())
                .map_err(encoder_error)?;
        }
        image.write_data(&data).map_err(encoder_error)
    }
}

/// Writes `channel` as a single-page, uncompressed 16-bit grey TIFF: the finite range maps
/// linearly onto 0..65535 and NaN onto 0 (see [`U16Scale`]). Returns the scale, which is
/// also stored in `ImageDescription`.
pub fn write_u16<W: Write>(channel: &ImageChannel, w: &mut W) -> Result<U16Scale, WriteError> {
    let (width, height) = dimensions(channel)?;
    let scale = U16Scale::for_channel(channel);
    let data: Vec<u16> = channel.z.iter().map(|&v| scale.count(v)).collect();
    let description = description(channel, Some(scale));
    let mut cursor = Cursor::new(Vec::new());
    {
        let mut encoder = TiffEncoder::new(&mut cursor).map_err(encoder_error)?;
        let mut image = encoder
            .new_image::<colortype::Gray16>(width, height)
            .map_err(encoder_error)?;
        image
            .encoder()
            .write_tag(Tag::ImageDescription, description.as_str())
            .map_err(encoder_error)?;
        image.write_data(&data).map_err(encoder_error)?;
    }
    w.write_all(cursor.get_ref())?;
    Ok(scale)
}

/// Reads the first image of a grey-scale TIFF (see the module docs).
pub fn read(bytes: &[u8]) -> Result<ScanFile, ReadError> {
    read_limited(bytes, &ReadLimits::default())
}

/// The decoder's explicit limits for a file of `len` bytes when `available` bytes of the
/// read budget are left: the decoded buffer may be at most [`DECODE_BUDGET_PER_BYTE`] bytes
/// per file byte (at least 1 MiB, at most 1 GiB) and never more than the budget.
fn decoder_limits(len: usize, available: u64) -> Limits {
    let budget = len
        .saturating_mul(DECODE_BUDGET_PER_BYTE)
        .clamp(1 << 20, 1 << 30)
        .min(usize::try_from(available).unwrap_or(usize::MAX));
    let mut limits = Limits::default();
    limits.decoding_buffer_size = budget;
    limits.intermediate_buffer_size = budget;
    limits.ifd_value_size = len.clamp(1 << 10, 1 << 20);
    limits
}

/// [`read`] under `limits` (see [`crate::limits`]): the decoder gets explicit
/// [`Limits`] and the image is charged to the budget twice, as the decoded samples and as
/// their `f64` copy (8 bytes per pixel), before it is decoded.
pub fn read_limited(bytes: &[u8], limits: &ReadLimits) -> Result<ScanFile, ReadError> {
    if !(bytes.starts_with(b"II*\0")
        || bytes.starts_with(b"MM\0*")
        || bytes.starts_with(b"II+\0")
        || bytes.starts_with(b"MM\0+"))
    {
        return Err(ReadError::wrong_format(FORMAT, "no TIFF byte-order mark"));
    }
    let mut read_budget = Budget::new(limits, bytes.len())?;
    let decoder_limits = decoder_limits(bytes.len(), read_budget.bytes_left());
    let budget = decoder_limits.decoding_buffer_size;
    let mut decoder = Decoder::new(Cursor::new(bytes))
        .map_err(|e| read_error(e, bytes))?
        .with_limits(decoder_limits);
    let (width, height) = decoder.dimensions().map_err(|e| read_error(e, bytes))?;
    if width == 0 || height == 0 {
        return Err(ReadError::NoImage {
            format: FORMAT,
            reason: format!("the image is {width} x {height} px"),
        });
    }
    let bits = sample_bits(decoder.colortype().map_err(|e| read_error(e, bytes))?)?;
    check_plausible_size(width, height, bits, budget as u64, bytes.len())?;
    read_budget.charge_images(
        FORMAT,
        u64::from(width),
        u64::from(height),
        1,
        u64::from(bits / 8),
    )?;
    let description = decoder
        .get_tag_ascii_string(Tag::ImageDescription)
        .ok()
        .unwrap_or_default();
    let pitch = stated_pitch(&mut decoder, &description);
    let more_pages = decoder.more_images();
    let image = decoder.read_image().map_err(|e| read_error(e, bytes))?;
    let values = samples_as_f64(image)?;

    let info = parse_description(&description);
    let scale = match (info.z_offset, info.z_step) {
        (Some(offset), Some(step)) if bits == 16 => Some(U16Scale { offset, step }),
        _ => None,
    };
    let values = match scale {
        Some(scale) => values
            .into_iter()
            .map(|v| scale.offset + scale.step * v)
            .collect(),
        None => values,
    };
    let (columns, rows) = match (usize::try_from(width), usize::try_from(height)) {
        (Ok(c), Ok(r)) => (c, r),
        _ => {
            return Err(ReadError::corrupt(
                FORMAT,
                "image too large for this machine",
            ));
        }
    };
    let name = info.name.unwrap_or_else(|| DEFAULT_NAME.to_string());
    let channel =
        ImageChannel::from_row_major(name, info.unit.unwrap_or_default(), rows, columns, values)
            .map_err(|source| ReadError::geometry(FORMAT, source))?;
    let mut geometry = crate::npy::assumed_geometry(columns, rows)
        .map_err(|source| ReadError::geometry(FORMAT, source))?;
    if let Some([x, y]) = pitch {
        geometry = geometry
            .with_pitch(x, y)
            .map_err(|source| ReadError::geometry(FORMAT, source))?
            .with_scale_source(ValueSource::Stated);
    }
    let pair = ScanPair::new(geometry, channel, None)
        .map_err(|source| ReadError::geometry(FORMAT, source))?;

    let mut metadata = tiff_metadata(bits, more_pages, &description, scale);
    if let Some([x, y]) = pitch {
        metadata.remove(ASSUMED_SCALE_KEY);
        metadata.insert(
            "tiff pixel size".to_string(),
            format!("{x:e} m × {y:e} m (resolution tags)"),
        );
    }
    Ok(ScanFile {
        format: FORMAT,
        pairs: vec![pair],
        metadata,
    })
}

/// The pixel size (metres, x and y) the resolution tags state, trusted only where the
/// description says they are physical: a TIFF written by dhct (its block in
/// `ImageDescription`) or an ImageJ header with a length `unit` (`nm`, `um`/`micron`/`µm`,
/// `mm`, `cm`, `m`, `A`/`Å`). A bare resolution (often 72 dpi of a screen) is no scale.
fn stated_pitch(decoder: &mut Decoder<Cursor<&[u8]>>, description: &str) -> Option<[f64; 2]> {
    let mut resolution = |tag| match decoder.find_tag(tag).ok().flatten()? {
        ::tiff::decoder::ifd::Value::Rational(n, d) if n > 0 && d > 0 => {
            Some(f64::from(n) / f64::from(d))
        }
        _ => None,
    };
    let (x, y) = (resolution(Tag::XResolution)?, resolution(Tag::YResolution)?);
    let unit = decoder
        .find_tag(Tag::ResolutionUnit)
        .ok()
        .flatten()
        .and_then(|v| v.into_u16().ok())
        .unwrap_or(2);
    // ImageJ's header comes first; dhct's block after it names the z unit `unit` or `z_unit`.
    let imagej_header = description
        .starts_with("ImageJ=")
        .then(|| {
            description
                .lines()
                .take_while(|l| l.trim() != DESCRIPTION_MAGIC)
        })
        .into_iter()
        .flatten();
    let imagej_unit_m = imagej_header.into_iter().find_map(|line| {
        let value = line.trim().strip_prefix("unit=")?.trim();
        match value {
            "nm" => Some(1e-9),
            "um" | "µm" | "micron" | "microns" => Some(1e-6),
            "mm" => Some(1e-3),
            "cm" => Some(1e-2),
            "m" => Some(1.0),
            "A" | "Å" | "angstrom" => Some(1e-10),
            _ => None,
        }
    });
    let ours = description
        .lines()
        .any(|line| line.trim() == DESCRIPTION_MAGIC);
    // Metres per resolution unit: centimetre and inch by the TIFF standard (trusted for our
    // own files and ImageJ's), none (1) in ImageJ's length unit.
    let unit_m = match unit {
        3 if ours || imagej_unit_m.is_some() => 1e-2,
        2 if ours || imagej_unit_m.is_some() => 2.54e-2,
        1 => imagej_unit_m?,
        _ => return None,
    };
    let pitch = [unit_m / x, unit_m / y];
    pitch
        .iter()
        .all(|p| p.is_finite() && (1e-15..=1.0).contains(p))
        .then_some(pitch)
}

/// The bits per sample of a single-channel grey image (8, 16, 32 or 64).
fn sample_bits(colour: ColorType) -> Result<u8, ReadError> {
    match colour {
        ColorType::Gray(bits @ (8 | 16 | 32 | 64)) => Ok(bits),
        other => Err(ReadError::unsupported(
            FORMAT,
            format!(
                "colour type {other:?}; dhct reads single-channel grey images of 8, 16, 32 or 64 bits"
            ),
        )),
    }
}

/// Refuses an image whose decoded samples would exceed the decoder's buffer budget.
fn check_plausible_size(
    width: u32,
    height: u32,
    bits: u8,
    budget: u64,
    file_len: usize,
) -> Result<(), ReadError> {
    let needed = crate::bytes::checked_data_len(
        FORMAT,
        u64::from(height),
        u64::from(width),
        u64::from(bits / 8),
    )?;
    if needed > budget {
        return Err(ReadError::corrupt(
            FORMAT,
            format!(
                "a {width} x {height} px image of {bits}-bit samples needs {needed} bytes, \
                 more than a {file_len}-byte file can plausibly hold"
            ),
        ));
    }
    Ok(())
}

/// The decoded samples as `f64`.
fn samples_as_f64(image: DecodingResult) -> Result<Vec<f64>, ReadError> {
    Ok(match image {
        DecodingResult::U8(v) => v.into_iter().map(f64::from).collect(),
        DecodingResult::U16(v) => v.into_iter().map(f64::from).collect(),
        DecodingResult::U32(v) => v.into_iter().map(f64::from).collect(),
        DecodingResult::U64(v) => v.into_iter().map(|x| x as f64).collect(),
        DecodingResult::I8(v) => v.into_iter().map(f64::from).collect(),
        DecodingResult::I16(v) => v.into_iter().map(f64::from).collect(),
        DecodingResult::I32(v) => v.into_iter().map(f64::from).collect(),
        DecodingResult::I64(v) => v.into_iter().map(|x| x as f64).collect(),
        DecodingResult::F32(v) => v.into_iter().map(f64::from).collect(),
        DecodingResult::F64(v) => v,
        DecodingResult::F16(_) => {
            return Err(ReadError::unsupported(FORMAT, "16-bit float samples"));
        }
    })
}

/// The file's metadata: sample bits, the assumptions, pages, description and z scale.
fn tiff_metadata(
    bits: u8,
    more_pages: bool,
    description: &str,
    scale: Option<U16Scale>,
) -> BTreeMap<String, String> {
    let mut metadata = BTreeMap::new();
    metadata.insert("tiff sample bits".to_string(), bits.to_string());
    metadata.insert(
        ASSUMED_SCALE_KEY.to_string(),
        "TIFF carries no scale".into(),
    );
    metadata.insert(
        ASSUMED_TIMING_KEY.to_string(),
        "TIFF carries no timing".into(),
    );
    if more_pages {
        metadata.insert(
            "tiff pages".to_string(),
            "several; only the first was read".to_string(),
        );
    }
    if !description.is_empty() && !description.starts_with(DESCRIPTION_MAGIC) {
        metadata.insert(
            "tiff description".to_string(),
            description.chars().take(500).collect(),
        );
    }
    if let Some(scale) = scale {
        metadata.insert(
            "tiff z scale".to_string(),
            format!("z = {:e} + {:e} · count", scale.offset, scale.step),
        );
    }
    metadata
}

/// What dhct stored in `ImageDescription`.
#[derive(Default)]
struct DescriptionInfo {
    name: Option<String>,
    unit: Option<String>,
    z_offset: Option<f64>,
    z_step: Option<f64>,
}

fn parse_description(text: &str) -> DescriptionInfo {
    let mut info = DescriptionInfo::default();
    // dhct's block starts at its magic line: the first line, or after an ImageJ header.
    let mut lines = text.lines();
    if !lines.any(|line| line.trim() == DESCRIPTION_MAGIC) {
        return info;
    }
    for line in lines {
        let Some((key, value)) = line.split_once('=') else {
            continue;
        };
        let value = value.trim();
        match key.trim() {
            "name" => info.name = Some(value.to_string()),
            "unit" | "z_unit" => info.unit = Some(value.to_string()),
            "z_offset" => info.z_offset = value.parse().ok().filter(|v: &f64| v.is_finite()),
            "z_step" => {
                info.z_step = value
                    .parse()
                    .ok()
                    .filter(|v: &f64| v.is_finite() && *v > 0.0)
            }
            _ => {}
        }
    }
    info
}

/// ASCII only: TIFF ASCII tags are 7-bit; other characters become '?'.
fn ascii(text: &str) -> String {
    text.chars()
        .map(|c| {
            if c.is_ascii() && !c.is_ascii_control() {
                c
            } else {
                '?'
            }
        })
        .collect()
}

/// The ImageJ header (length unit µm, matching the centimetre resolution tags; the value
/// unit as `vunit`) followed by dhct's block with the z unit as `z_unit`.
fn imagej_description(channel: &ImageChannel) -> String {
    format!(
        "ImageJ=1.11a\nunit=um\nvunit={unit}\n{DESCRIPTION_MAGIC}\nname={}\nz_unit={unit}\n",
        ascii(&channel.name),
        unit = ascii(&channel.unit)
    )
}

fn description(channel: &ImageChannel, scale: Option<U16Scale>) -> String {
    let mut text = format!(
        "{DESCRIPTION_MAGIC}\nname={}\nunit={}\n",
        ascii(&channel.name),
        ascii(&channel.unit)
    );
    if let Some(scale) = scale {
        text.push_str(&format!(
            "z_offset={:e}\nz_step={:e}\n",
            scale.offset, scale.step
        ));
    }
    text
}

fn dimensions(channel: &ImageChannel) -> Result<(u32, u32), WriteError> {
    match (
        u32::try_from(channel.columns()),
        u32::try_from(channel.rows()),
    ) {
        (Ok(w), Ok(h)) if w > 0 && h > 0 => Ok((w, h)),
        _ => Err(WriteError::Unrepresentable {
            format: FORMAT,
            reason: format!(
                "a TIFF image must be 1 to 2^32-1 px along each side, not {} x {}",
                channel.columns(),
                channel.rows()
            ),
        }),
    }
}

fn encoder_error(error: TiffError) -> WriteError {
    match error {
        TiffError::IoError(e) => WriteError::Stream(e),
        other => WriteError::Encoder {
            format: FORMAT,
            reason: other.to_string(),
        },
    }
}

fn read_error(error: TiffError, bytes: &[u8]) -> ReadError {
    match error {
        TiffError::IoError(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => {
            ReadError::Truncated {
                format: FORMAT,
                what: "TIFF directory or image data".to_string(),
                offset: bytes.len() as u64,
                needed: 1,
                len: bytes.len() as u64,
            }
        }
        TiffError::UnsupportedError(e) => ReadError::unsupported(FORMAT, e.to_string()),
        TiffError::LimitsExceeded => ReadError::corrupt(
            FORMAT,
            format!(
                "the image needs more memory than a {}-byte file can plausibly hold",
                bytes.len()
            ),
        ),
        other => ReadError::corrupt(FORMAT, other.to_string()),
    }
}
