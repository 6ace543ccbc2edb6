//! Normalised cross-correlation of an image with a kernel.

use ndarray::{Array2, ArrayView2};
use rayon::prelude::*;

use crate::Kernel;
use crate::correlate::Correlator;

/// Normalised cross-correlation, same size as `image`, values in [−1, 1]:
/// `Σ t′·I′ / √(Σ t′² · Σ I′²)` over the kernel-sized window centred on each pixel, with
/// `t′`, `I′` the template and window minus their means, and a flat window gives 0.
/// Outside the image, the image is padded with its mean (Matlab's `normxcorr2` pads with
/// zeros, which puts false edges at the borders of images with an offset).
///
/// Non-finite pixels must be replaced before calling. To correlate several images of one
/// size with one kernel, build an [`NccPlan`] once.
pub fn normalised_cross_correlation(image: ArrayView2<f64>, kernel: &Kernel) -> Array2<f64> {
    let (h, w) = image.dim();
    NccPlan::new(h, w, kernel).apply(image)
}

/// A planned normalised cross-correlation: FFT plans, the mean-free template and its
/// spectrum, for images of one size. A tall image is correlated in horizontal strips (each
/// with the kernel's half-height of neighbouring rows on either side), so the transforms
/// need memory for a strip, not for the image.
pub struct NccPlan {
    /// FFTs in f32: the NCC is used to threshold and segment, where ~1e-6 relative precision
    /// is ample, and single precision halves the memory traffic of the transforms.
    correlator: Correlator<f32>,
    /// Image size, `(rows, columns)`.
    size: (usize, usize),
    /// Output rows per strip (the last may be shorter).
    strip_rows: usize,
    /// Image rows above and below a strip in its buffer (0 when the image is one strip).
    margin: usize,
    template_energy: f64,
    template_len: f64,
    kernel_radius: (usize, usize),
}

/// Output rows per strip: eight kernel heights, at least 256 rows.
fn strip_rows_for(kernel_rows: usize) -> usize {
    (8 * kernel_rows).max(256)
}

impl NccPlan {
    /// Plans the NCC of `height x width` images with `kernel`, in strips of the automatic
    /// height (see [`NccPlan::with_strip_rows`]).
    pub fn new(height: usize, width: usize, kernel: &Kernel) -> NccPlan {
        NccPlan::with_strip_rows(height, width, kernel, 0)
    }

    /// Plans the NCC of `height x width` images with `kernel`, `strip_rows` output rows at
    /// a time (0 = automatic: eight kernel heights, at least 256; images up to twice that
    /// are one strip).
    pub fn with_strip_rows(
        height: usize,
        width: usize,
        kernel: &Kernel,
        strip_rows: usize,
    ) -> NccPlan {
        let template = kernel.values();
        let n = template.len() as f64;
        let mean_t = template.sum() / n;
        let centred = template.mapv(|v| v - mean_t);
        let (kr, kc) = kernel.radius();
        let strip_rows = match strip_rows {
            0 => {
                let strip = strip_rows_for(template.nrows());
                // Short images are one strip, exactly the image.
                if height <= 2 * strip { height } else { strip }
            }
            rows => rows.min(height),
        }
        .max(1);
        // A strip's buffer holds the kernel's half-height of rows above and below it.
        let margin = if strip_rows == height { 0 } else { kr };
        NccPlan {
            correlator: Correlator::new(strip_rows + 2 * margin, width, centred.view()),
            size: (height, width),
            strip_rows,
            margin,
            template_energy: centred.iter().map(|v| v * v).sum(),
            template_len: n,
            kernel_radius: (kr, kc),
        }
    }

    /// The image size this plan was made for, `(rows, columns)`.
    pub fn image_size(&self) -> (usize, usize) {
        self.size
    }

    /// The NCC map of `image` (its size must be the plan's). The image is standardised by
    /// its mean and spread first (neither changes the NCC; they keep single-precision FFTs
    /// accurate for any z offset), then correlated strip by strip.
    pub fn apply(&self, image: ArrayView2<f64>) -> Array2<f64> {
        assert_eq!(image.dim(), self.size, "image size differs from the plan");
        let (h, w) = self.size;
        let count = image.len() as f64;
        let mean = image.sum() / count;
        let spread = (image.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / count).sqrt();
        let scale = if spread > 0.0 { 1.0 / spread } else { 1.0 };
        let mut out = vec![0.0; h * w];
        if out.is_empty() {
            return Array2::zeros((h, w));
        }
        out.par_chunks_mut(self.strip_rows * w)
            .enumerate()
            .for_each(|(k, strip)| {
                let first = k * self.strip_rows;
                self.apply_strip(image, (mean, scale), first, strip);
            });
        Array2::from_shape_vec((h, w), out).expect("h x w values")
    }

