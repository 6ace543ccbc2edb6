//! The image's power spectrum and its peaks.
//!
//! The image is levelled by a plane, clipped at ±6 robust σ so that spikes and defects do
//! not spread over the spectrum, windowed (Hann) and transformed. Scan lines are *not*
//! levelled: a per-line median removes the lattice's own rows where they run along the fast
//! axis and puts a false peak at half their frequency. Line offsets only raise the columns
//! `kx = 0, ±1, ±2` (the window's main lobe), so peaks there are judged against those columns'
//! own median. Frequencies are in *bins*: `kx` cycles across the padded width, `ky`
//! cycles across the padded height (signed, the half plane `kx > 0 or (kx = 0, ky > 0)`).

use dhct_features::{RealSpectrum, subtract_polynomial};
use dhct_scan::Axis;
use ndarray::{Array2, ArrayView2};
use rayon::prelude::*;

/// Why an image has no usable spectrum (the calibration reports it as its own error).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SpectrumError {
    /// Fewer than 16 pixels along an axis.
    #[error("{columns} × {rows} pixels is too small for a spectrum")]
    ImageTooSmall {
        /// Image columns, pixels.
        columns: usize,
        /// Image rows, pixels.
        rows: usize,
    },
    /// No pixel can be used, or the image cannot be levelled: why, in words.
    #[error("{0}")]
    Unusable(String),
}

/// Peaks closer to the origin than this (bins) are ignored: a period of more than a
/// third of the image is no lattice.
pub const MIN_RADIUS_BINS: f64 = 3.0;

/// A peak must exceed the median power at its radius by this factor.
pub const MIN_PEAK_SNR: f64 = 12.0;

/// Scan-line offsets (and stripes along the fast axis) put their power at `kx = 0` (for
/// horizontal lines), spread by the window over `|kx| ≤ 1`: nothing there is taken for a
/// peak (a lattice's rows exactly along the fast axis look the same as line offsets).
pub const EXCLUDED_ACROSS: u64 = 1;

/// At the edge of that band (`|kx| = 2`) a peak must stand out this much.
pub const LINE_BAND_SNR: f64 = 50.0;

/// At most this many peaks (the strongest) are kept.
pub const MAX_PEAKS: usize = 48;

/// A peak weaker than this fraction of the strongest is ignored, however far it stands out
/// of the background: in a large image (many pixels, so a low background) the window's
/// leakage from a reflection along the scan lines and faint modulations of the corrected
/// image (10⁻⁷ of the strongest peak in an 8192² image) would otherwise be taken for the
/// reflections of a larger cell. A real superstructure a tenth as strong in amplitude
/// has 10⁻² of the power.
pub const MIN_RELATIVE_POWER: f64 = 1e-5;

/// A local maximum of the power spectrum.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Peak {
    /// Sub-bin position `[kx, ky]`, bins (half plane).
    pub k: [f64; 2],
    /// Power at the peak's bin.
    pub power: f64,
    /// Power over the median power at the same radius.
    pub snr: f64,
    /// Its position could not be refined to a fraction of a bin across the scan lines (its
    /// neighbour there lies in the scan-line band): it is uncertain by half a bin.
    pub unrefined: bool,
}

#[cfg(test)]
impl Peak {
    /// A refined peak at `[kx, ky]` (bins) of `power` and SNR 100, for tests.
    pub(crate) fn at(kx: f64, ky: f64, power: f64) -> Peak {
        Peak {
            k: [kx, ky],
            power,
            snr: 100.0,
            unrefined: false,
        }
    }
}

