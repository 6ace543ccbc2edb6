//! A separable Gaussian blur of an image, the kernel renormalised at the edges.

use dhct_numerics::dot::dot;
use ndarray::{Array2, ArrayView2};

/// `z` blurred by a Gaussian of `sigma_px` pixels along both axes (kernel cut at 3σ and
/// renormalised to the pixels inside the image at the edges). `sigma_px` must be positive.
pub fn gaussian_blur(z: &Array2<f64>, sigma_px: f64) -> Array2<f64> {
    let kernel = gaussian_kernel(sigma_px);
    let along_rows = blur_lines(z.as_standard_layout().view(), &kernel);
    let both = blur_lines(along_rows.t().as_standard_layout().view(), &kernel);
    both.t().as_standard_layout().to_owned()
}

/// [`gaussian_blur`] of `z` read only at every `step`-th row and column (from the first):
/// the blurred image `.slice(s![..;step, ..;step])`, at about `1/step` of the cost (each
/// pass sums the kernel only where the next pass or the output reads). `step` ≥ 1.
pub fn gaussian_blur_sampled(z: &Array2<f64>, sigma_px: f64, step: usize) -> Array2<f64> {
    let step = step.max(1);
    if step == 1 {
        return gaussian_blur(z, sigma_px);
    }
    let kernel = gaussian_kernel(sigma_px);
    let along_rows = blur_lines_sampled(z.as_standard_layout().view(), &kernel, step);
    let both = blur_lines_sampled(along_rows.t().as_standard_layout().view(), &kernel, step);
    both.t().as_standard_layout().to_owned()
}

/// A Gaussian of `sigma_px` sampled at whole pixels out to 3σ (odd length, centred).
fn gaussian_kernel(sigma_px: f64) -> Vec<f64> {
    let radius = (3.0 * sigma_px).ceil() as usize;
    (0..=2 * radius)
        .map(|k| (-0.5 * ((k as f64 - radius as f64) / sigma_px).powi(2)).exp())
        .collect()
}

/// [`blur_lines`] read at every `step`-th column only: `(rows, ⌈columns/step⌉)`.
fn blur_lines_sampled(z: ArrayView2<f64>, kernel: &[f64], step: usize) -> Array2<f64> {
    let (rows, columns) = z.dim();
    let radius = kernel.len() / 2;
    // Per output column c: the input columns c − radius ..= c + radius inside the line, the
    // kernel's part over them and its sum (the same for every line).
    let reads: Vec<(std::ops::RangeInclusive<usize>, &[f64], f64)> = (0..columns)
        .step_by(step)
        .map(|c| {
            let (first, last) = (c.saturating_sub(radius), (c + radius).min(columns - 1));
            let weights = &kernel[first + radius - c..=last + radius - c];
            (first..=last, weights, weights.iter().sum())
        })
        .collect();
    let mut out = Array2::<f64>::zeros((rows, reads.len()));
    for (line, mut blurred) in z.rows().into_iter().zip(out.rows_mut()) {
        let Some(line) = line.as_slice() else {
            unreachable!("the input is in standard layout");
        };
        for (o, (inside, weights, sum)) in blurred.iter_mut().zip(&reads) {
            *o = dot(weights, &line[inside.clone()]) / sum;
        }
    }
    out
}

