//! The size of a gap (against the noise floor), how far it shrank, the effects that shrank
//! it, and each feature's residuals.

use dhct_scan::ScanPass;
use serde::{Deserialize, Serialize};

use crate::model::fit::FittedParameter;
use crate::search::candidates::Candidate;

/// Size of a gap relative to the noise floor.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct GapSummary {
    /// RMS residual per axis, metres.
    pub rms_m: [f64; 2],
    /// `√(χ²/2N)`: RMS residual in units of the noise floor (1 = at the floor).
    pub gap_to_noise: f64,
    /// `Σ (r_x/σ_x)² + (r_y/σ_y)²`.
    pub chi2: f64,
    /// χ² over the degrees of freedom `2N − p`.
    pub chi2_per_dof: f64,
    /// `2N − p`.
    pub dof: usize,
}

impl GapSummary {
    pub(crate) fn of(residuals: &[[f64; 2]], sigma: [f64; 2], parameters: usize) -> GapSummary {
        let n = residuals.len().max(1) as f64;
        let mut sq = [0.0; 2];
        let mut chi2 = 0.0;
        for r in residuals {
            sq[0] += r[0] * r[0] / n;
            sq[1] += r[1] * r[1] / n;
            chi2 += (r[0] / sigma[0]).powi(2) + (r[1] / sigma[1]).powi(2);
        }
        let dof = (2 * residuals.len()).saturating_sub(parameters).max(1);
        GapSummary {
            rms_m: [sq[0].sqrt(), sq[1].sqrt()],
            gap_to_noise: (chi2 / (2.0 * n)).sqrt(),
            chi2,
            chi2_per_dof: chi2 / dof as f64,
            dof,
        }
    }
}

/// An effect added to the model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AddedEffect {
    /// Which.
    pub candidate: Candidate,
    /// Grid shape it started from.
    pub shape: String,
    /// Its fitted parameters with uncertainties (SI).
    pub parameters: Vec<FittedParameter>,
    /// Gap after adding it (and everything before it).
    pub gap_after: GapSummary,
    /// Other candidates of its round, refitted and passing, whose χ² reduction comes
    /// within [`NEAR_TIE_FRACTION`] of its own: they explain the positions about as well,
    /// so the data do not tell them apart from it.
    #[serde(default)]
    pub about_as_good: Vec<Candidate>,
}

/// How close (as a fraction of the accepted effect's χ² reduction) another candidate's
/// reduction must come to be reported as explaining the positions about as well. A few per
/// cent of the effect is what the base model's own misfit (a hysteresis law or creep form
/// that is close but not the scan's) shifts between similar candidates: on the validation
/// scans, the exponential and second creep events differ by 0.5–5 % and either can win,
/// and an x-only piezo non-linearity against an asymmetric hysteresis by 0.5–1.5 %.
pub const NEAR_TIE_FRACTION: f64 = 0.05;

/// How far the gap shrinks (gap/noise ratios).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Shrink {
    /// Base model (position-level fit).
    pub before: f64,
    /// The top-ranked candidate of round 1 (whether or not accepted).
    pub top: Option<Candidate>,
    /// Gap with it.
    pub after_top: Option<f64>,
    /// After the accepted greedy set.
    pub after_greedy: f64,
}

/// One feature's residuals, for plots.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FeatureResidual {
    /// Input set and index of the feature.
    pub set: usize,
    /// Index within its set.
    pub index: usize,
    /// Its pass.
    pub pass: ScanPass,
    /// Seconds since frame start.
    pub time_s: f64,
    /// Seconds since line start.
    pub line_time_s: f64,
    /// Measured controller position, metres.
    pub controller_m: [f64; 2],
    /// Controller-frame gap of the DHCT sim, `measured − predicted`, metres.
    pub dhct_gap_m: [f64; 2],
    /// Residual of the position-level base fit, metres.
    pub base_m: [f64; 2],
    /// Residual of the final model, metres.
    pub final_m: [f64; 2],
    /// Rejected as an outlier (not used in the fits).
    pub outlier: bool,
}
