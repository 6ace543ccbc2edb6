//! PNG export: 16-bit grey and 8-bit colour-mapped pictures of one image; and
//! [`read_picture`], which decodes any PNG into grey levels and alpha (for masks).
//!
//! PNG is a picture format: it holds no physical scale, so dhct writes it for viewing and
//! reports the z range it mapped, but does not read it back as a scan (see
//! [`crate::read_as`]). Row 0 of the image is the top row of the picture.

use std::io::Write;

use dhct_scan::{FileFormat, ImageChannel};
use serde::{Deserialize, Serialize};

use crate::limits::{Budget, ReadLimits};
use crate::tiff_file::U16Scale;
use crate::{ReadError, WriteError};

const FORMAT: FileFormat = FileFormat::Png;

/// Colour of NaN and infinite pixels in colour-mapped pictures (magenta, absent from every
/// colour map offered).
pub const NAN_COLOUR: [u8; 3] = [255, 0, 255];

/// Colour maps for [`write_colormap`]. All run from low values (dark) to high values (bright).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Colormap {
    /// matplotlib's perceptually uniform viridis (blue–green–yellow).
    #[default]
    Viridis,
    /// matplotlib's inferno (black–purple–orange–yellow).
    Inferno,
    /// matplotlib's magma (black–purple–pink–cream).
    Magma,
    /// matplotlib's plasma (blue–purple–orange–yellow).
    Plasma,
    /// cividis, designed for colour-vision deficiency (blue–grey–yellow).
    Cividis,
    /// Linear grey, black to white.
    Greys,
    /// The "afmhot"/gold map common for STM topography: black–brown–orange–yellow–white
    /// (red = 2t, green = 2t − ½, blue = 2t − 1, each clipped to 0..1).
    Gold,
}

impl Colormap {
    /// Every colour map, in the order listed above.
    pub const ALL: [Colormap; 7] = [
        Colormap::Viridis,
        Colormap::Inferno,
        Colormap::Magma,
        Colormap::Plasma,
        Colormap::Cividis,
        Colormap::Greys,
        Colormap::Gold,
    ];

    /// Lower-case name, as accepted by [`Colormap::parse`].
    pub fn name(self) -> &'static str {
        match self {
            Colormap::Viridis => "viridis",
            Colormap::Inferno => "inferno",
            Colormap::Magma => "magma",
            Colormap::Plasma => "plasma",
            Colormap::Cividis => "cividis",
            Colormap::Greys => "greys",
            Colormap::Gold => "gold",
        }
    }

    /// Parses a colour-map name, case-insensitively; `gray`/`grey` and `afmhot` are accepted
    /// as aliases of `greys` and `gold`.
    pub fn parse(name: &str) -> Option<Colormap> {
        match name.trim().to_ascii_lowercase().as_str() {
            "gray" | "grey" | "grays" => Some(Colormap::Greys),
            "afmhot" => Some(Colormap::Gold),
            other => Colormap::ALL.into_iter().find(|c| c.name() == other),
        }
    }

    /// The colour at position `t` (0 = lowest value, 1 = highest; clamped), as RGB.
    pub fn rgb(self, t: f64) -> [u8; 3] {
        let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
        let byte = |x: f64| (x.clamp(0.0, 1.0) * 255.0).round() as u8;
        let gradient = match self {
            Colormap::Viridis => colorous::VIRIDIS,
            Colormap::Inferno => colorous::INFERNO,
            Colormap::Magma => colorous::MAGMA,
            Colormap::Plasma => colorous::PLASMA,
            Colormap::Cividis => colorous::CIVIDIS,
            Colormap::Greys => {
                let g = byte(t);
                return [g, g, g];
            }
            Colormap::Gold => {
                return [byte(2.0 * t), byte(2.0 * t - 0.5), byte(2.0 * t - 1.0)];
            }
        };
        let c = gradient.eval_continuous(t);
        [c.r, c.g, c.b]
    }
}

