//! How a peak of the lines' spectrum steps from one line to the next in trace and in
//! retrace: a height signal in time and a pattern fixed on the sample step differently.

use realfft::RealFftPlanner;
use realfft::num_complex::Complex;
use serde::{Deserialize, Serialize};

use crate::image_view::line_spectrum::{
    MIN_RUN_FRACTION_OF_LINE, longest_finite_run, windowed_spectrum,
};

/// The least margin by which one reading of [`PassPhases`] must beat the other for the
/// peak to be called a signal in time or a pattern on the sample (`1 − cos 2Δ ≥ 0.3`: steps
/// `Δ` within 23° of 0 or π are left untold).
pub const PHASE_MARGIN: f64 = 0.3;

/// How a peak's phase steps from one line to the next in trace and in retrace, both read
/// in display orientation (the same pixel at the same index).
///
/// A height signal in time of `f` Hz steps by `Δ = 2π·f·(line-pair period)` from line to
/// line; the retrace runs the other way, so in display orientation its step is `−Δ`. A
/// pattern fixed on the sample steps alike in both passes. With `c_t`, `c_r` the unit
/// phasors of the two passes' mean steps at the peak's bin: `in_time = Re(c_t·c_r)` (1 for
/// a signal in time) and `on_sample = Re(c_t·c̄_r)` (1 for a pattern on the sample); for
/// either kind the other reading is `cos 2Δ`, so near `Δ = 0` or `π` (a frequency locked to
/// the raster) the two cannot be told apart. Constant or slowly varying offsets between the
/// passes (hysteresis) drop out: only steps within a pass are compared.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PassPhases {
    /// How steady the steps are: the smaller of the two passes' mean step phasor length
    /// over the mean of its lengths (1 for a steady sinusoid, about 0 for noise or a
    /// phase that wanders from line to line).
    pub steadiness: f64,
    /// Agreement with a signal in time, in [−1, 1].
    pub in_time: f64,
    /// Agreement with a pattern fixed on the sample, in [−1, 1].
    pub on_sample: f64,
}

/// The least [`PassPhases::steadiness`] whose phases are read.
pub const MIN_STEADINESS: f64 = 0.3;

/// The least agreement with one kind, and the least margin over the other, of a peak
/// called that kind.
pub const MIN_PHASE_AGREEMENT: f64 = 0.8;

impl PassPhases {
    /// A signal in time: steady, `in_time` at least [`MIN_PHASE_AGREEMENT`] and
    /// [`PHASE_MARGIN`] above `on_sample`.
    pub fn is_in_time(&self) -> bool {
        self.steadiness >= MIN_STEADINESS
            && self.in_time >= MIN_PHASE_AGREEMENT
            && self.in_time - self.on_sample >= PHASE_MARGIN
    }

    /// A pattern on the sample: the converse.
    pub fn is_on_sample(&self) -> bool {
        self.steadiness >= MIN_STEADINESS
            && self.on_sample >= MIN_PHASE_AGREEMENT
            && self.on_sample - self.in_time >= PHASE_MARGIN
    }
}

/// The phases of the peak at bin `k` in the `trace` and `retrace` lines, both in display
/// orientation ([`PassPhases`]); `None` without two consecutive usable lines in each.
pub(crate) fn pass_phases(trace: &[&[f64]], retrace: &[&[f64]], k: usize) -> Option<PassPhases> {
    let c_t = mean_line_step(trace, k)?;
    let c_r = mean_line_step(retrace, k)?;
    let steadiness = c_t.norm().min(c_r.norm());
    let (u_t, u_r) = (c_t / c_t.norm(), c_r / c_r.norm());
    Some(PassPhases {
        steadiness,
        in_time: (u_t * u_r).re,
        on_sample: (u_t * u_r.conj()).re,
    })
    .filter(|p| p.in_time.is_finite() && p.on_sample.is_finite())
}

