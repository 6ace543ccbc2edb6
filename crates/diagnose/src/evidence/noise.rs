//! The noise floor: how far a feature's measured position scatters when nothing
//! systematic is left, estimated from what an unmodelled effect cannot absorb.
//!
//! * **Localisation (Cramér–Rao)**, the floor: the features' own 1σ position uncertainties
//!   from their fits (the image noise and the feature's shape set them; metres per axis,
//!   RMS over the features). A displacement of the whole feature, however it varies in
//!   time, does not enter them, so no scan distortion can hide in this floor.
//! * **Successive differences** (cross-check): features of the same pass acquired one
//!   after the other within a scan line (less than `0.3 ×` the line scan time apart) share
//!   any smooth systematic displacement, so half the robust variance of the difference of
//!   their residuals is the localisation variance (per axis, 1.4826·MAD/√2). When it
//!   exceeds the fits' estimate by more than [`UNDERESTIMATE_RATIO`] (from at least
//!   [`MIN_RAISE_PAIRS`] pairs) the fits understate the scatter (correlated noise, a shape the fit does not follow) and the floor takes it.
//!   A rotated lattice may have no two features on one line: then it is not available.
//! * **Trace/retrace pairs** (an upper bound only): the same site imaged in trace and
//!   retrace. Anything that differs between the passes (a vibration's phase, a mis-modelled
//!   hysteresis) enters it, so it never raises the floor; but the same site seen twice
//!   scatters by at least its localisation noise, so fits more than [`OVERSTATE_RATIO`]
//!   times that spread (from at least [`MIN_RAISE_PAIRS`] pairs) are lowered to it: their
//!   correlated-noise factor then took structure for noise (a large cell's unmodelled
//!   atoms).
//!
//! Every estimate that cannot be made says why ([`FloorUnavailable`]); the floor itself is
//! always finite and positive, and [`FloorSource`] says where it came from.

use std::collections::HashMap;

use dhct_scan::{ScanGeometry, ScanPass};
use serde::{Deserialize, Serialize};

use crate::model::data::Observation;

/// Pairs an estimate from pairs of features needs.
pub const MIN_PAIRS: usize = 20;

/// Successive differences larger than this many times the fits' uncertainty replace it.
pub const UNDERESTIMATE_RATIO: f64 = 1.5;

/// Pairs the successive differences need before they may raise the floor (a few dozen
/// pairs of a real image are too rough an estimate to let a gap hide in them), and the
/// trace/retrace pairs need before they may lower it.
pub const MIN_RAISE_PAIRS: usize = 100;

/// Fits' uncertainty more than this many times the trace/retrace spread is lowered to it.
pub const OVERSTATE_RATIO: f64 = 1.5;

/// Why an estimate of the floor could not be made.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(tag = "reason", rename_all = "snake_case")]
pub enum FloorUnavailable {
    /// The features carry no finite, positive position uncertainty (e.g. centroids).
    NoFitUncertainty,
    /// Too few pairs: for successive differences, features acquired one after the other
    /// within one scan line (a rotated lattice may have none); for trace/retrace, sites
    /// seen in both passes.
    TooFewPairs {
        /// Pairs found.
        found: usize,
        /// Pairs needed.
        needed: usize,
    },
    /// Only one pass was given (trace/retrace pairs).
    SinglePass,
    /// The estimate came out zero on an axis (identical positions: quantised or copied data).
    Zero,
}

impl std::fmt::Display for FloorUnavailable {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            FloorUnavailable::NoFitUncertainty => {
                write!(f, "the features carry no position uncertainty")
            }
            FloorUnavailable::TooFewPairs { found, needed } => {
                write!(f, "{found} pairs, {needed} needed")
            }
            FloorUnavailable::SinglePass => write!(f, "one pass only"),
            FloorUnavailable::Zero => write!(f, "zero scatter on an axis"),
        }
    }
}

/// One estimate of the floor: metres per axis `[x, y]` from `count` features or pairs, or
/// why there is none.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "status", rename_all = "snake_case")]
pub enum FloorEstimate {
    /// Estimated.
    Estimated {
        /// 1σ per axis, metres.
        sigma_m: [f64; 2],
        /// Features or pairs it used.
        count: usize,
    },
    /// Not available.
    Unavailable {
        /// Why.
        #[serde(flatten)]
        reason: FloorUnavailable,
    },
}