/// The power spectrum `|F|²` of a levelled, windowed image.
#[derive(Debug, Clone)]
pub struct PowerSpectrum {
    /// `power[[ky_index, kx]]`, `kx` in `0..=columns/2`, `ky_index` in `0..rows`.
    power: Array2<f64>,
    /// Padded FFT size along y (rows).
    pub rows: usize,
    /// Padded FFT size along x (columns).
    pub columns: usize,
    /// Median power per integer radius (bins).
    background: Vec<f64>,
    /// The fast scan axis: line offsets are constant along it.
    fast_axis: Axis,
    /// Median power of the frequencies 0, 1 and 2 across the scan lines (`kx` for
    /// horizontal lines), where scan-line offsets live (the Hann window's main lobe is ±2
    /// bins wide).
    line_bands: [f64; 3],
}

impl PowerSpectrum {
    /// The spectrum of `z` (rows × columns, any finite values; non-finite pixels and
    /// pixels outside `mask` are left out) whose fast scan axis is `fast_axis`.
    pub fn of(
        z: ArrayView2<f64>,
        mask: Option<&Array2<bool>>,
        fast_axis: Axis,
    ) -> Result<PowerSpectrum, SpectrumError> {
        let (rows, columns) = z.dim();
        if rows < 16 || columns < 16 {
            return Err(SpectrumError::ImageTooSmall { columns, rows });
        }
        let prepared = prepare(z, mask)?;
        let spectrum = RealSpectrum::of(
            prepared.view(),
            RealSpectrum::fast_size(rows),
            RealSpectrum::fast_size(columns),
        );
        let width = spectrum.columns / 2 + 1;
        let power = Array2::from_shape_fn((spectrum.rows, width), |(ky, kx)| {
            spectrum.at(kx, ky).norm_sqr()
        });
        let mut result = PowerSpectrum {
            power,
            rows: spectrum.rows,
            columns: spectrum.columns,
            background: Vec::new(),
            fast_axis,
            line_bands: [0.0; 3],
        };
        result.background = result.radial_median();
        result.line_bands = [0usize, 1, 2].map(|k| {
            median(match fast_axis {
                Axis::Horizontal => result.power.column(k).to_vec(),
                Axis::Vertical => {
                    let rows = result.rows;
                    let mut band = result.power.row(k).to_vec();
                    if k > 0 {
                        band.extend(result.power.row(rows - k).iter());
                    }
                    band
                }
            })
        });
        Ok(result)
    }

    /// Power at integer frequency `(kx, ky)` (any sign; 0 outside the spectrum).
    pub fn at(&self, kx: i64, ky: i64) -> f64 {
        let (kx, ky) = if kx < 0 { (-kx, -ky) } else { (kx, ky) };
        if kx as usize > self.columns / 2 || ky.unsigned_abs() as usize > self.rows / 2 {
            return 0.0;
        }
        let row = ky.rem_euclid(self.rows as i64) as usize;
        self.power[[row, kx as usize]]
    }

    /// The background at frequency `k` (bins): the median power at its radius, or that of
    /// its band where scan-line offsets raise it (`|kx| ≤ 2` for horizontal lines).
    pub fn background_at(&self, k: [f64; 2]) -> f64 {
        if self.background.is_empty() {
            return 0.0;
        }
        let r = k[0].hypot(k[1]);
        let i = (r.round() as usize).min(self.background.len() - 1);
        let across = match self.fast_axis {
            Axis::Horizontal => k[0],
            Axis::Vertical => k[1],
        };
        match self.line_bands.get(across.abs().round() as usize) {
            Some(&line) => self.background[i].max(line),
            None => self.background[i],
        }
    }

    /// The power summed over the 5 × 5 bins around `k` (bins), robust to a peak smeared
    /// by a non-uniform distortion, and the background summed over the same bins.
    pub fn power_near(&self, k: [f64; 2]) -> (f64, f64) {
        let (cx, cy) = (k[0].round() as i64, k[1].round() as i64);
        let mut sum = 0.0f64;
        for dy in -2..=2 {
            for dx in -2..=2 {
                sum += self.at(cx + dx, cy + dy);
            }
        }
        (sum, 25.0 * self.background_at(k))
    }

