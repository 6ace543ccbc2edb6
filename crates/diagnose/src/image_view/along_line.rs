//! The lines' spectrum of the residual image: a height signal faster than a feature.
//!
//! Every line of the residual image (the image minus the model rendered forward,
//! [`crate::PassResidual`]) is windowed (Hann) over its longest run of modelled pixels
//! and transformed; the powers are averaged over the lines. Averaging over hundreds of
//! lines makes the noise's spectrum smooth, so a height signal of a fraction of the pixel
//! noise (electrical pickup, a vibration of the tip in z) stands far out of it, at its own
//! frequency whatever its phase on each line.
//!
//! Three things that are not such a signal also make peaks. Two are told apart with the
//! model image's own spectrum (the same lines of the rendered model):
//! - the lattice's own lines, where an inexact model leaves power (`lattice_locked`);
//! - sidebands: a lateral displacement `d(t)` changes the height by `∇z·d`, so a lateral
//!   vibration of `f` Hz shows as a pair of peaks `f` Hz either side of a lattice line
//!   (`sideband_of`), never at `f`; the slices ([`crate::SubFeatureView`]) measure those.
//!
//! The third, a pattern fixed on the sample that the lattice model lacks, is told apart by
//! how the peak's phase steps from line to line in trace and retrace
//! ([`crate::PassPhases`]); a signal in time must also show in both passes.
//!
//! Frequencies in Hz: bin `k` of an `n`-pixel line is `k / (n · pixel period)`.

use dhct_numerics::robust::{finite_median, mad_sigma_about};
use realfft::RealFftPlanner;
use serde::{Deserialize, Serialize};

use crate::image_view::line_spectrum::{
    MIN_RUN_FRACTION_OF_LINE, longest_finite_run, windowed_spectrum,
};
use crate::image_view::pass_phases::PassPhases;

/// The false-alarm probability below which an along-line peak is reported as found.
pub const ALONG_LINE_FALSE_ALARM: f64 = 1e-3;

/// The least share of a peak's excess power over its level that the other pass must show
/// at the same frequency for a height signal in time.
pub const MIN_SHARED_EXCESS: f64 = 0.25;

/// Bins either side of a bin its level is taken over (beyond its main lobe).
const LEVEL_WIDTH: usize = 24;
/// Fewest bins a side's level is taken over.
const MIN_LEVEL_BINS: usize = 4;

/// The strongest peak of the lines' mean power spectrum.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AlongLinePeak {
    /// Frequency, Hz (bin centre refined by a parabola through the peak's bins).
    pub frequency_hz: f64,
    /// Power over the local level (the higher of the medians of the bins either side, the
    /// main lobe left out): about 1 for noise; a spectrum that only falls (red noise, a
    /// background's curvature) does not rise above its level.
    pub power_over_level: f64,
    /// Peak amplitude of a sinusoid in the height that gives this excess power, z units.
    pub amplitude: f64,
    /// Whether the peak lies on one of the lattice's own lines (within the main lobe of a
    /// local maximum of the model image's spectrum over [`LATTICE_LINE_RATIO`] × its local
    /// level), where an inexact model leaves power: not a signal of its own.
    pub lattice_locked: bool,
    /// When the peak has a mirror image about one of the lattice's lines: that line's
    /// frequency and the offset, Hz. A lateral displacement `d(t)` changes the height by
    /// `∇z·d`, the lattice's lines modulated by `d`: a lateral vibration of `f` Hz shows as
    /// a pair of sidebands `f` Hz either side of each line, not as a peak at `f`.
    pub sideband_of: Option<LatticeSideband>,
    /// Probability that noise alone gives a peak this high among the bins searched, judged
    /// by the bins' own scatter about their levels.
    pub false_alarm_probability: f64,
    /// Bins searched.
    pub searched: usize,
    /// FFT bin along the line (cycles per line) and the half-width of its main lobe, bins.
    pub bin: [usize; 2],
    /// With both passes: whether the peak's phase moves from line to line as a signal in
    /// time or as a pattern on the sample does ([`PassPhases`]). `None` with one pass.
    #[serde(default)]
    pub phases: Option<PassPhases>,
    /// With both passes: the other pass's power over its level at the same bin (the
    /// highest within one bin). Trace and retrace lines alternate in time, so a height
    /// signal in time shows in both; a peak in one pass only is something else.
    #[serde(default)]
    pub other_pass_power_over_level: Option<f64>,
}

/// A lattice line and how far from it a peak lies.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LatticeSideband {
    /// The lattice line's frequency along the lines, Hz.
    pub lattice_hz: f64,
    /// The peak's distance from it, Hz: the frequency of a lateral modulation.
    pub offset_hz: f64,
}

