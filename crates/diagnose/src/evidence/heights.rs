//! What changes only the height: terraces at different levels (step edges), feature
//! heights that vary from atom to atom or change at one moment (a tip that changes its
//! contrast without moving). None of these moves a feature, so none is a scan distortion
//! and the position-level diagnosis does not name them; this view says they are there.

use dhct_numerics::robust::{finite_median, mad_sigma_about};
use serde::{Deserialize, Serialize};

use crate::model::data::Observation;

/// Fewest features for the view.
const MIN_FEATURES_FOR_HEIGHTS: usize = 20;

/// Significance (difference of the means over its standard error) from which a change of
/// the feature heights in time is reported. Splits are searched over most of the frame, so
/// the bar is far above a single test's.
pub const HEIGHT_CHANGE_Z: f64 = 8.0;

/// Smallest relative change of the feature heights reported (5 %).
pub const HEIGHT_CHANGE_MIN: f64 = 0.05;

/// The heights of the indexed features: what only the height tells.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HeightView {
    /// Features it was measured on.
    pub features: usize,
    /// Median apparent feature height, z units (negative for dark features).
    pub median_height: f64,
    /// Robust spread of the feature heights (MAD σ) over `|median_height|`.
    pub relative_spread: f64,
    /// Range of the local terrace level under the features (2nd to 98th percentile), z
    /// units; the levels of terraces a step edge separates.
    pub terrace_range: f64,
    /// `terrace_range` over `|median_height|` (above about 1: terraces at different levels).
    pub terrace_range_over_height: f64,
    /// The most significant change of the feature heights in time, if it passes
    /// [`HEIGHT_CHANGE_Z`] and [`HEIGHT_CHANGE_MIN`].
    pub change: Option<HeightChange>,
}

/// A change of the feature heights at one moment.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct HeightChange {
    /// When, seconds since frame start (the first feature after it).
    pub time_s: f64,
    /// Median height before, z units.
    pub before: f64,
    /// Median height after, z units.
    pub after: f64,
    /// `after / before − 1`.
    pub relative: f64,
    /// Difference of the sides' (clipped) means over its standard error, from the
    /// feature-to-feature scatter in time order (which a single change hardly raises).
    pub z: f64,
}

impl HeightView {
    /// The view of `observations` (`None` with fewer than 20 finite heights).
    pub(crate) fn of(observations: &[Observation]) -> Option<HeightView> {
        let mut in_time: Vec<(f64, f64)> = observations
            .iter()
            .filter(|o| o.apparent_height.is_finite() && o.time_s.is_finite())
            .map(|o| (o.time_s, o.apparent_height))
            .collect();
        if in_time.len() < MIN_FEATURES_FOR_HEIGHTS {
            return None;
        }
        in_time.sort_by(|a, b| a.0.total_cmp(&b.0));
        let heights: Vec<f64> = in_time.iter().map(|p| p.1).collect();
        let median_height = finite_median(heights.iter().copied())?;
        let scale = median_height.abs().max(f64::MIN_POSITIVE);
        let spread = mad_sigma_about(&heights, median_height).unwrap_or(0.0);
        let terrace_range =
            percentile_range(observations.iter().map(|o| o.terrace_height_m), 0.02, 0.98);
        Some(HeightView {
            features: heights.len(),
            median_height,
            relative_spread: spread / scale,
            terrace_range,
            terrace_range_over_height: terrace_range / scale,
            change: height_change(&in_time),
        })
    }

    /// One line for the text report.
    pub fn describe(&self) -> String {
        let mut s = format!(
            "feature heights spread {:.0} % (robust); terrace levels span {:.1} × the median \
             feature height",
            100.0 * self.relative_spread,
            self.terrace_range_over_height
        );
        if let Some(c) = &self.change {
            s.push_str(&format!(
                "; the feature heights differ by {:+.0} % after {:.1} s (z {:.0})",
                100.0 * c.relative,
                c.time_s,
                c.z
            ));
        }
        s
    }
}

/// The range between the `lo` and `hi` quantiles of the finite `values` (0 if none).
fn percentile_range(values: impl IntoIterator<Item = f64>, lo: f64, hi: f64) -> f64 {
    let mut v: Vec<f64> = values.into_iter().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
    at(hi) - at(lo)
}

/// The most significant single change of the heights `(time, height)` (in time order) over
/// the middle 80 % of the features, if it passes [`HEIGHT_CHANGE_Z`] and
/// [`HEIGHT_CHANGE_MIN`]. The split is where the means of the heights (clipped to 10
/// robust σ about the median against gross outliers) differ most significantly (a median
/// barely moves when the split is off the change, so it would not say where the change
/// is); the heights before and after are the sides' medians.
fn height_change(in_time: &[(f64, f64)]) -> Option<HeightChange> {
    let n = in_time.len();
    let raw: Vec<f64> = in_time.iter().map(|p| p.1).collect();
    let steps: Vec<f64> = raw.windows(2).map(|w| w[1] - w[0]).collect();
    let sigma = mad_sigma_about(&steps, 0.0)? / std::f64::consts::SQRT_2;
    if sigma <= 0.0 || !sigma.is_finite() {
        return None;
    }
    let centre = finite_median(raw.iter().copied())?;
    let spread = mad_sigma_about(&raw, centre)?.max(sigma);
    let clipped: Vec<f64> = raw
        .iter()
        .map(|h| h.clamp(centre - 10.0 * spread, centre + 10.0 * spread))
        .collect();
    let mut prefix = vec![0.0; n + 1];
    for (k, h) in clipped.iter().enumerate() {
        prefix[k + 1] = prefix[k] + h;
    }
    let (k, z) = (n / 10..n - n / 10)
        .map(|k| {
            let before = prefix[k] / k as f64;
            let after = (prefix[n] - prefix[k]) / (n - k) as f64;
            let error = sigma * (1.0 / k as f64 + 1.0 / (n - k) as f64).sqrt();
            (k, (after - before).abs() / error)
        })
        .max_by(|a, b| a.1.total_cmp(&b.1))?;
    let before = finite_median(raw[..k].iter().copied())?;
    let after = finite_median(raw[k..].iter().copied())?;
    let change = HeightChange {
        time_s: in_time[k].0,
        before,
        after,
        relative: after / before - 1.0,
        z,
    };
    (z >= HEIGHT_CHANGE_Z && change.relative.abs() >= HEIGHT_CHANGE_MIN).then_some(change)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn series(n: usize, change_at: Option<(usize, f64)>) -> Vec<(f64, f64)> {
        (0..n)
            .map(|i| {
                // Deterministic scatter of ±2 % about 1.
                let scatter = 0.02 * ((i as f64 * 1.618).fract() - 0.5) * 2.0;
                let level = match change_at {
                    Some((k, to)) if i >= k => to,
                    _ => 1.0,
                };
                (i as f64 * 0.1, level + scatter)
            })
            .collect()
    }

    #[test]
    fn a_contrast_change_is_found_when_it_happened() {
        let c = height_change(&series(1000, Some((600, 0.7)))).expect("found");
        assert!((c.time_s - 60.0).abs() < 1.0, "{c:?}");
        assert!((c.relative + 0.3).abs() < 0.02, "{c:?}");
        assert!(height_change(&series(1000, None)).is_none());
        // A 3 % change is below the size reported.
        assert!(height_change(&series(1000, Some((600, 0.97)))).is_none());
    }
}