/// A colour map sampled at [`ColourTable::ENTRIES`] evenly spaced positions, for drawing
/// whole images: a lookup per pixel instead of a spline evaluation. Entries differ from
/// [`Colormap::rgb`] by at most one 8-bit level.
#[derive(Debug, Clone)]
pub struct ColourTable {
    entries: Vec<[u8; 3]>,
}

impl ColourTable {
    /// Number of sampled positions.
    pub const ENTRIES: usize = 4096;

    /// The table of `colormap`.
    pub fn new(colormap: Colormap) -> Self {
        let last = (Self::ENTRIES - 1) as f64;
        ColourTable {
            entries: (0..Self::ENTRIES)
                .map(|k| colormap.rgb(k as f64 / last))
                .collect(),
        }
    }

    /// The colour at position `t` (0 = lowest value, 1 = highest; clamped; NaN = lowest).
    #[inline]
    pub fn rgb(&self, t: f64) -> [u8; 3] {
        let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
        self.entries[(t * (Self::ENTRIES - 1) as f64 + 0.5) as usize]
    }
}

/// The z range a colour-mapped picture shows: `low` (first colour) to `high` (last colour),
/// in the channel's unit. `None` when the image has no finite value.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ZRange {
    /// Value drawn with the first colour of the map.
    pub low: f64,
    /// Value drawn with the last colour of the map.
    pub high: f64,
}

impl ZRange {
    /// Position of `value` in the range, 0..1 (0 for a flat range).
    pub fn position(&self, value: f64) -> f64 {
        let span = self.high - self.low;
        if span > 0.0 && span.is_finite() {
            ((value - self.low) / span).clamp(0.0, 1.0)
        } else {
            0.0
        }
    }
}

/// Writes `channel` as a 16-bit grey PNG: the smallest finite value is black (0), the largest
/// white (65535), linearly; NaN and infinities are black. Returns the map from counts back to
/// values.
pub fn write_gray16<W: Write>(channel: &ImageChannel, w: &mut W) -> Result<U16Scale, WriteError> {
    let (width, height) = dimensions(channel)?;
    let scale = U16Scale::for_channel(channel);
    let mut data = Vec::with_capacity(channel.rows() * channel.columns() * 2);
    for &value in channel.z.iter() {
        data.extend_from_slice(&scale.count(value).to_be_bytes());
    }
    encode(
        w,
        width,
        height,
        png::ColorType::Grayscale,
        png::BitDepth::Sixteen,
        &data,
    )?;
    Ok(scale)
}

/// Writes `channel` as an 8-bit RGB PNG through `colormap`: the finite range maps linearly
/// onto the colour map ([`Colormap::rgb`] of [`ZRange::position`]), NaN and infinities are
/// drawn in [`NAN_COLOUR`]. Returns the range mapped (`None` if no value is finite).
pub fn write_colormap<W: Write>(
    channel: &ImageChannel,
    colormap: Colormap,
    w: &mut W,
) -> Result<Option<ZRange>, WriteError> {
    let (width, height) = dimensions(channel)?;
    let range = channel
        .finite_range()
        .map(|(low, high)| ZRange { low, high });
    let table = ColourTable::new(colormap);
    let mut data = Vec::with_capacity(channel.rows() * channel.columns() * 3);
    for &value in channel.z.iter() {
        let rgb = match range {
            Some(range) if value.is_finite() => table.rgb(range.position(value)),
            _ => NAN_COLOUR,
        };
        data.extend_from_slice(&rgb);
    }
    encode(
        w,
        width,
        height,
        png::ColorType::Rgb,
        png::BitDepth::Eight,
        &data,
    )?;
    Ok(range)
}

fn encode<W: Write>(
    w: &mut W,
    width: u32,
    height: u32,
    color: png::ColorType,
    depth: png::BitDepth,
    data: &[u8],
) -> Result<(), WriteError> {
    let mut encoder = png::Encoder::new(w, width, height);
    encoder.set_color(color);
    encoder.set_depth(depth);
    let mut writer = encoder.write_header().map_err(encoder_error)?;
    writer.write_image_data(data).map_err(encoder_error)?;
    writer.finish().map_err(encoder_error)
}