/// A bin of the model image's spectrum over this many times its local level is a line of
/// the lattice's own.
pub const LATTICE_LINE_RATIO: f64 = 3.0;

/// A peak has a mirror image when the residual's power over its level at the mirrored bin
/// exceeds 1 by at least this fraction of the peak's own excess.
const MIRROR_FRACTION: f64 = 0.25;

impl AlongLinePeak {
    /// What the peak is, in words.
    fn what(&self) -> &'static str {
        if self.is_found() {
            return "a height signal that moves no feature (electrical pickup or a vibration in \
                    z; not a scan distortion)";
        }
        if self.false_alarm_probability >= ALONG_LINE_FALSE_ALARM {
            return "not significant";
        }
        if self.lattice_locked {
            return "on a lattice line (the model's atom is not exact there)";
        }
        if self.sideband_of.is_some() {
            return "a sideband of a lattice line (a lateral modulation)";
        }
        if self.is_on_sample() {
            return "a pattern fixed on the sample that the lattice model lacks (trace and \
                    retrace step alike from line to line)";
        }
        match (self.phases, self.seen_in_both_passes()) {
            (None, _) => {
                "significant, but with one pass it cannot be told from a pattern fixed on the \
                 sample"
            }
            (_, false) => "significant in this pass only (a signal in time would show in both)",
            _ => {
                "significant, but its phase from line to line tells neither a steady signal in \
                 time nor a pattern on the sample (it wanders: narrowband noise, or a pattern \
                 with little order; or it steps by nearly 0 or π per line pair)"
            }
        }
    }

    /// The peak in words (`unit`: the image's z unit).
    pub fn describe(&self, unit: &str) -> String {
        let what = self.what();
        let mut s = format!(
            "strongest peak {:.1} Hz, {:.1} × its level, amplitude {}, {what}",
            self.frequency_hz,
            self.power_over_level,
            z_value(self.amplitude, unit),
        );
        if let Some(side) = &self.sideband_of {
            s.push_str(&format!(
                " {:.1} Hz from the lattice line at {:.1} Hz",
                side.offset_hz, side.lattice_hz
            ));
        }
        s
    }

    /// Whether this is a height signal in time: significant, on no lattice line, no
    /// sideband, stepping from line to line as a signal in time does
    /// ([`PassPhases::is_in_time`]; with one pass it cannot be told from a pattern fixed on
    /// the sample, so it is not), and seen by both passes.
    pub fn is_found(&self) -> bool {
        !self.lattice_locked
            && self.sideband_of.is_none()
            && self.false_alarm_probability < ALONG_LINE_FALSE_ALARM
            && self.phases.is_some_and(|p| p.is_in_time())
            && self.seen_in_both_passes()
    }

    /// Whether the other pass shows the peak too: its power over its level exceeds 1 by at
    /// least [`MIN_SHARED_EXCESS`] of this peak's excess.
    pub fn seen_in_both_passes(&self) -> bool {
        self.other_pass_power_over_level
            .is_some_and(|r| r - 1.0 >= MIN_SHARED_EXCESS * (self.power_over_level - 1.0))
    }

    /// Whether it is a pattern fixed on the sample that the lattice model lacks (a
    /// superstructure, a second lattice, an incommensurate modulation).
    pub fn is_on_sample(&self) -> bool {
        !self.lattice_locked
            && self.sideband_of.is_none()
            && self.false_alarm_probability < ALONG_LINE_FALSE_ALARM
            && self.phases.is_some_and(|p| p.is_on_sample())
    }
}

/// The lines' mean power spectrum.
#[derive(Debug, Clone)]
pub(crate) struct LinesSpectrum {
    /// The lines' length `n`, pixels.
    length: usize,
    /// Mean power of bin `k`, `0..=n/2`.
    power: Vec<f64>,
    /// Half-width of a sinusoid's main lobe, bins (2 for whole lines; wider when the runs
    /// of modelled pixels are shorter).
    lobe: usize,
}

