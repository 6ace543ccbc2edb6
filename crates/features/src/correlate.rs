//! 2-D cross-correlation by FFT (realfft along rows, rustfft along columns).

use ndarray::{Array2, ArrayView2};
use rayon::prelude::*;
use realfft::RealFftPlanner;
use rustfft::FftPlanner;
use rustfft::num_complex::Complex64;

/// Smallest n ≥ `minimum` whose prime factors are all ≤ 7 (fast FFT sizes).
fn fast_fft_size(minimum: usize) -> usize {
    let mut n = minimum.max(1);
    loop {
        let mut m = n;
        for p in [2, 3, 5, 7] {
            while m.is_multiple_of(p) {
                m /= p;
            }
        }
        if m == 1 {
            return n;
        }
        n += 1;
    }
}

/// `out[r, c] = Σ_ij kernel[i, j] · image[r + i − kr, c + j − kc]`, with the kernel centred at
/// `(kr, kc) = (rows/2, cols/2)` and zero padding outside the image; same size as `image`.
pub fn correlate_same(image: ArrayView2<f64>, kernel: ArrayView2<f64>) -> Array2<f64> {
    let (height, width) = image.dim();
    let (kh, kw) = kernel.dim();
    let (kr, kc) = (kh / 2, kw / 2);
    let ph = fast_fft_size(height + kh - 1);
    let pw = fast_fft_size(width + kw - 1);
    let spectrum_width = pw / 2 + 1;

    let mut real_planner = RealFftPlanner::<f64>::new();
    let row_forward = real_planner.plan_fft_forward(pw);
    let row_inverse = real_planner.plan_fft_inverse(pw);
    let mut planner = FftPlanner::<f64>::new();
    let column_forward = planner.plan_fft_forward(ph);
    let column_inverse = planner.plan_fft_inverse(ph);

    // Forward transform of a (zero-padded) real array: rows first, then columns.
    let forward = |source: ArrayView2<f64>| -> Vec<Complex64> {
        let (rows, cols) = source.dim();
        // Row spectra, stored column-major (spectrum_width columns of length ph) so that the
        // column transforms work on contiguous memory.
        let mut row_spectra = vec![Complex64::default(); ph * spectrum_width];
        let mut computed: Vec<Vec<Complex64>> = (0..rows)
            .into_par_iter()
            .map_init(
                || (row_forward.make_input_vec(), row_forward.make_output_vec()),
                |(input, output), r| {
                    input.iter_mut().for_each(|v| *v = 0.0);
                    for c in 0..cols {
                        input[c] = source[[r, c]];
                    }
                    row_forward
                        .process(input, output)
                        .expect("buffer sizes come from the plan");
                    output.clone()
                },
            )
            .collect();
        for (r, spectrum) in computed.iter_mut().enumerate() {
            for (k, value) in spectrum.iter().enumerate() {
                row_spectra[k * ph + r] = *value;
            }
        }
        row_spectra
            .par_chunks_mut(ph)
            .for_each(|column| column_forward.process(column));
        row_spectra
    };

    let mut product = forward(image);
    let kernel_spectrum = forward(kernel);
    let scale = 1.0 / (ph * pw) as f64;
    product
        .par_iter_mut()
        .zip(kernel_spectrum.par_iter())
        .for_each(|(p, k)| *p = *p * k.conj() * scale);
    product
        .par_chunks_mut(ph)
        .for_each(|column| column_inverse.process(column));

    // Inverse row transforms; pick the lags (r − kr, c − kc), wrapping negatives.
    let rows: Vec<Vec<f64>> = (0..height)
        .into_par_iter()
        .map_init(
            || (row_inverse.make_input_vec(), row_inverse.make_output_vec()),
            |(input, output), r| {
                let lag_row = (r + ph - kr) % ph;
                for (k, value) in input.iter_mut().enumerate() {
                    *value = product[k * ph + lag_row];
                }
                // The DC and Nyquist bins of a real signal's spectrum are real.
                input[0].im = 0.0;
                if pw.is_multiple_of(2) {
                    input[spectrum_width - 1].im = 0.0;
                }
                row_inverse
                    .process(input, output)
                    .expect("buffer sizes come from the plan");
                (0..width).map(|c| output[(c + pw - kc) % pw]).collect()
            },
        )
        .collect();
    let mut out = Array2::zeros((height, width));
    for (r, row) in rows.into_iter().enumerate() {
        for (c, value) in row.into_iter().enumerate() {
            out[[r, c]] = value;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn direct(image: &Array2<f64>, kernel: &Array2<f64>) -> Array2<f64> {
        let (h, w) = image.dim();
        let (kh, kw) = kernel.dim();
        let mut out = Array2::zeros((h, w));
        for r in 0..h {
            for c in 0..w {
                let mut sum = 0.0;
                for i in 0..kh {
                    for j in 0..kw {
                        let (rr, cc) = (
                            r as i64 + i as i64 - (kh / 2) as i64,
                            c as i64 + j as i64 - (kw / 2) as i64,
                        );
                        if rr >= 0 && cc >= 0 && (rr as usize) < h && (cc as usize) < w {
                            sum += kernel[[i, j]] * image[[rr as usize, cc as usize]];
                        }
                    }
                }
                out[[r, c]] = sum;
            }
        }
        out
    }

    #[test]
    fn fft_correlation_equals_the_direct_sum() {
        for (h, w, kh, kw) in [(17, 23, 5, 7), (32, 32, 9, 9), (8, 40, 3, 11), (1, 9, 1, 3)] {
            let image = Array2::from_shape_fn((h, w), |(r, c)| {
                ((r * 31 + c * 17) % 13) as f64 - 6.0 + 0.1 * r as f64
            });
            let kernel =
                Array2::from_shape_fn((kh, kw), |(i, j)| (i as f64 + 1.0) * 0.3 - (j as f64) * 0.2);
            let fast = correlate_same(image.view(), kernel.view());
            let slow = direct(&image, &kernel);
            let worst = (&fast - &slow).iter().fold(0.0f64, |m, v| m.max(v.abs()));
            assert!(worst < 1e-9, "{h}x{w} kernel {kh}x{kw}: {worst}");
        }
    }

    #[test]
    fn fast_sizes_have_small_factors() {
        assert_eq!(fast_fft_size(2068), 2100);
        assert_eq!(fast_fft_size(1), 1);
        assert_eq!(fast_fft_size(11), 12);
    }
}
