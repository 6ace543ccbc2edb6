//! A separable Gaussian blur of an image, the kernel renormalised at the edges.

use ndarray::Array2;

/// `z` blurred by a Gaussian of `sigma_px` pixels along both axes (kernel cut at 3σ and
/// renormalised to the pixels inside the image at the edges). `sigma_px` must be positive.
pub fn gaussian_blur(z: &Array2<f64>, sigma_px: f64) -> Array2<f64> {
    let radius = (3.0 * sigma_px).ceil() as isize;
    let kernel: Vec<f64> = (-radius..=radius)
        .map(|d| (-0.5 * (d as f64 / sigma_px).powi(2)).exp())
        .collect();
    let pass = |z: &Array2<f64>, along_rows: bool| {
        let (rows, columns) = z.dim();
        Array2::from_shape_fn((rows, columns), |(r, c)| {
            let (mut sum, mut weight) = (0.0, 0.0);
            for (k, w) in kernel.iter().enumerate() {
                let offset = k as isize - radius;
                let (rr, cc) = if along_rows {
                    (r as isize, c as isize + offset)
                } else {
                    (r as isize + offset, c as isize)
                };
                if rr >= 0 && cc >= 0 && (rr as usize) < rows && (cc as usize) < columns {
                    sum += w * z[[rr as usize, cc as usize]];
                    weight += w;
                }
            }
            sum / weight
        })
    };
    pass(&pass(z, true), false)
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
}
