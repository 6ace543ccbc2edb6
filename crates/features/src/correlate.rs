//! 2-D cross-correlation by FFT (realfft along rows, rustfft along columns).

use std::sync::Arc;

use ndarray::{Array2, ArrayView2};
use rayon::prelude::*;
use realfft::{ComplexToReal, RealFftPlanner, RealToComplex};
use rustfft::num_complex::Complex;
use rustfft::num_traits::Float;
use rustfft::{Fft, FftNum, FftPlanner};

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
    Correlator::<f64>::new(height, width, kernel).correlate(image)
}

/// Correlation of `height x width` images with one kernel, by FFT: the FFT plans and the
/// kernel's spectrum are computed once and reused for every image (e.g. trace and retrace).
///
/// Inputs and outputs are f64; the transforms run in `T` (f64 for exact results, f32 for
/// half the memory traffic where ~1e-6 relative precision is enough).
pub struct Correlator<T: FftNum> {
    height: usize,
    width: usize,
    kernel_radius: (usize, usize),
    /// Padded FFT size along rows (ph) and columns (pw); no wrap-around for the kernel.
    padded: (usize, usize),
    row_forward: Arc<dyn RealToComplex<T>>,
    row_inverse: Arc<dyn ComplexToReal<T>>,
    column_forward: Arc<dyn Fft<T>>,
    column_inverse: Arc<dyn Fft<T>>,
    /// Conjugated kernel spectrum divided by ph·pw, column-major (`pw/2+1` columns of `ph`).
    kernel_spectrum: Vec<Complex<T>>,
}

impl<T: FftNum + Float> Correlator<T> {
    /// Plans correlation of `height x width` images with `kernel`.
    pub fn new(height: usize, width: usize, kernel: ArrayView2<f64>) -> Correlator<T> {
        let (kh, kw) = kernel.dim();
        let ph = fast_fft_size(height + kh - 1);
        let pw = fast_fft_size(width + kw - 1);
        let mut real_planner = RealFftPlanner::<T>::new();
        let mut planner = FftPlanner::<T>::new();
        let mut correlator = Correlator {
            height,
            width,
            kernel_radius: (kh / 2, kw / 2),
            padded: (ph, pw),
            row_forward: real_planner.plan_fft_forward(pw),
            row_inverse: real_planner.plan_fft_inverse(pw),
            column_forward: planner.plan_fft_forward(ph),
            column_inverse: planner.plan_fft_inverse(ph),
            kernel_spectrum: Vec::new(),
        };
        let scale = T::from_f64(1.0 / (ph * pw) as f64).unwrap_or_else(T::zero);
        let mut spectrum = correlator.forward(kernel);
        spectrum.par_iter_mut().for_each(|k| *k = k.conj() * scale);
        correlator.kernel_spectrum = spectrum;
        correlator
    }

    /// Image size this correlator was planned for, `(height, width)`.
    pub fn image_size(&self) -> (usize, usize) {
        (self.height, self.width)
    }

    /// 2-D spectrum of a zero-padded real array (rows first, then columns), column-major.
    fn forward(&self, source: ArrayView2<f64>) -> Vec<Complex<T>> {
        forward_spectrum(
            source,
            self.padded,
            self.row_forward.as_ref(),
            self.column_forward.as_ref(),
        )
    }

    /// Correlates an image of the planned size with the kernel.
    ///
    /// # Panics
    /// If the image size differs from the planned one (a programming error).
    pub fn correlate(&self, image: ArrayView2<f64>) -> Array2<f64> {
        assert_eq!(
            image.dim(),
            (self.height, self.width),
            "image size differs from the plan"
        );
        let (ph, pw) = self.padded;
        let (kr, kc) = self.kernel_radius;
        let spectrum_width = pw / 2 + 1;
        let mut product = self.forward(image);
        product
            .par_chunks_mut(ph)
            .zip(self.kernel_spectrum.par_chunks(ph))
            .for_each(|(column, kernel)| {
                for (p, k) in column.iter_mut().zip(kernel) {
                    *p = *p * *k;
                }
                self.column_inverse.process(column);
            });
        // Inverse row transforms; pick the lags (r − kr, c − kc), wrapping negatives.
        let mut values = vec![0.0; self.height * self.width];
        values.par_chunks_mut(self.width).enumerate().for_each_init(
            || {
                (
                    self.row_inverse.make_input_vec(),
                    self.row_inverse.make_output_vec(),
                )
            },
            |(input, output), (r, row)| {
                let lag_row = (r + ph - kr) % ph;
                for (k, value) in input.iter_mut().enumerate() {
                    *value = product[k * ph + lag_row];
                }
                // The DC and Nyquist bins of a real signal's spectrum are real.
                input[0].im = T::zero();
                if pw.is_multiple_of(2) {
                    input[spectrum_width - 1].im = T::zero();
                }
                self.row_inverse
                    .process(input, output)
                    .expect("buffer sizes come from the plan");
                for (c, value) in row.iter_mut().enumerate() {
                    *value = output[(c + pw - kc) % pw].to_f64().unwrap_or(f64::NAN);
                }
            },
        );
        Array2::from_shape_vec((self.height, self.width), values)
            .expect("the buffer has height x width values")
    }
}