/// The mean phase step of bin `k` from each line to the next, as a phasor whose length is
/// its steadiness: `Σ X_{l+1}·X̄_l / Σ |X_{l+1}|·|X_l|`.
fn mean_line_step(lines: &[&[f64]], k: usize) -> Option<Complex<f64>> {
    let n = lines.first()?.len();
    if k == 0 || k > n / 2 {
        return None;
    }
    let fft = RealFftPlanner::<f64>::new().plan_fft_forward(n);
    let at_k: Vec<Option<Complex<f64>>> = lines
        .iter()
        .map(|line| {
            let run = longest_finite_run(line);
            (run.len() >= n / MIN_RUN_FRACTION_OF_LINE)
                .then(|| windowed_spectrum(fft.as_ref(), line, run, n))
                .flatten()
                .map(|spectrum| spectrum[k])
        })
        .collect();
    let (mut sum, mut norm) = (Complex::new(0.0, 0.0), 0.0);
    for pair in at_k.windows(2) {
        if let [Some(a), Some(b)] = pair {
            sum += b * a.conj();
            norm += b.norm() * a.norm();
        }
    }
    (norm > 0.0).then(|| sum / norm)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Trace and retrace lines (display orientation, 256 px, 50 ms per line, 0.1 s per
    /// line pair) of `z(t, x, line)` plus a little deterministic noise.
    fn passes(z: impl Fn(f64, f64, f64) -> f64) -> (Vec<Vec<f64>>, Vec<Vec<f64>>) {
        let (n, line_s, pair_s) = (256usize, 0.05, 0.1);
        let pixel_s = line_s / n as f64;
        let mut seed = 12345u64;
        let mut noise = move || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 0.2
        };
        let mut trace = Vec::new();
        let mut retrace = Vec::new();
        for l in 0..64 {
            let start = l as f64 * pair_s;
            let line = l as f64;
            trace.push(
                (0..n)
                    .map(|x| z(start + x as f64 * pixel_s, x as f64, line) + noise())
                    .collect(),
            );
            retrace.push(
                (0..n)
                    .map(|x| {
                        z(
                            start + line_s + (n - 1 - x) as f64 * pixel_s,
                            x as f64,
                            line,
                        ) + noise()
                    })
                    .collect(),
            );
        }
        (trace, retrace)
    }

    fn phases_of(z: impl Fn(f64, f64, f64) -> f64, k: usize) -> PassPhases {
        let (t, r) = passes(z);
        let t: Vec<&[f64]> = t.iter().map(Vec::as_slice).collect();
        let r: Vec<&[f64]> = r.iter().map(Vec::as_slice).collect();
        pass_phases(&t, &r, k).unwrap()
    }

    #[test]
    fn a_signal_in_time_and_a_pattern_on_the_sample_step_differently() {
        use std::f64::consts::TAU;
        // 437 Hz: 21.85 cycles per 50 ms line (bin 22); steps 43.7 cycles per line pair.
        let in_time = phases_of(|t, _, _| (TAU * 437.0 * t + 0.3).sin(), 22);
        assert!(
            in_time.is_in_time() && !in_time.is_on_sample(),
            "{in_time:?}"
        );
        // A pattern of 22 cycles per line, its rows sheared by 0.3 of a period per line.
        let on_sample = phases_of(
            |_, x, line| (TAU * (22.0 * x / 256.0 + 0.3 * line)).sin(),
            22,
        );
        assert!(
            on_sample.is_on_sample() && !on_sample.is_in_time(),
            "{on_sample:?}"
        );
        // A time signal stepping by a whole number of cycles per line pair (400 Hz × 0.1 s)
        // cannot be told from a pattern.
        let locked = phases_of(|t, _, _| (TAU * 400.0 * t).sin(), 20);
        assert!(!locked.is_in_time() && !locked.is_on_sample(), "{locked:?}");
        // Noise alone is not steady.
        let noise = phases_of(|_, _, _| 0.0, 22);
        assert!(noise.steadiness < MIN_STEADINESS, "{noise:?}");
    }
}
