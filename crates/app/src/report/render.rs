//! Raster pictures with vector overlays (lattice sites, unit-cell outlines, asymmetric unit,
//! confidence ellipses), encoded as PNG for the output directory and the report.
//!
//! Coordinates are picture pixels (x right, y down, pixel centres at integers + ½ of the
//! upscaled grid); callers convert from image pixels or metres.

use dhct_sm4_io::png_file::{Colormap, ColourTable, NAN_COLOUR};
#[cfg(test)]
use ndarray::Array2;
use ndarray::ArrayView2;

/// An 8-bit RGB picture.
pub struct Canvas {
    /// Width, px.
    pub width: usize,
    /// Height, px.
    pub height: usize,
    rgb: Vec<u8>,
}

/// Robust display range of an image: the 0.5 and 99.5 percentiles of its finite values
/// (so a few spikes do not wash out the picture).
pub fn display_range<T: Copy + Into<f64>>(values: ArrayView2<T>) -> Option<(f64, f64)> {
    // About 200,000 evenly spaced pixels (a huge image is not copied whole).
    let step = (values.len() / 200_000).max(1);
    let mut finite: Vec<f64> = values
        .iter()
        .step_by(step)
        .map(|&v| v.into())
        .filter(|v: &f64| v.is_finite())
        .collect();
    if finite.is_empty() {
        // A sample of NaN only: look at every pixel before giving up.
        finite = values
            .iter()
            .map(|&v| v.into())
            .filter(|v: &f64| v.is_finite())
            .take(200_000)
            .collect();
        if finite.is_empty() {
            return None;
        }
    }
    finite.sort_by(f64::total_cmp);
    let at = |q: f64| finite[((finite.len() - 1) as f64 * q).round() as usize];
    let (low, high) = (at(0.005), at(0.995));
    Some(if high > low {
        (low, high)
    } else {
        (finite[0], finite[finite.len() - 1])
    })
}

impl Canvas {
    /// `image` through `colormap` over `range` (default: [`display_range`]), each pixel
    /// drawn as `scale × scale` picture pixels. NaN is drawn in [`NAN_COLOUR`].
    pub fn from_image<T: Copy + Into<f64>>(
        image: ArrayView2<T>,
        colormap: Colormap,
        range: Option<(f64, f64)>,
        scale: usize,
    ) -> Canvas {
        let (rows, columns) = image.dim();
        let scale = scale.max(1);
        let (width, height) = (columns * scale, rows * scale);
        let (low, high) = range.or_else(|| display_range(image)).unwrap_or((0.0, 1.0));
        let span = if high > low { high - low } else { 1.0 };
        let table = ColourTable::new(colormap);
        let mut rgb = vec![0u8; width * height * 3];
        for r in 0..rows {
            for c in 0..columns {
                let v: f64 = image[[r, c]].into();
                let colour = if v.is_finite() {
                    table.rgb((v - low) / span)
                } else {
                    NAN_COLOUR
                };
                for dy in 0..scale {
                    let row = (r * scale + dy) * width;
                    for dx in 0..scale {
                        let i = (row + c * scale + dx) * 3;
                        rgb[i..i + 3].copy_from_slice(&colour);
                    }
                }
            }
        }
        Canvas { width, height, rgb }
    }

    /// A picture from a function of picture-pixel centres (used for skewed unit cells).
    pub fn from_fn(
        width: usize,
        height: usize,
        colormap: Colormap,
        range: (f64, f64),
        value: impl Fn(f64, f64) -> f64,
    ) -> Canvas {
        let span = if range.1 > range.0 {
            range.1 - range.0
        } else {
            1.0
        };
        let table = ColourTable::new(colormap);
        let mut rgb = vec![0u8; width * height * 3];
        for y in 0..height {
            for x in 0..width {
                let v = value(x as f64 + 0.5, y as f64 + 0.5);
                let colour = if v.is_finite() {
                    table.rgb((v - range.0) / span)
                } else {
                    [255, 255, 255]
                };
                let i = (y * width + x) * 3;
                rgb[i..i + 3].copy_from_slice(&colour);
            }
        }
        Canvas { width, height, rgb }
    }

    fn blend(&mut self, x: i64, y: i64, colour: [u8; 3], alpha: f64) {
        if x < 0 || y < 0 || x as usize >= self.width || y as usize >= self.height || alpha <= 0.0 {
            return;
        }
        let i = (y as usize * self.width + x as usize) * 3;
        let a = alpha.min(1.0);
        for (channel, &target) in self.rgb[i..i + 3].iter_mut().zip(&colour) {
            let old = *channel as f64;
            *channel = (old + (target as f64 - old) * a).round() as u8;
        }
    }

    /// Greys out (blends towards mid-grey) every image pixel where `mask` is false; the
    /// canvas was drawn from an image of the mask's shape at `scale` picture px per pixel.
    pub fn dim_outside(&mut self, mask: &ndarray::Array2<bool>, scale: usize) {
        for y in 0..self.height {
            for x in 0..self.width {
                let (r, c) = (y / scale.max(1), x / scale.max(1));
                if r < mask.nrows() && c < mask.ncols() && !mask[[r, c]] {
                    self.blend(x as i64, y as i64, [128, 128, 128], 0.6);
                }
            }
        }
    }