impl FloorEstimate {
    fn of(sigma_m: [f64; 2], count: usize, needed: usize) -> FloorEstimate {
        if count < needed {
            FloorEstimate::Unavailable {
                reason: FloorUnavailable::TooFewPairs {
                    found: count,
                    needed,
                },
            }
        } else if !sigma_m.iter().all(|s| s.is_finite() && *s > 0.0) {
            FloorEstimate::Unavailable {
                reason: FloorUnavailable::Zero,
            }
        } else {
            FloorEstimate::Estimated { sigma_m, count }
        }
    }

    /// The estimate, if there is one.
    pub fn sigma_m(&self) -> Option<[f64; 2]> {
        match self {
            FloorEstimate::Estimated { sigma_m, .. } => Some(*sigma_m),
            FloorEstimate::Unavailable { .. } => None,
        }
    }

    /// `"x × y pm (n)"` or `"— (why)"`.
    pub fn describe(&self) -> String {
        match self {
            FloorEstimate::Estimated { sigma_m, count } => format!(
                "{:.2} × {:.2} pm ({count})",
                sigma_m[0] * 1e12,
                sigma_m[1] * 1e12
            ),
            FloorEstimate::Unavailable { reason } => format!("— ({reason})"),
        }
    }
}

/// Where the floor used came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FloorSource {
    /// The features' localisation uncertainty (Cramér–Rao, from their fits).
    Localisation,
    /// The localisation uncertainty, raised on at least one axis to the successive
    /// differences (the fits understate the scatter).
    LocalisationRaisedToSuccessive,
    /// The localisation uncertainty, lowered on at least one axis to the trace/retrace
    /// spread (the fits overstate the scatter: the same site seen twice scatters less).
    LocalisationLoweredToTraceRetrace,
    /// Successive differences (the features carry no uncertainty).
    SuccessiveDifferences,
    /// Neither independent estimate exists: the residuals' own robust spread. A gap
    /// cannot be measured against it (it is 1 by construction).
    ResidualSpread,
}

impl FloorSource {
    /// Where the floor comes from, in words (the text report and the HTML report).
    pub fn describe(self) -> &'static str {
        match self {
            FloorSource::Localisation => "the features' localisation uncertainty",
            FloorSource::LocalisationRaisedToSuccessive => {
                "localisation, raised to the successive differences"
            }
            FloorSource::LocalisationLoweredToTraceRetrace => {
                "localisation, lowered to the trace/retrace spread"
            }
            FloorSource::SuccessiveDifferences => "successive differences",
            FloorSource::ResidualSpread => "the residuals' own spread: no independent floor",
        }
    }
}

/// The noise floor and its independent estimates, metres per axis `[x, y]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NoiseFloor {
    /// The floor used for weights, χ² and gap/noise: finite and positive.
    pub sigma_m: [f64; 2],
    /// Where it came from.
    pub source: FloorSource,
    /// The features' localisation uncertainty (RMS of the fits' 1σ).
    pub localisation: FloorEstimate,
    /// Successive differences within a line.
    pub successive_differences: FloorEstimate,
    /// Trace/retrace pairs of the same site (reported, never used: see the module docs).
    pub trace_retrace: FloorEstimate,
}

/// The median (NaN for no values), the shared convention of [`dhct_numerics::robust`].
pub(crate) fn median(values: &mut [f64]) -> f64 {
    dhct_numerics::robust::median(values).unwrap_or(f64::NAN)
}

/// 1.4826·MAD (NaN for no finite values).
pub(crate) fn robust_sigma(values: &[f64]) -> f64 {
    dhct_numerics::robust::mad_sigma(values).unwrap_or(f64::NAN)
}

fn pair_sigma(diffs: &[[f64; 2]]) -> [f64; 2] {
    let x: Vec<f64> = diffs.iter().map(|d| d[0]).collect();
    let y: Vec<f64> = diffs.iter().map(|d| d[1]).collect();
    [
        robust_sigma(&x) / 2f64.sqrt(),
        robust_sigma(&y) / 2f64.sqrt(),
    ]
}