impl LinesSpectrum {
    /// The mean Hann-windowed power spectrum of the `lines` (all `n` long), each taken over
    /// its longest run of finite values (at least `n/4`; shorter lines are left out),
    /// windowed over the run, zero-padded to `n` and scaled by `(n/m)²` (`m` the run's
    /// length), so that a sinusoid gives the same peak power however long the run. `None`
    /// without such lines.
    pub(crate) fn of(lines: &[&[f64]]) -> Option<LinesSpectrum> {
        let n = lines.first()?.len();
        if n < 64 {
            return None;
        }
        let fft = RealFftPlanner::<f64>::new().plan_fft_forward(n);
        let mut sum = vec![0.0; n / 2 + 1];
        let mut runs = Vec::new();
        for line in lines {
            let run = longest_finite_run(line);
            if run.len() < n / MIN_RUN_FRACTION_OF_LINE {
                continue;
            }
            runs.push(run.len() as f64);
            let spectrum = windowed_spectrum(fft.as_ref(), line, run, n)?;
            sum.iter_mut()
                .zip(&spectrum)
                .for_each(|(s, c)| *s += c.norm_sqr());
        }
        let median_run = finite_median(runs.iter().copied())?;
        let used = runs.len() as f64;
        Some(LinesSpectrum {
            length: n,
            power: sum.iter().map(|s| s / used).collect(),
            lobe: ((2.0 * n as f64 / median_run).round() as usize).max(2),
        })
    }

    /// The local level at bin `k`: the higher of the medians of the [`LEVEL_WIDTH`] bins
    /// beyond the main lobe on either side (a side with fewer than [`MIN_LEVEL_BINS`] is
    /// left out; NaN if both are).
    fn level(&self, k: usize) -> f64 {
        let last = self.power.len() - 1;
        let side = |range: std::ops::RangeInclusive<usize>| {
            (range.clone().count() >= MIN_LEVEL_BINS)
                .then(|| finite_median(range.map(|j| self.power[j])))
                .flatten()
        };
        let left = k
            .checked_sub(self.lobe + 1)
            .filter(|hi| *hi >= 1)
            .and_then(|hi| side(hi.saturating_sub(LEVEL_WIDTH - 1).max(1)..=hi));
        let right = Some(k + self.lobe + 1)
            .filter(|lo| *lo <= last)
            .and_then(|lo| side(lo..=(lo + LEVEL_WIDTH - 1).min(last)));
        match (left, right) {
            (Some(a), Some(b)) => a.max(b),
            (Some(a), None) | (None, Some(a)) => a,
            (None, None) => f64::NAN,
        }
    }

    /// Each bin's power over its level; NaN below the first bin with a full level on its
    /// low side (lower bins hold the lines' levels and slopes).
    fn ratios(&self) -> Vec<f64> {
        let first = self.first_bin();
        (0..self.power.len())
            .map(|k| {
                if k < first {
                    f64::NAN
                } else {
                    self.power[k] / self.level(k).max(f64::MIN_POSITIVE)
                }
            })
            .collect()
    }

    /// The first bin searched: its low side has [`MIN_LEVEL_BINS`] bins of level.
    fn first_bin(&self) -> usize {
        self.lobe + MIN_LEVEL_BINS + 1
    }
}

/// The strongest peak of the residual lines' mean power spectrum `residual` over its
/// level, judged against the `model_lines`' spectrum (the same lines of the rendered
/// model; `pixel_period` seconds per pixel). `None` when the lines are too short or too
/// few.
pub(crate) fn along_line_peak(
    residual: &LinesSpectrum,
    model_lines: &[&[f64]],
    pixel_period: f64,
) -> Option<AlongLinePeak> {
    let model = LinesSpectrum {
        lobe: residual.lobe,
        ..LinesSpectrum::of(model_lines)?
    };
    let n = residual.length;
    let hz = |bin: f64| bin / (n as f64 * pixel_period);
    let residual_ratio = residual.ratios();
    let model_ratio = model.ratios();
    let first = residual.first_bin();
    let searched: Vec<f64> = residual_ratio[first..]
        .iter()
        .copied()
        .filter(|r| r.is_finite())
        .collect();
    if searched.len() < 2 * LEVEL_WIDTH {
        return None;
    }
    let typical = finite_median(searched.iter().copied())?;
    let spread = mad_sigma_about(&searched, typical)?;
    let k = (first..residual_ratio.len())
        .filter(|k| residual_ratio[*k].is_finite())
        .max_by(|a, b| residual_ratio[*a].total_cmp(&residual_ratio[*b]))?;
    let peak = residual_ratio[k];
    let single =
        dhct_numerics::special::normal_upper_tail((peak - typical) / spread.max(f64::MIN_POSITIVE));
    let lobe = residual.lobe;
    let line = nearest_lattice_line(&model_ratio, k);
    let lattice_locked = line.is_some_and(|line| line.abs_diff(k) <= lobe);
    let sideband_of = line
        .filter(|&line| !lattice_locked && has_mirror(&residual_ratio, k, line))
        .map(|line| LatticeSideband {
            lattice_hz: hz(line as f64),
            offset_hz: hz(k.abs_diff(line) as f64),
        });
    Some(AlongLinePeak {
        frequency_hz: hz(refined_bin(&residual.power, k)),
        power_over_level: peak,
        amplitude: sinusoid_amplitude(residual, k, n),
        lattice_locked,
        sideband_of,
        false_alarm_probability: (1.0 - (1.0 - single).powf(searched.len() as f64)).clamp(0.0, 1.0),
        searched: searched.len(),
        bin: [k, lobe],
        phases: None,
        other_pass_power_over_level: None,
    })
}