    /// A filled disc (anti-aliased edge).
    pub fn disc(&mut self, centre: [f64; 2], radius: f64, colour: [u8; 3]) {
        let (x0, x1) = (
            (centre[0] - radius - 1.0).floor() as i64,
            (centre[0] + radius + 1.0).ceil() as i64,
        );
        let (y0, y1) = (
            (centre[1] - radius - 1.0).floor() as i64,
            (centre[1] + radius + 1.0).ceil() as i64,
        );
        for y in y0..=y1 {
            for x in x0..=x1 {
                let d = (x as f64 + 0.5 - centre[0]).hypot(y as f64 + 0.5 - centre[1]);
                self.blend(x, y, colour, radius + 0.5 - d);
            }
        }
    }

    /// A straight segment of the given width (anti-aliased).
    pub fn line(&mut self, a: [f64; 2], b: [f64; 2], width: f64, colour: [u8; 3]) {
        let half = 0.5 * width;
        let (x0, x1) = (a[0].min(b[0]) - half - 1.0, a[0].max(b[0]) + half + 1.0);
        let (y0, y1) = (a[1].min(b[1]) - half - 1.0, a[1].max(b[1]) + half + 1.0);
        if !(x0.is_finite() && x1.is_finite() && y0.is_finite() && y1.is_finite()) {
            return;
        }
        let (x0, x1) = (x0.max(0.0) as i64, x1.min(self.width as f64) as i64);
        let (y0, y1) = (y0.max(0.0) as i64, y1.min(self.height as f64) as i64);
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        let length2 = dx * dx + dy * dy;
        for y in y0..=y1 {
            for x in x0..=x1 {
                let (px, py) = (x as f64 + 0.5, y as f64 + 0.5);
                let t = if length2 > 0.0 {
                    (((px - a[0]) * dx + (py - a[1]) * dy) / length2).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                let d = (px - a[0] - t * dx).hypot(py - a[1] - t * dy);
                self.blend(x, y, colour, half + 0.5 - d);
            }
        }
    }

    /// A closed polygon outline.
    pub fn polygon(&mut self, points: &[[f64; 2]], width: f64, colour: [u8; 3]) {
        for i in 0..points.len() {
            self.line(points[i], points[(i + 1) % points.len()], width, colour);
        }
    }

    /// A "+" marker.
    pub fn cross(&mut self, centre: [f64; 2], size: f64, width: f64, colour: [u8; 3]) {
        let [x, y] = centre;
        self.line([x - size, y], [x + size, y], width, colour);
        self.line([x, y - size], [x, y + size], width, colour);
    }

    /// A `width × height` canvas of one colour.
    pub fn filled(width: usize, height: usize, colour: [u8; 3]) -> Canvas {
        Canvas {
            width,
            height,
            rgb: colour.repeat(width * height),
        }
    }

    /// Copies `other` onto this canvas with its top-left corner at (`x`, `y`), clipped.
    pub fn paste(&mut self, other: &Canvas, x: usize, y: usize) {
        let columns = other.width.min(self.width.saturating_sub(x));
        for row in 0..other.height.min(self.height.saturating_sub(y)) {
            let from = row * other.width * 3;
            let to = ((y + row) * self.width + x) * 3;
            self.rgb[to..to + columns * 3].copy_from_slice(&other.rgb[from..from + columns * 3]);
        }
    }

    /// Fills the rectangle from (`x`, `y`), `width × height` px, clipped.
    pub fn fill_rect(&mut self, x: i64, y: i64, width: usize, height: usize, colour: [u8; 3]) {
        for yy in y..y + height as i64 {
            for xx in x..x + width as i64 {
                self.blend(xx, yy, colour, 1.0);
            }
        }
    }

    /// By how much [`Canvas::preview`] reduces this canvas for `max_side` (1: not at all):
    /// each preview pixel averages `factor × factor` canvas pixels.
    pub fn reduction(&self, max_side: usize) -> usize {
        self.width.max(self.height).div_ceil(max_side.max(1)).max(1)
    }

    /// A box-filtered copy at most `max_side` px along its longer side, or `None` when
    /// this canvas is already that small.
    pub fn preview(&self, max_side: usize) -> Option<Canvas> {
        let factor = self.reduction(max_side);
        if factor <= 1 {
            return None;
        }
        let (width, height) = (self.width / factor, self.height / factor);
        let mut rgb = vec![0u8; width * height * 3];
        let n = (factor * factor) as u32;
        for y in 0..height {
            for x in 0..width {
                let mut sum = [0u32; 3];
                for dy in 0..factor {
                    let row = (y * factor + dy) * self.width;
                    for dx in 0..factor {
                        let i = (row + x * factor + dx) * 3;
                        for (s, &v) in sum.iter_mut().zip(&self.rgb[i..i + 3]) {
                            *s += v as u32;
                        }
                    }
                }
                let i = (y * width + x) * 3;
                for (out, s) in rgb[i..i + 3].iter_mut().zip(sum) {
                    *out = ((s + n / 2) / n) as u8;
                }
            }
        }
        Some(Canvas { width, height, rgb })
    }

    /// PNG bytes (fast compression: these are pictures to look at, written on every run).
    pub fn png(&self) -> Vec<u8> {
        if self.width == 0 || self.height == 0 {
            // An empty picture (e.g. a crop of nothing) is a 1 × 1 white PNG, not a panic.
            return Canvas {
                width: 1,
                height: 1,
                rgb: vec![255; 3],
            }
            .png();
        }
        let mut out = Vec::new();
        {
            let mut encoder = png::Encoder::new(&mut out, self.width as u32, self.height as u32);
            encoder.set_color(png::ColorType::Rgb);
            encoder.set_depth(png::BitDepth::Eight);
            encoder.set_compression(png::Compression::Fast);
            let mut writer = encoder.write_header().expect("PNG header to memory");
            writer
                .write_image_data(&self.rgb)
                .expect("PNG data to memory");
        }
        out
    }
}

/// A picture encoded for a page: its bytes and their MIME type.
pub struct EncodedPicture {
    /// The encoded bytes.
    pub bytes: Vec<u8>,
    /// `image/png` or `image/jpeg`.
    pub mime: &'static str,
}

/// PNG bytes of a continuous-tone preview above which JPEG is tried: noisy atomic images
/// barely compress losslessly (about 3 bytes a pixel).
const PHOTO_PNG_BYTES: usize = 96 * 1024;

/// JPEG quality of previews (90: no visible blocks on colour-mapped images).
const PREVIEW_JPEG_QUALITY: u8 = 90;

impl Canvas {
    /// The canvas for a page: PNG, or JPEG when the PNG is large (continuous tone) and the
    /// JPEG under 70 % of its size. The full-resolution files stay PNG.
    pub fn for_page(&self) -> EncodedPicture {
        let png = self.png();
        let jpeg = (png.len() > PHOTO_PNG_BYTES)
            .then(|| self.jpeg(PREVIEW_JPEG_QUALITY))
            .flatten()
            .filter(|jpeg| 10 * jpeg.len() < 7 * png.len());
        match jpeg {
            Some(bytes) => EncodedPicture {
                bytes,
                mime: "image/jpeg",
            },
            None => EncodedPicture {
                bytes: png,
                mime: "image/png",
            },
        }
    }