/// Residual differences of features acquired one after the other within a line.
fn successive_diffs(
    observations: &[Observation],
    residuals: &[[f64; 2]],
    geometry: &ScanGeometry,
) -> Vec<[f64; 2]> {
    let max_dt = 0.3 * geometry.line_scan_time();
    let mut diffs = Vec::new();
    for pass in ScanPass::BOTH {
        let mut order: Vec<usize> = (0..observations.len())
            .filter(|&i| observations[i].pass == pass)
            .collect();
        order.sort_by(|&a, &b| observations[a].time_s.total_cmp(&observations[b].time_s));
        for w in order.windows(2) {
            let (a, b) = (&observations[w[0]], &observations[w[1]]);
            // Same scan line: line starts (sub-pixel rows interpolate them) closer than
            // half a line pair.
            let same_line = (b.time_s - b.line_time_s - (a.time_s - a.line_time_s)).abs()
                < 0.5 * geometry.line_period();
            if same_line && b.time_s - a.time_s < max_dt {
                diffs.push([
                    residuals[w[1]][0] - residuals[w[0]][0],
                    residuals[w[1]][1] - residuals[w[0]][1],
                ]);
            }
        }
    }
    diffs
}

/// Residual differences of the same lattice site seen in trace and in retrace.
fn trace_retrace_diffs(observations: &[Observation], residuals: &[[f64; 2]]) -> Vec<[f64; 2]> {
    let mut by_site: HashMap<(i64, i64, usize), [Option<usize>; 2]> = HashMap::new();
    for (i, o) in observations.iter().enumerate() {
        let slot = match o.pass {
            ScanPass::Trace => 0,
            ScanPass::Retrace => 1,
        };
        by_site.entry(o.indices).or_insert([None, None])[slot] = Some(i);
    }
    by_site
        .values()
        .filter_map(|pair| match pair {
            [Some(a), Some(b)] => Some([
                residuals[*a][0] - residuals[*b][0],
                residuals[*a][1] - residuals[*b][1],
            ]),
            _ => None,
        })
        .collect()
}

/// RMS of the features' finite, positive fit uncertainties per axis (fits more than five
/// times as uncertain as the median, failed fits on defects, left out).
fn localisation(observations: &[Observation]) -> FloorEstimate {
    let fit: Vec<[f64; 2]> = observations
        .iter()
        .map(|o| o.fit_sigma_m)
        .filter(|s| s.iter().all(|v| v.is_finite() && *v > 0.0))
        .collect();
    if fit.is_empty() {
        return FloorEstimate::Unavailable {
            reason: FloorUnavailable::NoFitUncertainty,
        };
    }
    let rms = [0, 1].map(|a| {
        let mut v: Vec<f64> = fit.iter().map(|s| s[a]).collect();
        let limit = 5.0 * median(&mut v);
        let kept: Vec<f64> = v.into_iter().filter(|s| *s <= limit).collect();
        (kept.iter().map(|s| s * s).sum::<f64>() / kept.len().max(1) as f64).sqrt()
    });
    FloorEstimate::of(rms, fit.len(), 1)
}

/// `localisation` lowered per axis to the `trace_retrace` spread (from at least
/// [`MIN_RAISE_PAIRS`] pairs) where it exceeds it [`OVERSTATE_RATIO`] times, and whether it
/// was. The same site imaged twice scatters by at least its localisation noise, so fits
/// far above that spread take for noise what is structure (a large cell's unmodelled atoms
/// in the residual their correlated-noise factor is measured on).
fn lowered_to_trace_retrace(
    localisation: FloorEstimate,
    trace_retrace: &FloorEstimate,
) -> (FloorEstimate, bool) {
    let (
        FloorEstimate::Estimated { sigma_m, count },
        FloorEstimate::Estimated {
            sigma_m: tr,
            count: pairs,
        },
    ) = (localisation, *trace_retrace)
    else {
        return (localisation, false);
    };
    if pairs < MIN_RAISE_PAIRS || !(0..2).any(|a| sigma_m[a] > OVERSTATE_RATIO * tr[a]) {
        return (localisation, false);
    }
    let lowered = [0, 1].map(|a| {
        if sigma_m[a] > OVERSTATE_RATIO * tr[a] {
            tr[a]
        } else {
            sigma_m[a]
        }
    });
    (
        FloorEstimate::Estimated {
            sigma_m: lowered,
            count,
        },
        true,
    )
}

fn localisation_source(lowered: bool) -> FloorSource {
    if lowered {
        FloorSource::LocalisationLoweredToTraceRetrace
    } else {
        FloorSource::Localisation
    }
}

