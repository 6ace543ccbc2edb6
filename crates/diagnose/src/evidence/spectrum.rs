//! Residual spectrum vs acquisition time: a Lomb–Scargle periodogram of the weighted
//! residuals (unevenly sampled: features are acquired at irregular times), both axes
//! summed, as the χ² reduction of fitting one sinusoid per axis (≈ χ²₄ under pure noise).

use serde::{Deserialize, Serialize};

use crate::model::data::Observation;

/// The periodogram of the residuals.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Spectrum {
    /// Frequencies, Hz (max-pooled to at most ~2000 points for plotting).
    pub frequency_hz: Vec<f64>,
    /// χ² reduction of one sinusoid per axis at each frequency (dimensionless).
    pub power: Vec<f64>,
    /// The strongest peaks, highest first.
    pub peaks: Vec<SpectralPeak>,
    /// Number of frequencies searched.
    pub searched: usize,
}

/// A peak of the periodogram.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SpectralPeak {
    /// Hz.
    pub frequency_hz: f64,
    /// χ² reduction.
    pub power: f64,
    /// Probability that noise alone gives a peak this high anywhere in the searched band.
    pub false_alarm_probability: f64,
}

/// Frequency grid: from 2/T to half the inverse median spacing of consecutive times,
/// oversampled ×2, at most 12 000 points.
fn grid(times_s: &[f64]) -> Option<(f64, f64, usize)> {
    let mut t: Vec<f64> = times_s.to_vec();
    t.sort_by(f64::total_cmp);
    let span = t.last()? - t.first()?;
    if span <= 0.0 || t.len() < 8 {
        return None;
    }
    let mut gaps: Vec<f64> = t
        .windows(2)
        .map(|w| w[1] - w[0])
        .filter(|d| *d > 0.0)
        .collect();
    let dt = crate::evidence::noise::median(&mut gaps);
    let f_max = 0.5 / dt;
    let f0 = 2.0 / span;
    let mut df = 1.0 / (2.0 * span);
    let mut count = ((f_max - f0) / df).ceil() as usize;
    if count > 12_000 {
        df = (f_max - f0) / 12_000.0;
        count = 12_000;
    }
    (count >= 2).then_some((f0, df, count))
}

/// Power at every grid frequency; `weighted` = `[x0, y0, x1, y1, …]`.
pub(crate) fn periodogram(observations: &[Observation], weighted: &[f64]) -> Vec<(f64, f64)> {
    let times: Vec<f64> = observations.iter().map(|o| o.time_s).collect();
    periodogram_at(&times, weighted)
}

/// [`periodogram`] of samples taken at `times_s` (seconds since frame start).
pub(crate) fn periodogram_at(times_s: &[f64], weighted: &[f64]) -> Vec<(f64, f64)> {
    let Some((f0, df, count)) = grid(times_s) else {
        return Vec::new();
    };
    let n = times_s.len() as f64;
    let mean = |axis: usize| {
        (0..times_s.len())
            .map(|i| weighted[2 * i + axis])
            .sum::<f64>()
            / n
    };
    let (mx, my) = (mean(0), mean(1));
    // Σ r cos θ, Σ r sin θ per axis and Σ cos 2θ, Σ sin 2θ, by phasor recurrence.
    let mut acc = vec![[0.0f64; 6]; count];
    for (i, &t) in times_s.iter().enumerate() {
        let (rx, ry) = (weighted[2 * i] - mx, weighted[2 * i + 1] - my);
        let theta0 = std::f64::consts::TAU * f0 * t;
        let dtheta = std::f64::consts::TAU * df * t;
        let (mut s, mut c) = theta0.sin_cos();
        let (ds, dc) = dtheta.sin_cos();
        for (k, a) in acc.iter_mut().enumerate() {
            if k % 256 == 0 && k > 0 {
                // Re-anchor to stop rounding drift.
                let (s2, c2) = (theta0 + k as f64 * dtheta).sin_cos();
                s = s2;
                c = c2;
            }
            a[0] += rx * c;
            a[1] += rx * s;
            a[2] += ry * c;
            a[3] += ry * s;
            a[4] += c * c - s * s;
            a[5] += 2.0 * s * c;
            let ns = s * dc + c * ds;
            c = c * dc - s * ds;
            s = ns;
        }
    }
    acc.iter()
        .enumerate()
        .map(|(k, a)| {
            let f = f0 + k as f64 * df;
            let two_wt = a[5].atan2(a[4]);
            let (st, ct) = (0.5 * two_wt).sin_cos();
            let c2 = a[4] * two_wt.cos() + a[5] * two_wt.sin();
            let cc = (0.5 * (n + c2)).max(1e-9);
            let ss = (0.5 * (n - c2)).max(1e-9);
            let axis = |rc: f64, rs: f64| {
                let p = ct * rc + st * rs;
                let q = ct * rs - st * rc;
                p * p / cc + q * q / ss
            };
            (f, axis(a[0], a[1]) + axis(a[2], a[3]))
        })
        .collect()
}