    /// JPEG bytes at `quality` (1–100), or `None` for a canvas JPEG cannot hold (a side
    /// beyond 65,535 px).
    fn jpeg(&self, quality: u8) -> Option<Vec<u8>> {
        let width = u16::try_from(self.width).ok()?;
        let height = u16::try_from(self.height).ok()?;
        let mut out = Vec::new();
        jpeg_encoder::Encoder::new(&mut out, quality)
            .encode(&self.rgb, width, height, jpeg_encoder::ColorType::Rgb)
            .ok()?;
        Some(out)
    }
}

/// Integer upscale so the longest side is at least `target` picture pixels (max 16×).
pub fn upscale_for(rows: usize, columns: usize, target: usize) -> usize {
    let longest = rows.max(columns).max(1);
    target.div_ceil(longest).clamp(1, 16)
}

/// The sequential (inferno: black → yellow) colour of `t` in `[0, 1]` used for magnitudes
/// such as deviations and residuals.
pub fn heat_colour(t: f64) -> [u8; 3] {
    Colormap::Inferno.rgb(t.clamp(0.0, 1.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn draws_inside_and_clips_outside() {
        let image = Array2::<f64>::zeros((10, 10));
        let mut canvas = Canvas::from_image(image.view(), Colormap::Greys, Some((0.0, 1.0)), 2);
        assert_eq!((canvas.width, canvas.height), (20, 20));
        canvas.line([-50.0, 10.0], [50.0, 10.0], 2.0, [255, 0, 0]);
        canvas.disc([100.0, 100.0], 3.0, [0, 255, 0]); // entirely outside: no panic
        canvas.line([f64::NAN, 0.0], [1.0, 1.0], 1.0, [0, 0, 255]);
        let png = canvas.png();
        assert_eq!(&png[1..4], b"PNG");
        // Row 10 (the line) is red, row 2 is untouched black.
        let at = |x: usize, y: usize| &canvas.rgb[(y * 20 + x) * 3..(y * 20 + x) * 3 + 3];
        assert_eq!(at(5, 10), &[255, 0, 0]);
        assert_eq!(at(5, 2), &[0, 0, 0]);
    }

    #[test]
    fn display_range_ignores_spikes_and_nan() {
        let mut image = Array2::from_shape_fn((100, 100), |(r, _)| r as f64);
        image[[0, 0]] = 1e9;
        image[[1, 1]] = f64::NAN;
        let (low, high) = display_range(image.view()).unwrap();
        assert!(low >= 0.0 && high < 100.0);
        assert!(display_range(Array2::from_elem((2, 2), f64::NAN).view()).is_none());
    }
}