/// Each line (row) of `z` (standard layout) convolved with `kernel` (odd length, centred),
/// the kernel renormalised to the samples inside the line.
fn blur_lines(z: ArrayView2<f64>, kernel: &[f64]) -> Array2<f64> {
    let (rows, columns) = z.dim();
    let radius = kernel.len() / 2;
    // The kernel's weight inside the line, per column (the same for every line).
    let weight: Vec<f64> = (0..columns)
        .map(|c| {
            let first = radius.saturating_sub(c);
            let last = (radius + columns - 1 - c).min(kernel.len() - 1);
            kernel[first..=last].iter().sum()
        })
        .collect();
    let mut out = Array2::<f64>::zeros((rows, columns));
    for (line, mut blurred) in z.rows().into_iter().zip(out.rows_mut()) {
        let (Some(line), Some(blurred)) = (line.as_slice(), blurred.as_slice_mut()) else {
            unreachable!("both arrays are in standard layout");
        };
        for (k, &w) in kernel.iter().enumerate() {
            // Output column c reads input column c + k − radius.
            let from = radius.saturating_sub(k);
            let to = (columns + radius).saturating_sub(k).min(columns);
            if from >= to {
                continue;
            }
            let source = &line[from + k - radius..to + k - radius];
            for (o, &v) in blurred[from..to].iter_mut().zip(source) {
                *o += w * v;
            }
        }
        for (o, w) in blurred.iter_mut().zip(&weight) {
            *o /= w;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_constant_stays_and_a_spike_spreads_with_unit_sum() {
        let flat = Array2::from_elem((9, 11), 2.5);
        assert!(
            gaussian_blur(&flat, 1.5)
                .iter()
                .all(|v| (v - 2.5).abs() < 1e-12)
        );
        let mut spike = Array2::<f64>::zeros((41, 41));
        spike[[20, 20]] = 1.0;
        let blurred = gaussian_blur(&spike, 2.0);
        assert!((blurred.sum() - 1.0).abs() < 1e-9);
        assert!((blurred[[20, 22]] - blurred[[22, 20]]).abs() < 1e-15);
    }

    /// The direct sum over the kernel inside the image, renormalised: what the blur means.
    fn blurred_directly(z: &Array2<f64>, sigma_px: f64) -> Array2<f64> {
        let radius = (3.0 * sigma_px).ceil() as isize;
        let (rows, columns) = z.dim();
        Array2::from_shape_fn((rows, columns), |(r, c)| {
            let (mut sum, mut weight) = (0.0, 0.0);
            for i in -radius..=radius {
                for j in -radius..=radius {
                    let (rr, cc) = (r as isize + i, c as isize + j);
                    if rr >= 0 && cc >= 0 && (rr as usize) < rows && (cc as usize) < columns {
                        let w = (-0.5 * ((i * i + j * j) as f64) / sigma_px.powi(2)).exp();
                        sum += w * z[[rr as usize, cc as usize]];
                        weight += w;
                    }
                }
            }
            sum / weight
        })
    }

    /// Sampled, the blur is the full blur read at every step-th row and column, also
    /// where the kernel outgrows the image.
    #[test]
    fn the_sampled_blur_reads_the_full_blur_at_every_step() {
        let z = Array2::from_shape_fn((37, 29), |(r, c)| ((r * 5 + c * 3) % 7) as f64 - 2.0);
        for (sigma, step) in [(0.7, 2), (3.0, 3), (6.0, 5), (20.0, 4)] {
            let full = gaussian_blur(&z, sigma);
            let sampled = gaussian_blur_sampled(&z, sigma, step);
            let expected = full.slice(ndarray::s![..;step, ..;step]);
            assert_eq!(sampled.dim(), expected.dim());
            let worst = sampled
                .iter()
                .zip(expected.iter())
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            assert!(worst < 1e-12, "σ {sigma}, step {step}: {worst}");
        }
    }

    #[test]
    fn the_blur_is_the_renormalised_gaussian_sum_even_when_the_kernel_outgrows_the_image() {
        let z = Array2::from_shape_fn((13, 7), |(r, c)| ((r * 5 + c * 3) % 7) as f64 - 2.0);
        for sigma in [0.7, 2.0, 4.5] {
            let fast = gaussian_blur(&z, sigma);
            let direct = blurred_directly(&z, sigma);
            let worst = fast
                .iter()
                .zip(&direct)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            assert!(worst < 1e-12, "σ {sigma}: {worst}");
        }
        // A column-major input blurs alike.
        let reversed = z.t().to_owned().reversed_axes();
        assert!(
            (gaussian_blur(&reversed, 2.0) - gaussian_blur(&z, 2.0))
                .iter()
                .all(|d| d.abs() < 1e-12)
        );
    }
}