fn dimensions(channel: &ImageChannel) -> Result<(u32, u32), WriteError> {
    match (
        u32::try_from(channel.columns()),
        u32::try_from(channel.rows()),
    ) {
        (Ok(w), Ok(h)) if w > 0 && h > 0 && w < (1 << 31) && h < (1 << 31) => Ok((w, h)),
        _ => Err(WriteError::Unrepresentable {
            format: FORMAT,
            reason: format!(
                "a PNG image must be 1 to 2^31-1 px along each side, not {} x {}",
                channel.columns(),
                channel.rows()
            ),
        }),
    }
}

fn encoder_error(error: png::EncodingError) -> WriteError {
    match error {
        png::EncodingError::IoError(e) => WriteError::Stream(e),
        other => WriteError::Encoder {
            format: FORMAT,
            reason: other.to_string(),
        },
    }
}

/// A decoded PNG picture: grey levels and, when the file has one, alpha; row-major, row 0
/// at the top.
#[derive(Debug, Clone, PartialEq)]
pub struct Picture {
    /// Pixels along x.
    pub columns: usize,
    /// Pixels along y.
    pub rows: usize,
    /// Grey level of every pixel, 0 (black) to 1 (white); colour pictures give the mean of
    /// red, green and blue.
    pub grey: Vec<f64>,
    /// Opacity of every pixel, 0 (transparent) to 1 (opaque), when the picture has an alpha
    /// channel (grey + alpha, RGBA, or a palette or colour key with transparency).
    pub alpha: Option<Vec<f64>>,
    /// Bits per sample of the file (1, 2, 4, 8 or 16).
    pub bit_depth: u8,
}

/// Decodes a PNG of any colour type (grey, grey + alpha, RGB, RGBA, palette; 1–16 bits)
/// under `limits`: the decoder may allocate at most what the budget leaves, and the pixels
/// are charged (decoded buffer plus grey and alpha planes) before decoding.
pub fn read_picture(bytes: &[u8], limits: &ReadLimits) -> Result<Picture, ReadError> {
    let mut budget = Budget::new(limits, bytes.len())?;
    let decoder_bytes = usize::try_from(budget.bytes_left()).unwrap_or(usize::MAX);
    let mut decoder = png::Decoder::new_with_limits(
        std::io::Cursor::new(bytes),
        png::Limits {
            bytes: decoder_bytes,
        },
    );
    decoder.set_transformations(png::Transformations::EXPAND);
    let mut reader = decoder.read_info().map_err(png_read_error)?;
    let (width, height) = reader.info().size();
    let bit_depth = reader.info().bit_depth as u8;
    let (color, depth) = reader.output_color_type();
    let samples = color.samples();
    let bytes_per_sample = if depth == png::BitDepth::Sixteen {
        2
    } else {
        1
    };
    let planes = if matches!(color, png::ColorType::GrayscaleAlpha | png::ColorType::Rgba) {
        2
    } else {
        1
    };
    budget.charge_images(
        FORMAT,
        u64::from(width),
        u64::from(height),
        planes,
        (samples * bytes_per_sample) as u64,
    )?;
    let size = reader.output_buffer_size().ok_or_else(|| {
        ReadError::corrupt(
            FORMAT,
            format!("a {width} x {height} px picture is too large"),
        )
    })?;
    let mut buffer = vec![0u8; size];
    let frame = reader.next_frame(&mut buffer).map_err(png_read_error)?;
    let line = frame.line_size;
    let (columns, rows) = (width as usize, height as usize);
    let max = if bytes_per_sample == 2 {
        65535.0
    } else {
        255.0
    };
    let sample = |row: usize, column: usize, k: usize| -> f64 {
        let at = row * line + (column * samples + k) * bytes_per_sample;
        let value = if bytes_per_sample == 2 {
            buffer
                .get(at..at + 2)
                .map_or(0, |b| u16::from_be_bytes([b[0], b[1]]))
        } else {
            buffer.get(at).map_or(0, |&b| u16::from(b))
        };
        f64::from(value) / max
    };
    let colour = matches!(color, png::ColorType::Rgb | png::ColorType::Rgba);
    let mut grey = Vec::with_capacity(columns * rows);
    let mut alpha = (planes == 2).then(|| Vec::with_capacity(columns * rows));
    for row in 0..rows {
        for column in 0..columns {
            grey.push(if colour {
                (sample(row, column, 0) + sample(row, column, 1) + sample(row, column, 2)) / 3.0
            } else {
                sample(row, column, 0)
            });
            if let Some(alpha) = alpha.as_mut() {
                alpha.push(sample(row, column, samples - 1));
            }
        }
    }
    Ok(Picture {
        columns,
        rows,
        grey,
        alpha,
        bit_depth,
    })
}