    /// The largest power in the 3 × 3 bins around `k` (bins) over the background there: how
    /// clearly the spectrum shows something at a predicted reflection, whether or not it
    /// was detected as a peak.
    pub fn contrast_near(&self, k: [f64; 2]) -> f64 {
        let (cx, cy) = (k[0].round() as i64, k[1].round() as i64);
        let mut top = 0.0f64;
        for dy in -1..=1 {
            for dx in -1..=1 {
                top = top.max(self.at(cx + dx, cy + dy));
            }
        }
        top / self.background_at(k).max(f64::MIN_POSITIVE)
    }

    fn radial_median(&self) -> Vec<f64> {
        let max_r = self.rows.min(self.columns) / 2;
        let mut bins: Vec<Vec<f64>> = vec![Vec::new(); max_r + 1];
        // Every other bin along ky is plenty for a median and halves the work.
        for (row, line) in self.power.outer_iter().enumerate().step_by(2) {
            let ky = signed(row, self.rows) as f64;
            for (kx, &p) in line.iter().enumerate() {
                let r = (kx as f64).hypot(ky).round() as usize;
                if r <= max_r {
                    bins[r].push(p);
                }
            }
        }
        bins.into_iter().map(median).collect()
    }

    /// The strongest local maxima (5 × 5 neighbourhood) that stand out of the background,
    /// strongest first, refined to sub-bin positions.
    pub fn peaks(&self) -> Vec<Peak> {
        let half_x = (self.columns / 2) as i64;
        let half_y = (self.rows / 2) as i64;
        let mut peaks = Vec::new();
        for kx in 0..=half_x {
            for ky in -half_y + 1..half_y {
                if kx == 0 && ky <= 0 {
                    continue;
                }
                let r = (kx as f64).hypot(ky as f64);
                if r < MIN_RADIUS_BINS {
                    continue;
                }
                let across = self.across_lines(kx, ky);
                if across <= EXCLUDED_ACROSS {
                    continue;
                }
                let p = self.at(kx, ky);
                let background = self.background_at([kx as f64, ky as f64]);
                let threshold = if across <= 2 {
                    LINE_BAND_SNR
                } else {
                    MIN_PEAK_SNR
                };
                if p.is_nan() || p <= threshold * background || !self.is_local_max(kx, ky, p) {
                    continue;
                }
                let unrefined = across <= EXCLUDED_ACROSS + 1;
                peaks.push(Peak {
                    k: self.refine(kx, ky),
                    unrefined,
                    power: p,
                    snr: if background > 0.0 {
                        p / background
                    } else {
                        f64::INFINITY
                    },
                });
            }
        }
        peaks.sort_by(|a, b| b.power.total_cmp(&a.power));
        let strongest = peaks.first().map_or(0.0, |p| p.power);
        peaks.retain(|p| p.power >= MIN_RELATIVE_POWER * strongest);
        peaks.truncate(MAX_PEAKS);
        peaks
    }

    /// `|frequency|` across the scan lines (`|kx|` for horizontal lines), bins.
    fn across_lines(&self, kx: i64, ky: i64) -> u64 {
        match self.fast_axis {
            Axis::Horizontal => kx.unsigned_abs(),
            Axis::Vertical => ky.unsigned_abs(),
        }
    }

    fn is_local_max(&self, kx: i64, ky: i64, p: f64) -> bool {
        for dy in -2..=2i64 {
            for dx in -2..=2i64 {
                if dx == 0 && dy == 0 {
                    continue;
                }
                if self.across_lines(kx + dx, ky + dy) <= EXCLUDED_ACROSS {
                    continue;
                }
                let q = self.at(kx + dx, ky + dy);
                // Ties go to the first in scan order (kx, then ky ascending).
                if q > p || (q == p && (dx, dy) < (0, 0)) {
                    return false;
                }
            }
        }
        true
    }

