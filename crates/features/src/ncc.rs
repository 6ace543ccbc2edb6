//! Normalised cross-correlation of an image with a kernel.

use ndarray::{Array2, ArrayView2};

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
/// spectrum, for images of one size.
pub struct NccPlan {
    /// FFTs in f32: the NCC is used to threshold and segment, where ~1e-6 relative precision
    /// is ample, and single precision halves the memory traffic of the transforms.
    correlator: Correlator<f32>,
    template_energy: f64,
    template_len: f64,
    kernel_radius: (usize, usize),
}

impl NccPlan {
    /// Plans the NCC of `height x width` images with `kernel`.
    pub fn new(height: usize, width: usize, kernel: &Kernel) -> NccPlan {
        let template = kernel.values();
        let n = template.len() as f64;
        let mean_t = template.sum() / n;
        let centred = template.mapv(|v| v - mean_t);
        NccPlan {
            correlator: Correlator::new(height, width, centred.view()),
            template_energy: centred.iter().map(|v| v * v).sum(),
            template_len: n,
            kernel_radius: kernel.radius(),
        }
    }

    /// Image size this plan was made for, `(height, width)`.
    pub fn image_size(&self) -> (usize, usize) {
        self.correlator.image_size()
    }

    /// The NCC of `image` (of the planned size); see [`normalised_cross_correlation`].
    pub fn apply(&self, image: ArrayView2<f64>) -> Array2<f64> {
        let (n, template_energy) = (self.template_len, self.template_energy);
        // Standardise the image so window sums of squares do not cancel catastrophically
        // (z in metres can carry a large offset); NCC is invariant to this affine change.
        let count = image.len() as f64;
        let mean = image.sum() / count;
        let spread = (image.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / count).sqrt();
        let scale = if spread > 0.0 { 1.0 / spread } else { 1.0 };
        let standard = image.mapv(|v| (v - mean) * scale);

        let numerator = self.correlator.correlate(standard.view());
        let (h, w) = image.dim();
        let (integral, integral_sq) = integral_images(&standard);
        let (kr, kc) = self.kernel_radius;
        let floor = 1e-12 * n;
        let stride = w + 1;
        let numerator = numerator.as_standard_layout();
        let numerator = numerator.as_slice().unwrap_or_default();
        let mut out = vec![0.0; h * w];
        for (r, row) in out.chunks_mut(w).enumerate() {
            // Window [r−kr, r+kr] x [c−kc, c+kc] clipped to the image (mean padding outside).
            let (top, bottom) = (r.saturating_sub(kr) * stride, (r + kr + 1).min(h) * stride);
            for (c, value) in row.iter_mut().enumerate() {
                let (left, right) = (c.saturating_sub(kc), (c + kc + 1).min(w));
                let boxed = |t: &[f64]| {
                    t[bottom + right] - t[top + right] - t[bottom + left] + t[top + left]
                };
                let sum = boxed(&integral);
                let variance_sum = boxed(&integral_sq) - sum * sum / n;
                if variance_sum > floor {
                    *value = (numerator[r * w + c] / (template_energy * variance_sum).sqrt())
                        .clamp(-1.0, 1.0);
                }
            }
        }
        Array2::from_shape_vec((h, w), out).expect("h x w values")
    }
}

/// Summed-area tables of the values and of their squares, `(h+1) x (w+1)`, row-major.
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