/// Half-width (grid points) of the window the local noise level is taken over.
const LEVEL_WINDOW: usize = 64;
/// Median of χ²₄.
const CHI2_4_MEDIAN: f64 = 3.356_694;

/// The window around each frequency that its local noise level is the median power of.
#[derive(Debug, Clone, Copy)]
pub(crate) enum LevelWindow {
    /// ±[`LEVEL_WINDOW`] grid points (fine, long grids: the slices' spectrum).
    Points,
    /// Frequencies within a factor `r` of it, the peak's own main lobe (±2 grid points)
    /// left out (coarse grids starting a few cycles per frame: the positions' spectrum,
    /// where noise correlated in time raises the lowest octaves most).
    Ratio(f64),
}

/// The periodogram's local noise level at each frequency, as a factor on χ²₄: the median
/// power over the [`LevelWindow`] over χ²₄'s median (floored at 1). Errors are not always
/// white (correlated image noise moves neighbouring features alike, the lattice repeats):
/// a peak must stand out from its neighbourhood, not only from white noise.
pub(crate) fn local_noise_levels(p: &[(f64, f64)], window: LevelWindow) -> Vec<f64> {
    (0..p.len())
        .map(|k| {
            let median = match window {
                LevelWindow::Points => {
                    let w = &p[k.saturating_sub(LEVEL_WINDOW)..(k + LEVEL_WINDOW + 1).min(p.len())];
                    dhct_numerics::robust::finite_median(w.iter().map(|(_, power)| *power))
                }
                LevelWindow::Ratio(r) => {
                    let (lo, hi) = (p[k].0 / r, p[k].0 * r);
                    dhct_numerics::robust::finite_median(
                        p.iter()
                            .enumerate()
                            .filter(|(j, (f, _))| j.abs_diff(k) > 2 && *f >= lo && *f <= hi)
                            .map(|(_, (_, power))| *power),
                    )
                }
            };
            (median.unwrap_or(CHI2_4_MEDIAN) / CHI2_4_MEDIAN).max(1.0)
        })
        .collect()
}

/// Probability that noise alone gives a peak of `power` (χ²₄, over the local level)
/// somewhere among `searched` independent frequencies.
pub(crate) fn false_alarm_probability(power: f64, searched: usize) -> f64 {
    // χ²₄ survival: e^(−z/2)(1 + z/2).
    let single = (-power / 2.0).exp() * (1.0 + power / 2.0);
    (1.0 - (1.0 - single).powf(searched.max(1) as f64)).clamp(0.0, 1.0)
}

/// The spectrum's own upper tail starts at this quantile of its normalised powers.
const TAIL_QUANTILE: f64 = 0.99;
/// Fewer normalised powers than this have no upper tail of their own to calibrate on.
const MIN_TAIL_POINTS: usize = 20;

/// Probability that a peak of `power` (over the local level) arises somewhere among
/// `searched` independent frequencies, judged by the spectrum's own upper tail: the
/// normalised powers `spectrum` above their 99th percentile are taken as exponential
/// (peaks over a threshold; their scale is their mean excess, never below the χ²₄ tail's 2)
/// and extrapolated to `power`. Noise that is not independent from sample to sample
/// (slices sharing a line, a feature, a pixel phase) gives heavier tails than χ²₄, and
/// this is what keeps its highest peaks from counting as found. `None` when the spectrum
/// is too short to have a tail.
pub(crate) fn tail_false_alarm_probability(
    spectrum: &[f64],
    power: f64,
    searched: usize,
) -> Option<f64> {
    let mut sorted: Vec<f64> = spectrum.iter().copied().filter(|p| p.is_finite()).collect();
    if sorted.len() < MIN_TAIL_POINTS * 10 {
        return None;
    }
    sorted.sort_by(f64::total_cmp);
    let start = ((sorted.len() as f64) * TAIL_QUANTILE) as usize;
    let threshold = sorted[start];
    let tail = &sorted[start..];
    let excess = tail.iter().map(|p| p - threshold).sum::<f64>() / tail.len() as f64;
    let scale = excess.max(2.0);
    let above = tail.len() as f64 / sorted.len() as f64;
    let single = if power > threshold {
        above * (-(power - threshold) / scale).exp()
    } else {
        sorted.iter().filter(|p| **p >= power).count() as f64 / sorted.len() as f64
    };
    Some((1.0 - (1.0 - single).powf(searched.max(1) as f64)).clamp(0.0, 1.0))
}