/// Writes `picture` as a PNG: grey (or RGB with equal channels when `rgb`), plus an
/// alpha channel when `picture.alpha` is set, at 8 or 16 (`sixteen_bit`) bits per sample;
/// levels are rounded from 0..1. The inverse of [`read_picture`] (e.g. for masks).
pub fn write_picture<W: Write>(
    picture: &Picture,
    rgb: bool,
    sixteen_bit: bool,
    w: &mut W,
) -> Result<(), WriteError> {
    let pixels = picture.columns * picture.rows;
    if picture.grey.len() != pixels || picture.alpha.as_ref().is_some_and(|a| a.len() != pixels) {
        return Err(WriteError::Unrepresentable {
            format: FORMAT,
            reason: format!(
                "a {} x {} picture needs {pixels} levels, got {}",
                picture.columns,
                picture.rows,
                picture.grey.len()
            ),
        });
    }
    let (width, height) = match (u32::try_from(picture.columns), u32::try_from(picture.rows)) {
        (Ok(w), Ok(h)) if w > 0 && h > 0 => (w, h),
        _ => {
            return Err(WriteError::Unrepresentable {
                format: FORMAT,
                reason: "a PNG picture must be at least 1 x 1 px".into(),
            });
        }
    };
    let color = match (rgb, picture.alpha.is_some()) {
        (false, false) => png::ColorType::Grayscale,
        (false, true) => png::ColorType::GrayscaleAlpha,
        (true, false) => png::ColorType::Rgb,
        (true, true) => png::ColorType::Rgba,
    };
    let mut data = Vec::with_capacity(pixels * color.samples() * 2);
    let mut push = |level: f64| {
        let level = if level.is_finite() {
            level.clamp(0.0, 1.0)
        } else {
            0.0
        };
        if sixteen_bit {
            data.extend_from_slice(&((level * 65535.0).round() as u16).to_be_bytes());
        } else {
            data.push((level * 255.0).round() as u8);
        }
    };
    for k in 0..pixels {
        let grey = picture.grey[k];
        for _ in 0..if rgb { 3 } else { 1 } {
            push(grey);
        }
        if let Some(alpha) = &picture.alpha {
            push(alpha[k]);
        }
    }
    let depth = if sixteen_bit {
        png::BitDepth::Sixteen
    } else {
        png::BitDepth::Eight
    };
    encode(w, width, height, color, depth, &data)
}

fn png_read_error(error: png::DecodingError) -> ReadError {
    match error {
        png::DecodingError::IoError(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => {
            ReadError::Truncated {
                format: FORMAT,
                what: "PNG chunks".to_string(),
                offset: 0,
                needed: 1,
                len: 0,
            }
        }
        png::DecodingError::LimitsExceeded => ReadError::corrupt(
            FORMAT,
            "the picture needs more memory than the read limit allows",
        ),
        other => ReadError::corrupt(FORMAT, other.to_string()),
    }
}