/// Estimates the floor from the residuals (metres) of any reasonable model; the fits'
/// uncertainty is lowered to the trace/retrace spread only if `lower`.
pub(crate) fn estimate(
    observations: &[Observation],
    residuals: &[[f64; 2]],
    geometry: &ScanGeometry,
    lower: bool,
) -> NoiseFloor {
    let diffs = successive_diffs(observations, residuals, geometry);
    let successive_differences = FloorEstimate::of(pair_sigma(&diffs), diffs.len(), MIN_PAIRS);
    let both = ScanPass::BOTH
        .iter()
        .all(|p| observations.iter().any(|o| o.pass == *p));
    let trace_retrace = if both {
        let tr = trace_retrace_diffs(observations, residuals);
        FloorEstimate::of(pair_sigma(&tr), tr.len(), MIN_PAIRS)
    } else {
        FloorEstimate::Unavailable {
            reason: FloorUnavailable::SinglePass,
        }
    };
    let localisation = localisation(observations);
    let (fits, lowered) = if lower {
        lowered_to_trace_retrace(localisation, &trace_retrace)
    } else {
        (localisation, false)
    };
    let raising = successive_differences
        .sigma_m()
        .filter(|_| diffs.len() >= MIN_RAISE_PAIRS);
    let (sigma_m, source) = match (fits.sigma_m(), raising) {
        (Some(l), Some(s)) => {
            let raised = [0, 1].map(|a| s[a] > UNDERESTIMATE_RATIO * l[a]);
            if raised.iter().any(|r| *r) {
                let floor = [0, 1].map(|a| if raised[a] { s[a] } else { l[a] });
                (floor, FloorSource::LocalisationRaisedToSuccessive)
            } else {
                (l, localisation_source(lowered))
            }
        }
        (Some(l), None) => (l, localisation_source(lowered)),
        (None, _) if successive_differences.sigma_m().is_some() => (
            successive_differences.sigma_m().unwrap_or([1e-15; 2]),
            FloorSource::SuccessiveDifferences,
        ),
        (None, _) => {
            let all: Vec<f64> = residuals.iter().flat_map(|r| *r).collect();
            let s = robust_sigma(&all);
            let s = if s.is_finite() && s > 0.0 { s } else { 1e-15 };
            ([s, s], FloorSource::ResidualSpread)
        }
    };
    NoiseFloor {
        sigma_m,
        source,
        localisation,
        successive_differences,
        trace_retrace,
    }
}