/// Indices of the `count` highest local maxima of `p` (frequency, power), highest first.
pub(crate) fn local_maxima(p: &[(f64, f64)], count: usize) -> Vec<usize> {
    let mut idx: Vec<usize> = (0..p.len())
        .filter(|&k| (k == 0 || p[k].1 >= p[k - 1].1) && (k + 1 == p.len() || p[k].1 >= p[k + 1].1))
        .collect();
    idx.sort_by(|&a, &b| p[b].1.total_cmp(&p[a].1));
    idx.truncate(count);
    idx
}

/// The positions' local noise level is taken within this factor of each frequency (half
/// an octave either side).
const POSITION_LEVEL_RATIO: f64 = 1.5;

/// Frequencies (Hz) of the `count` highest periodogram peaks over the local noise level
/// ([`local_noise_levels`], [`LevelWindow::Ratio`]) with at least `min_cycles` periods in
/// the time span and a false-alarm probability below `max_false_alarm` over that level,
/// and the number of independent frequencies searched (half the ×2-oversampled grid at or
/// above that frequency). A broad rise of the spectrum (noise correlated in time) proposes
/// nothing; a line standing out of it does.
pub(crate) fn periodogram_peaks(
    observations: &[Observation],
    weighted: &[f64],
    count: usize,
    min_cycles: f64,
    max_false_alarm: f64,
) -> (Vec<f64>, usize) {
    let times: Vec<f64> = observations.iter().map(|o| o.time_s).collect();
    peaks_at(&times, weighted, count, min_cycles, max_false_alarm)
}

/// [`periodogram_peaks`] of samples taken at `times_s` (seconds since frame start).
fn peaks_at(
    times_s: &[f64],
    weighted: &[f64],
    count: usize,
    min_cycles: f64,
    max_false_alarm: f64,
) -> (Vec<f64>, usize) {
    let p = periodogram_at(times_s, weighted);
    let (lo, hi) = times_s
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &t| {
            (a.min(t), b.max(t))
        });
    let f_min = min_cycles / (hi - lo).max(1e-12);
    let kept: Vec<(f64, f64)> = p.into_iter().filter(|(f, _)| *f >= f_min).collect();
    let searched = kept.len().div_ceil(2).max(1);
    let normalised: Vec<(f64, f64)> = kept
        .iter()
        .zip(local_noise_levels(
            &kept,
            LevelWindow::Ratio(POSITION_LEVEL_RATIO),
        ))
        .map(|(&(f, power), level)| (f, power / level))
        .collect();
    let peaks = local_maxima(&normalised, count)
        .into_iter()
        .filter(|&k| false_alarm_probability(normalised[k].1, searched) < max_false_alarm)
        .map(|k| kept[k].0)
        .collect();
    (peaks, searched)
}

/// The report's spectrum.
pub(crate) fn spectrum(observations: &[Observation], weighted: &[f64]) -> Spectrum {
    let p = periodogram(observations, weighted);
    let searched = p.len();
    // Independent frequencies ≈ half the oversampled grid.
    let m = (searched as f64 / 2.0).max(1.0);
    let peaks = local_maxima(&p, 5)
        .into_iter()
        .map(|k| {
            let z = p[k].1;
            // χ²₄ survival: e^(−z/2)(1 + z/2).
            let single = (-z / 2.0).exp() * (1.0 + z / 2.0);
            SpectralPeak {
                frequency_hz: p[k].0,
                power: z,
                false_alarm_probability: (1.0 - (1.0 - single).powf(m)).clamp(0.0, 1.0),
            }
        })
        .collect();
    let pool = searched.div_ceil(2000).max(1);
    let (frequency_hz, power) = p
        .chunks(pool)
        .map(|c| {
            c.iter().cloned().fold(
                (0.0, f64::NEG_INFINITY),
                |a, b| if b.1 > a.1 { b } else { a },
            )
        })
        .unzip();
    Spectrum {
        frequency_hz,
        power,
        peaks,
        searched,
    }
}