/// 2-D spectrum of `source` zero-padded to `padded = (ph, pw)`: real FFT along rows, complex
/// FFT along columns; column-major (`pw/2+1` columns of `ph` values).
fn forward_spectrum<T: FftNum + Float>(
    source: ArrayView2<f64>,
    padded: (usize, usize),
    row_forward: &dyn RealToComplex<T>,
    column_forward: &dyn Fft<T>,
) -> Vec<Complex<T>> {
    let (ph, pw) = padded;
    let spectrum_width = pw / 2 + 1;
    let (rows, cols) = source.dim();
    // Row spectra, row-major, then transposed so column transforms are contiguous.
    let mut row_major = vec![Complex::new(T::zero(), T::zero()); rows * spectrum_width];
    row_major
        .par_chunks_mut(spectrum_width)
        .enumerate()
        .for_each_init(
            || row_forward.make_input_vec(),
            |input, (r, output)| {
                input.iter_mut().for_each(|v| *v = T::zero());
                for (c, value) in input.iter_mut().enumerate().take(cols) {
                    *value = T::from_f64(source[[r, c]]).unwrap_or_else(T::nan);
                }
                row_forward
                    .process(input, output)
                    .expect("buffer sizes come from the plan");
            },
        );
    let mut column_major = vec![Complex::new(T::zero(), T::zero()); ph * spectrum_width];
    column_major
        .par_chunks_mut(ph)
        .enumerate()
        .for_each(|(k, column)| {
            for r in 0..rows {
                column[r] = row_major[r * spectrum_width + k];
            }
            column_forward.process(column);
        });
    column_major
}

/// The 2-D spectrum of a real image (no padding beyond fast FFT sizes): `F(ky, kx)` for
/// `kx` in `0..=columns/2` and `ky` in `0..rows` (negative `ky` wrap to `rows + ky`).
#[derive(Debug, Clone)]
pub struct RealSpectrum {
    /// FFT size along the rows of the image (y, number of `ky` bins).
    pub rows: usize,
    /// FFT size along the columns of the image (x); `columns/2 + 1` `kx` bins are kept.
    pub columns: usize,
    /// Column-major values: `values[kx * rows + ky]`.
    pub values: Vec<Complex<f64>>,
}

impl RealSpectrum {
    /// The spectrum of `image` zero-padded to `(rows, columns)` (each at least the image's).
    pub fn of(image: ArrayView2<f64>, rows: usize, columns: usize) -> RealSpectrum {
        let (h, w) = image.dim();
        let (rows, columns) = (rows.max(h), columns.max(w));
        let row_forward = RealFftPlanner::<f64>::new().plan_fft_forward(columns);
        let column_forward = FftPlanner::<f64>::new().plan_fft_forward(rows);
        let values = forward_spectrum(
            image,
            (rows, columns),
            row_forward.as_ref(),
            column_forward.as_ref(),
        );
        RealSpectrum {
            rows,
            columns,
            values,
        }
    }

    /// The fast FFT size (prime factors ≤ 7) of at least `minimum` samples.
    pub fn fast_size(minimum: usize) -> usize {
        fast_fft_size(minimum)
    }

    /// `F` at `kx` in `0..=columns/2`, `ky` in `0..rows`.
    pub fn at(&self, kx: usize, ky: usize) -> Complex<f64> {
        self.values[kx * self.rows + ky]
    }
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