    /// Writes the NCC of output rows `first..` (as many as `out` holds) of `image`.
    fn apply_strip(
        &self,
        image: ArrayView2<f64>,
        (mean, scale): (f64, f64),
        first: usize,
        out: &mut [f64],
    ) {
        let (h, w) = self.size;
        let (kr, kc) = self.kernel_radius;
        let (buffer_rows, _) = self.correlator.image_size();
        // Buffer row b holds image row first + b − offset (zero = the mean outside the image).
        let offset = self.margin;
        let mut standard = Array2::<f64>::zeros((buffer_rows, w));
        for (b, mut row) in standard.rows_mut().into_iter().enumerate() {
            let r = (first + b) as i64 - offset as i64;
            if r >= 0 && (r as usize) < h {
                row.zip_mut_with(&image.row(r as usize), |s, &v| *s = (v - mean) * scale);
            }
        }
        let numerator = self.correlator.correlate(standard.view());
        let (integral, integral_sq) = integral_images(&standard);
        let n = self.template_len;
        let floor = 1e-12 * n;
        let stride = w + 1;
        for (r, row) in out.chunks_mut(w).enumerate() {
            let b = r + offset;
            let (top, bottom) = (
                b.saturating_sub(kr) * stride,
                (b + kr + 1).min(buffer_rows) * stride,
            );
            for (c, value) in row.iter_mut().enumerate() {
                let (left, right) = (c.saturating_sub(kc), (c + kc + 1).min(w));
                let boxed = |t: &[f64]| {
                    t[bottom + right] - t[top + right] - t[bottom + left] + t[top + left]
                };
                let sum = boxed(&integral);
                let variance_sum = boxed(&integral_sq) - sum * sum / n;
                *value = if variance_sum > floor {
                    (numerator[[b, c]] / (self.template_energy * variance_sum).sqrt())
                        .clamp(-1.0, 1.0)
                } else {
                    0.0
                };
            }
        }
    }
}

/// Summed-area tables of `image` and of its square, `(rows + 1) × (columns + 1)`, row-major.
fn integral_images(image: &Array2<f64>) -> (Vec<f64>, Vec<f64>) {
    let (h, w) = image.dim();
    let stride = w + 1;
    let mut integral = vec![0.0; (h + 1) * stride];
    let mut integral_sq = vec![0.0; (h + 1) * stride];
    for (r, row) in image.rows().into_iter().enumerate() {
        let (mut sum, mut sum_sq) = (0.0, 0.0);
        let (above, below) = (r * stride, (r + 1) * stride);
        for (c, &v) in row.iter().enumerate() {
            sum += v;
            sum_sq += v * v;
            integral[below + c + 1] = integral[above + c + 1] + sum;
            integral_sq[below + c + 1] = integral_sq[above + c + 1] + sum_sq;
        }
    }
    (integral, integral_sq)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The NCC by its definition at one pixel, the image padded with its mean.
    fn direct_ncc(image: &Array2<f64>, kernel: &Kernel, (r, c): (usize, usize)) -> f64 {
        let t = kernel.values();
        let (kr, kc) = kernel.radius();
        let mean = image.mean().unwrap();
        let n = t.len() as f64;
        let mean_t = t.sum() / n;
        let window: Vec<f64> = t
            .indexed_iter()
            .map(|((i, j), _)| {
                let (rr, cc) = (
                    r as i64 + i as i64 - kr as i64,
                    c as i64 + j as i64 - kc as i64,
                );
                image
                    .get((rr.max(-1) as usize, cc.max(-1) as usize))
                    .filter(|_| rr >= 0 && cc >= 0)
                    .copied()
                    .unwrap_or(mean)
            })
            .collect();
        let mean_w = window.iter().sum::<f64>() / n;
        let (mut num, mut tt, mut ww) = (0.0, 0.0, 0.0);
        for (w, tv) in window.iter().zip(t.iter()) {
            num += (w - mean_w) * (tv - mean_t);
            tt += (tv - mean_t).powi(2);
            ww += (w - mean_w).powi(2);
        }
        num / (tt * ww).sqrt()
    }

    #[test]
    fn a_tall_image_correlated_in_strips_matches_the_definition_at_the_seams() {
        let kernel = Kernel::gaussian(2.0).unwrap();
        let (h, w) = (700, 48);
        let image = Array2::from_shape_fn((h, w), |(r, c)| {
            let (x, y) = (c as f64, r as f64);
            2e-9 + 1e-10 * ((0.9 * x).sin() * (0.7 * y).cos() + 0.3 * (0.13 * x * y).sin())
        });
        let plan = NccPlan::new(h, w, &kernel);
        assert!(plan.strip_rows < h, "the image must be split");
        let ncc = plan.apply(image.view());
        let s = plan.strip_rows;
        for r in [0, 1, s - 1, s, s + 1, 2 * s - 1, 2 * s, h - 2, h - 1] {
            for c in [0, 5, w / 2, w - 1] {
                let expected = direct_ncc(&image, &kernel, (r, c));
                assert!(
                    (ncc[[r, c]] - expected).abs() < 2e-5,
                    "row {r} column {c}: {} vs {expected}",
                    ncc[[r, c]]
                );
            }
        }
    }

    #[test]
    fn a_copy_of_the_kernel_correlates_to_one_and_its_negative_to_minus_one() {
        let kernel = Kernel::gaussian(2.0).unwrap();
        let (kh, kw) = kernel.values().dim();
        let mut image = Array2::from_elem((40, 40), 3.0e-9);
        let mut dark = image.clone();
        for i in 0..kh {
            for j in 0..kw {
                image[[10 + i, 12 + j]] += 5e-11 * kernel.values()[[i, j]];
                dark[[10 + i, 12 + j]] -= 5e-11 * kernel.values()[[i, j]];
            }
        }
        let centre = (10 + kh / 2, 12 + kw / 2);
        let ncc = normalised_cross_correlation(image.view(), &kernel);
        // The transforms run in f32 (see NccPlan): exact up to single-precision rounding.
        assert!((ncc[[centre.0, centre.1]] - 1.0).abs() < 1e-5);
        assert!(ncc.iter().all(|v| (-1.0..=1.0).contains(v)));
        let ncc = normalised_cross_correlation(dark.view(), &kernel);
        assert!((ncc[[centre.0, centre.1]] + 1.0).abs() < 1e-5);
        // Flat windows inside the image give exactly 0.
        assert_eq!(ncc[[34, 30]], 0.0);
    }
}
