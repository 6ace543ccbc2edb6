//! The noise floor: how far a feature's measured position scatters when nothing
//! systematic is left, estimated independently of the model being tested.
//!
//! * **Successive differences** (used as the floor): features of the same pass acquired one
//!   after the other within a line (time apart `< 0.3 ×` the line scan time) share any
//!   smooth systematic displacement, so half the robust variance of the difference of their
//!   residuals is the localisation variance (per axis, 1.4826·MAD/√2). Signals faster
//!   than the time between neighbours (vibration above ~1/(4·Δt)) inflate it.
//! * **Trace/retrace pairs**: the same lattice site imaged in trace and retrace (less than
//!   two line times apart), same estimator; includes any trace/retrace systematic.
//! * **Fit uncertainty**: the median 1σ of the feature fits (Cramér–Rao-like, from the
//!   fit covariance).

use std::collections::HashMap;

use dhct_scan::{ScanGeometry, ScanPass};
use serde::{Deserialize, Serialize};

use crate::data::Observation;

/// The noise floor and its independent estimates, metres per axis `[x, y]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NoiseFloor {
    /// The floor used for weights, χ² and gap/noise (trace/retrace pairs, else successive
    /// differences, else the feature fits).
    pub sigma_m: [f64; 2],
    /// Successive-difference estimate.
    pub successive_difference_m: [f64; 2],
    /// Pairs it used.
    pub successive_pairs: usize,
    /// Trace/retrace same-site estimate, if both passes are present.
    pub trace_retrace_m: Option<[f64; 2]>,
    /// Pairs it used.
    pub trace_retrace_pairs: usize,
    /// Median feature-fit uncertainty, if the features carry one.
    pub fit_uncertainty_m: Option<[f64; 2]>,
}

pub(crate) fn median(values: &mut [f64]) -> f64 {
    if values.is_empty() {
        return f64::NAN;
    }
    values.sort_by(f64::total_cmp);
    let n = values.len();
    if n % 2 == 1 {
        values[n / 2]
    } else {
        0.5 * (values[n / 2 - 1] + values[n / 2])
    }
}

/// 1.4826·MAD.
pub(crate) fn robust_sigma(values: &[f64]) -> f64 {
    let mut v = values.to_vec();
    let m = median(&mut v);
    let mut dev: Vec<f64> = values.iter().map(|x| (x - m).abs()).collect();
    1.4826 * median(&mut dev)
}

fn pair_sigma(diffs: &[[f64; 2]]) -> [f64; 2] {
    let x: Vec<f64> = diffs.iter().map(|d| d[0]).collect();
    let y: Vec<f64> = diffs.iter().map(|d| d[1]).collect();
    [
        robust_sigma(&x) / 2f64.sqrt(),
        robust_sigma(&y) / 2f64.sqrt(),
    ]
}

/// Estimates the floor from the residuals (metres) of any reasonable model.
pub(crate) fn estimate(
    observations: &[Observation],
    residuals: &[[f64; 2]],
    geometry: &ScanGeometry,
) -> NoiseFloor {
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
    let successive = pair_sigma(&diffs);
    let mut by_site: HashMap<(usize, i64, i64, usize), [Option<usize>; 2]> = HashMap::new();
    for (i, o) in observations.iter().enumerate() {
        let slot = match o.pass {
            ScanPass::Trace => 0,
            ScanPass::Retrace => 1,
        };
        by_site
            .entry((0, o.indices.0, o.indices.1, o.indices.2))
            .or_insert([None, None])[slot] = Some(i);
    }
    let tr: Vec<[f64; 2]> = by_site
        .values()
        .filter_map(|pair| match pair {
            [Some(a), Some(b)] => Some([
                residuals[*a][0] - residuals[*b][0],
                residuals[*a][1] - residuals[*b][1],
            ]),
            _ => None,
        })
        .collect();
    let fit: Vec<[f64; 2]> = observations
        .iter()
        .map(|o| o.fit_sigma_m)
        .filter(|s| s[0].is_finite() && s[1].is_finite())
        .collect();
    let fit_uncertainty_m = (!fit.is_empty()).then(|| {
        let mut x: Vec<f64> = fit.iter().map(|s| s[0]).collect();
        let mut y: Vec<f64> = fit.iter().map(|s| s[1]).collect();
        [median(&mut x), median(&mut y)]
    });
    let trace_retrace_m = (tr.len() >= 10).then(|| pair_sigma(&tr));
    // Trace/retrace pairs first (validated), then successive differences, then the fits.
    let sigma_m = if let Some(t) = trace_retrace_m.filter(|t| t.iter().all(|s| *s > 0.0)) {
        t
    } else if diffs.len() >= 20 && successive.iter().all(|s| *s > 0.0) {
        successive
    } else if let Some(f) = fit_uncertainty_m.filter(|f| f.iter().all(|s| *s > 0.0)) {
        f
    } else {
        let all: Vec<f64> = residuals.iter().flat_map(|r| *r).collect();
        let s = robust_sigma(&all).max(1e-15);
        [s, s]
    };
    NoiseFloor {
        sigma_m,
        successive_difference_m: successive,
        successive_pairs: diffs.len(),
        trace_retrace_m,
        trace_retrace_pairs: tr.len(),
        fit_uncertainty_m,
    }
}