/// The power over its level of the lines' mean `spectrum` within one bin of `k` (the
/// highest), or `None` when it has none there.
pub(crate) fn power_over_level_near(spectrum: &LinesSpectrum, k: usize) -> Option<f64> {
    let ratios = spectrum.ratios();
    (k.saturating_sub(1)..=(k + 1).min(ratios.len() - 1))
        .map(|j| ratios[j])
        .filter(|r| r.is_finite())
        .max_by(f64::total_cmp)
}

/// The amplitude of the sinusoid whose excess power over the level fills the main lobe
/// around bin `k` of an `n`-point spectrum. A sinusoid of amplitude A under the Hann
/// window puts Σ|X|² = (3/32)·n²·A² into the positive frequencies (Parseval, Σw² = 3n/8),
/// nearly all of it in the main lobe.
fn sinusoid_amplitude(spectrum: &LinesSpectrum, k: usize, n: usize) -> f64 {
    let last = spectrum.power.len() - 1;
    let excess: f64 = (k.saturating_sub(spectrum.lobe).max(1)..=(k + spectrum.lobe).min(last))
        .map(|j| (spectrum.power[j] - spectrum.level(j)).max(0.0))
        .filter(|e| e.is_finite())
        .sum();
    (excess * 32.0 / (3.0 * n as f64 * n as f64)).sqrt()
}

/// The lattice line nearest to bin `k`: a local maximum of the model's spectrum over
/// [`LATTICE_LINE_RATIO`] × its level.
fn nearest_lattice_line(model_ratio: &[f64], k: usize) -> Option<usize> {
    (1..model_ratio.len() - 1)
        .filter(|&j| {
            model_ratio[j] > LATTICE_LINE_RATIO
                && model_ratio[j] >= model_ratio[j - 1]
                && model_ratio[j] >= model_ratio[j + 1]
        })
        .min_by_key(|&j| j.abs_diff(k))
}

/// Whether the residual's peak at bin `k` has a mirror image about bin `line`: power over
/// its level within a bin of `2·line − k` exceeding 1 by [`MIRROR_FRACTION`] of the
/// peak's own excess.
fn has_mirror(residual_ratio: &[f64], k: usize, line: usize) -> bool {
    let peak_excess = residual_ratio[k] - 1.0;
    let Some(mirror) = (2 * line)
        .checked_sub(k)
        .filter(|m| *m >= 1 && *m + 1 < residual_ratio.len())
    else {
        return false;
    };
    (mirror - 1..=mirror + 1)
        .map(|m| residual_ratio[m])
        .any(|r| r - 1.0 > MIRROR_FRACTION * peak_excess)
}

/// Bin `k` refined by the vertex of the parabola through its log powers and its
/// neighbours'.
fn refined_bin(power: &[f64], k: usize) -> f64 {
    if k == 0 || k + 1 >= power.len() {
        return k as f64;
    }
    let (a, b, c) = (power[k - 1].ln(), power[k].ln(), power[k + 1].ln());
    let denominator = a - 2.0 * b + c;
    if !(denominator.is_finite() && denominator < 0.0) {
        return k as f64;
    }
    k as f64 + (0.5 * (a - c) / denominator).clamp(-0.5, 0.5)
}

/// `value` in `unit`, picometres when the unit is metres.
pub(crate) fn z_value(value: f64, unit: &str) -> String {
    if unit == "m" {
        dhct_scan::quantity::picometres(value)
    } else {
        dhct_scan::quantity::si(value, unit)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn longest_run_skips_missing_values() {
        let v = [f64::NAN, 1.0, 2.0, f64::NAN, 1.0, 2.0, 3.0, f64::NAN];
        assert_eq!(longest_finite_run(&v), 4..7);
        assert_eq!(longest_finite_run(&[1.0, 2.0]), 0..2);
        assert_eq!(longest_finite_run(&[f64::NAN]), 0..0);
    }

    #[test]
    fn a_falling_spectrum_does_not_rise_above_its_level() {
        let spectrum = LinesSpectrum {
            length: 398,
            power: (0..200).map(|k| 1.0 / (1.0 + k as f64).powi(2)).collect(),
            lobe: 2,
        };
        let ratios = spectrum.ratios();
        assert!(
            ratios.iter().filter(|r| r.is_finite()).all(|r| *r <= 1.0),
            "{ratios:?}"
        );
    }
}