/// The false-alarm probability below which a slice-level vibration is reported as found.
pub const SIGNIFICANT_FALSE_ALARM: f64 = 1e-3;

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, StandardNormal};

    /// Powers with an exponential tail of scale `scale` (χ²₂-like, heavier than χ²₄'s 2).
    fn exponential_powers(scale: f64, n: usize, seed: u64) -> Vec<f64> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        (0..n)
            .map(|_| -scale * (1.0 - rand::RngExt::random::<f64>(&mut rng)).ln())
            .collect()
    }

    #[test]
    fn a_heavy_tailed_spectrum_keeps_its_own_highest_peak_from_counting_as_found() {
        // 12 000 powers of scale 5: the highest is near 5 ln 12 000 ≈ 47, which χ²₄ calls
        // significant among 6 000 frequencies; against the spectrum's own tail it is not.
        let spectrum = exponential_powers(5.0, 12_000, 3);
        let highest = spectrum.iter().copied().fold(0.0, f64::max);
        assert!(false_alarm_probability(highest, 6_000) < 1e-3, "{highest}");
        let tail = tail_false_alarm_probability(&spectrum, highest, spectrum.len()).unwrap();
        assert!(tail > 0.1, "{tail}");
        // A peak well beyond the tail is found by both.
        let tail = tail_false_alarm_probability(&spectrum, 150.0, spectrum.len()).unwrap();
        assert!(tail < 1e-6, "{tail}");
    }

    #[test]
    fn a_short_spectrum_has_no_tail_of_its_own() {
        assert!(
            tail_false_alarm_probability(&exponential_powers(2.0, 150, 4), 30.0, 150).is_none()
        );
    }

    /// 2000 samples over 100 s (irregular), weighted residuals: white noise of σ 1 plus an
    /// Ornstein–Uhlenbeck part of σ `red` and correlation time 1 s on both axes, plus a
    /// sinusoid of `amplitude` at 0.5 Hz along x.
    fn residuals(red: f64, amplitude: f64, seed: u64) -> (Vec<f64>, Vec<f64>) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut normal = || -> f64 { StandardNormal.sample(&mut rng) };
        let mut times = Vec::new();
        let mut weighted = Vec::new();
        let (mut t, mut state) = (0.0, [0.0; 2]);
        while t < 100.0 {
            let dt = 0.05 * (0.5 + normal().abs());
            let rho = (-dt / 1.0f64).exp();
            for v in &mut state {
                *v = rho * *v + (1.0 - rho * rho).sqrt() * red * normal();
            }
            let wave = amplitude * (std::f64::consts::TAU * 0.5 * t).sin();
            weighted.push(normal() + state[0] + wave);
            weighted.push(normal() + state[1]);
            times.push(t);
            t += dt;
        }
        (times, weighted)
    }

    #[test]
    fn correlated_noise_proposes_no_vibration_but_a_line_above_it_is_proposed() {
        // Red noise three times the white σ: its lowest octaves stand far above white
        // noise, so a white-noise test would propose peaks there.
        for seed in 1..6 {
            let (times, weighted) = residuals(3.0, 0.0, seed);
            let raw = periodogram_at(&times, &weighted);
            let highest = raw.iter().map(|p| p.1).fold(0.0, f64::max);
            assert!(
                highest > 40.0,
                "seed {seed}: the red noise is strong ({highest})"
            );
            let (peaks, _) = peaks_at(&times, &weighted, 5, 4.0, 1e-3);
            assert!(peaks.is_empty(), "seed {seed}: {peaks:?}");
        }
        let (times, weighted) = residuals(3.0, 1.5, 9);
        let (peaks, _) = peaks_at(&times, &weighted, 5, 4.0, 1e-3);
        assert!(
            peaks.first().is_some_and(|f| (f - 0.5).abs() < 0.01),
            "{peaks:?}"
        );
    }
}