#[cfg(test)]
mod tests {
    use dhct_scan::{ScanDirection, ScanPass};
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, StandardNormal};

    use super::*;

    /// A 256² px, 10 pm/px scan; features on a square lattice of 10 px turned by
    /// `angle_rad`, in trace only, with fit uncertainty `fit_sigma_m`.
    fn observations(angle_rad: f64, fit_sigma_m: f64) -> (Vec<Observation>, ScanGeometry) {
        let g = ScanGeometry::new(
            256,
            256,
            1e-11,
            1e-11,
            1e-4,
            ScanDirection::Right,
            ScanDirection::Down,
        )
        .expect("geometry");
        let (s, c) = angle_rad.sin_cos();
        let mut out = Vec::new();
        for n in -40i64..40 {
            for m in -40i64..40 {
                let (u, v) = (10.0 * n as f64, 10.0 * m as f64);
                let (x, y) = (128.0 + c * u - s * v, 128.0 + s * u + c * v);
                if !(5.0..250.0).contains(&x) || !(5.0..250.0).contains(&y) {
                    continue;
                }
                let t = g.acquisition_time(ScanPass::Trace, x, y);
                out.push(Observation {
                    set: 0,
                    index: out.len(),
                    pass: ScanPass::Trace,
                    controller_m: [x * 1e-11, y * 1e-11],
                    time_s: t.since_frame_start,
                    line_time_s: t.since_line_start,
                    terrace_height_m: 0.0,
                    apparent_height: 1.0,
                    fit_sigma_m: [fit_sigma_m; 2],
                    indices: (n, m, 0),
                    lattice_vector_m: [u * 1e-11, v * 1e-11],
                    whitening: crate::model::data::NO_WHITENING,
                });
            }
        }
        (out, g)
    }

    fn noise(n: usize, sigma: f64, seed: u64) -> Vec<[f64; 2]> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        (0..n)
            .map(|_| {
                let x: f64 = StandardNormal.sample(&mut rng);
                let y: f64 = StandardNormal.sample(&mut rng);
                [x * sigma, y * sigma]
            })
            .collect()
    }

    #[test]
    fn a_rotated_lattice_without_line_pairs_still_has_a_finite_floor() {
        // Rows turned by 20°: neighbours along a row are 3.4 px apart in y, never on one
        // line (the cause of the NaN × NaN floors of the field tests).
        let (obs, g) = observations(20f64.to_radians(), 2e-12);
        let r = noise(obs.len(), 2e-12, 1);
        let floor = estimate(&obs, &r, &g, true);
        assert!(matches!(
            floor.successive_differences,
            FloorEstimate::Unavailable {
                reason: FloorUnavailable::TooFewPairs { .. }
            }
        ));
        assert!(matches!(
            floor.trace_retrace,
            FloorEstimate::Unavailable {
                reason: FloorUnavailable::SinglePass
            }
        ));
        assert_eq!(floor.source, FloorSource::Localisation);
        assert!(floor.sigma_m.iter().all(|s| (*s - 2e-12).abs() < 1e-15));
        let json = serde_json::to_string(&floor).expect("serialises");
        assert!(
            json.contains("\"too_few_pairs\"") && !json.contains("NaN"),
            "{json}"
        );
    }

    #[test]
    fn without_any_independent_estimate_the_floor_says_so() {
        let (obs, g) = observations(20f64.to_radians(), f64::NAN);
        let r = noise(obs.len(), 3e-12, 2);
        let floor = estimate(&obs, &r, &g, true);
        assert_eq!(floor.source, FloorSource::ResidualSpread);
        assert!(matches!(
            floor.localisation,
            FloorEstimate::Unavailable {
                reason: FloorUnavailable::NoFitUncertainty
            }
        ));
        assert!(floor.sigma_m.iter().all(|s| s.is_finite() && *s > 0.0));
    }

    #[test]
    fn fits_that_understate_the_scatter_are_raised_to_the_successive_differences() {
        // Aligned rows (pairs along every line); the scatter is 3 pm, the fits claim 1 pm.
        let (obs, g) = observations(0.0, 1e-12);
        let r = noise(obs.len(), 3e-12, 3);
        let floor = estimate(&obs, &r, &g, true);
        assert_eq!(floor.source, FloorSource::LocalisationRaisedToSuccessive);
        assert!(
            floor
                .sigma_m
                .iter()
                .all(|s| (*s / 3e-12 - 1.0).abs() < 0.25)
        );
        // Fits that are right are kept.
        let (obs, g) = observations(0.0, 3e-12);
        let floor = estimate(&obs, &r, &g, true);
        assert_eq!(floor.source, FloorSource::Localisation);
    }

    /// [`observations`] at 20° seen in trace and in retrace.
    fn both_passes(fit_sigma_m: f64) -> (Vec<Observation>, ScanGeometry) {
        let (trace, g) = observations(20f64.to_radians(), fit_sigma_m);
        let retrace = trace.iter().map(|o| Observation {
            pass: ScanPass::Retrace,
            index: o.index + trace.len(),
            ..*o
        });
        (trace.iter().copied().chain(retrace).collect(), g)
    }

    #[test]
    fn fits_that_overstate_the_scatter_are_lowered_to_the_trace_retrace_spread() {
        // Every site in trace and retrace, scattering 2 pm in each; the fits claim 6 pm
        // (a correlated-noise factor that took structure for noise).
        let (obs, g) = both_passes(6e-12);
        let r = noise(obs.len(), 2e-12, 4);
        let floor = estimate(&obs, &r, &g, true);
        assert_eq!(floor.source, FloorSource::LocalisationLoweredToTraceRetrace);
        assert!(
            floor
                .sigma_m
                .iter()
                .all(|s| (*s / 2e-12 - 1.0).abs() < 0.15),
            "{floor:?}"
        );
        // The fits' own estimate is still reported; unasked, nothing is lowered.
        let fits = floor.localisation.sigma_m().expect("estimated");
        assert!(fits.iter().all(|s| (*s - 6e-12).abs() < 1e-18), "{fits:?}");
        let kept = estimate(&obs, &r, &g, false);
        assert_eq!(kept.source, FloorSource::Localisation);
        // Fits within 1.5 × the spread are kept.
        let (obs, g) = both_passes(2.5e-12);
        assert_eq!(
            estimate(&obs, &r, &g, true).source,
            FloorSource::Localisation
        );
    }
}