    /// Sub-bin position along each axis from the three amplitudes around the peak (the
    /// estimator exact for a sinusoid under a Hann window: `δ = 2(A₊ − A₋)/(A₋ + 2A₀ + A₊)`;
    /// the log-parabola of a Gaussian peak is off by up to 0.016 bin there).
    fn refine(&self, kx: i64, ky: i64) -> [f64; 2] {
        let offset = |minus: f64, centre: f64, plus: f64| {
            let (a, b, c) = (
                minus.max(0.0).sqrt(),
                centre.max(0.0).sqrt(),
                plus.max(0.0).sqrt(),
            );
            let denominator = a + 2.0 * b + c;
            if denominator <= 0.0 || !denominator.is_finite() {
                return 0.0;
            }
            (2.0 * (c - a) / denominator).clamp(-0.5, 0.5)
        };
        let p = self.at(kx, ky);
        let usable = |x: i64, y: i64| self.across_lines(x, y) > EXCLUDED_ACROSS;
        let along = |x0: i64, y0: i64, x1: i64, y1: i64| {
            if usable(x0, y0) && usable(x1, y1) {
                offset(self.at(x0, y0), p, self.at(x1, y1))
            } else {
                0.0
            }
        };
        let dx = along(kx - 1, ky, kx + 1, ky);
        let dy = along(kx, ky - 1, kx, ky + 1);
        [kx as f64 + dx, ky as f64 + dy]
    }
}

/// `index` of an FFT of length `n` as a signed frequency.
fn signed(index: usize, n: usize) -> i64 {
    if index <= n / 2 {
        index as i64
    } else {
        index as i64 - n as i64
    }
}

/// The median (0 for no values), the shared convention of [`dhct_numerics::robust`].
fn median(mut values: Vec<f64>) -> f64 {
    dhct_numerics::robust::median(&mut values).unwrap_or(0.0)
}

/// Levels, clips and windows `z`; pixels left out become 0.
fn prepare(z: ArrayView2<f64>, mask: Option<&Array2<bool>>) -> Result<Array2<f64>, SpectrumError> {
    let (rows, columns) = z.dim();
    let use_pixel = |r: usize, c: usize| z[[r, c]].is_finite() && mask.is_none_or(|m| m[[r, c]]);
    let levelled = Array2::from_shape_fn((rows, columns), |(r, c)| {
        if use_pixel(r, c) { z[[r, c]] } else { f64::NAN }
    });
    if !levelled.iter().any(|v| v.is_finite()) {
        return Err(SpectrumError::Unusable(
            "no finite pixel is inside the mask".into(),
        ));
    }
    let levelled = subtract_polynomial(&levelled, 1, None)
        .map_err(|e| SpectrumError::Unusable(format!("the image could not be levelled: {e}")))?;
    let limit = 6.0 * robust_sigma(&levelled);
    let hann = |n: usize| -> Vec<f64> {
        (0..n)
            .map(|i| 0.5 - 0.5 * (2.0 * std::f64::consts::PI * (i as f64 + 0.5) / n as f64).cos())
            .collect()
    };
    let (window_rows, window_columns) = (hann(rows), hann(columns));
    let mut levelled = levelled.as_standard_layout().into_owned();
    levelled
        .as_slice_mut()
        .expect("standard layout is contiguous")
        .par_chunks_mut(columns)
        .zip(window_rows.par_iter())
        .for_each(|(line, wr)| {
            for (v, wc) in line.iter_mut().zip(&window_columns) {
                *v = if v.is_finite() {
                    v.clamp(-limit, limit) * wr * wc
                } else {
                    0.0
                };
            }
        });
    Ok(levelled)
}

/// 1.4826 × the median absolute deviation from the median of the finite values (from at
/// most about 2^18 of them, evenly spaced: plenty for a clipping level).
fn robust_sigma(z: &Array2<f64>) -> f64 {
    let step = (z.len() >> 18).max(1);
    let values: Vec<f64> = z.iter().step_by(step).copied().collect();
    let sigma = dhct_numerics::robust::mad_sigma(&values).unwrap_or(0.0);
    if sigma > 0.0 { sigma } else { f64::INFINITY }
}
