//! Scoring and greedy selection of candidate effects.
//!
//! For the current model (fitted, weighted residual `r`, Jacobian `J`) each candidate's
//! proposals are screened by the exact linearised χ² reduction of adding their columns `B`
//! jointly with a re-adjustment of every current parameter (`B` projected off `J`). The best
//! shape of each candidate is then scored by
//!
//! * **cross-validation over time blocks**: the frame is cut into 10 time blocks; fold `k`
//!   holds out blocks `k` and `k + 5`; the model is re-fitted (one Gauss–Newton step from
//!   the full-data solution, exact for parameters that enter linearly) on the rest and
//!   predicts the held-out residuals. Score: held-out mean square with the effect ÷ without;
//! * **BIC/AIC** with the noise variance profiled out: `n·ln(χ²/n) + k·ln n` (`2k`),
//!   counting the grid-searched shape parameters in `k`.
//!
//! The best few by BIC are re-fitted in full (all parameters, shapes free where smooth) and
//! re-scored. An effect is accepted only if its CV ratio is below `1 − min_cv_gain` and its
//! ΔBIC below `−min_delta_bic`; the accepted best joins the model and the next round
//! starts. If none passes, the answer is "no further effect needed".

use dhct_scan::ScanGeometry;
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::candidates::{Candidate, Context, Proposal, proposals, tip_proposal};
use crate::data::Observation;
use crate::fit::{Fitted, fit, pinv_sym, pinv_sym_cut, weighted};

/// Score of one candidate in one greedy round.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CandidateScore {
    /// The candidate.
    pub candidate: Candidate,
    /// The chosen shape (grid point), human-readable.
    pub shape: String,
    /// Parameters added (including grid-searched shape parameters).
    pub added_parameters: usize,
    /// χ² (weighted by the noise floor) of the model with this effect.
    pub chi2: f64,
    /// χ² reduction relative to the current model.
    pub delta_chi2: f64,
    /// BIC change (negative = better).
    pub delta_bic: f64,
    /// AIC change (negative = better).
    pub delta_aic: f64,
    /// Held-out mean square with the effect ÷ without (< 1 = predicts unseen time blocks
    /// better).
    pub cv_ratio: f64,
    /// Whether the scores come from a full non-linear refit (else linearised screening).
    pub refitted: bool,
    /// Whether it passes both acceptance tests.
    pub passes: bool,
}

/// Options of the selection.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct SelectionOptions {
    /// At most this many effects are added.
    pub max_effects: usize,
    /// Required relative drop of the held-out mean square.
    pub min_cv_gain: f64,
    /// Required BIC decrease.
    pub min_delta_bic: f64,
    /// Candidates re-fitted in full per round (best by linearised BIC).
    pub refit_top: usize,
    /// Levenberg–Marquardt iteration limit.
    pub max_iterations: usize,
}

impl Default for SelectionOptions {
    fn default() -> Self {
        SelectionOptions {
            max_effects: 3,
            min_cv_gain: 0.02,
            min_delta_bic: 20.0,
            refit_top: 3,
            max_iterations: 300,
        }
    }
}

/// Time-block fold of every observation.
pub(crate) fn folds(observations: &[Observation], blocks: usize, folds: usize) -> Vec<usize> {
    let (lo, hi) = observations
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), o| {
            (a.min(o.time_s), b.max(o.time_s))
        });
    let span = (hi - lo).max(1e-12);
    observations
        .iter()
        .map(|o| {
            let b = (((o.time_s - lo) / span * blocks as f64) as usize).min(blocks - 1);
            b % folds
        })
        .collect()
}

/// Held-out mean square of the linearised refit of design `a` (rows `[x0, y0, …]`).
pub(crate) fn cv_mean_square(a: &DMatrix<f64>, r: &DVector<f64>, fold: &[usize], k: usize) -> f64 {
    let q = a.ncols();
    let mut g = vec![DMatrix::<f64>::zeros(q, q); k];
    let mut h = vec![DVector::<f64>::zeros(q); k];
    for row in 0..a.nrows() {
        let f = fold[row / 2];
        let ar = a.row(row);
        g[f] += ar.transpose() * ar;
        h[f] += ar.transpose() * r[row];
    }
    let gt: DMatrix<f64> = g.iter().fold(DMatrix::zeros(q, q), |acc, x| acc + x);
    let ht: DVector<f64> = h.iter().fold(DVector::zeros(q), |acc, x| acc + x);
    let deltas: Vec<DVector<f64>> = (0..k)
        .map(|f| -pinv_sym_cut(&(&gt - &g[f]), 1e-8) * (&ht - &h[f]))
        .collect();
    let mut sum = 0.0;
    for row in 0..a.nrows() {
        let f = fold[row / 2];
        let e = r[row] + (a.row(row) * &deltas[f])[0];
        sum += e * e;
    }
    sum / a.nrows() as f64
}

fn hcat(a: &DMatrix<f64>, b: &DMatrix<f64>) -> DMatrix<f64> {
    let mut out = DMatrix::zeros(a.nrows(), a.ncols() + b.ncols());
    out.columns_mut(0, a.ncols()).copy_from(a);
    out.columns_mut(a.ncols(), b.ncols()).copy_from(b);
    out
}

/// Linearised χ² reduction and coefficients of adding `b` to the fit with Jacobian basis `q`.
fn screen(q: &DMatrix<f64>, r: &DVector<f64>, b: &DMatrix<f64>) -> (f64, Vec<f64>) {
    let bp = b - q * (q.transpose() * b);
    let rp = r - q * (q.transpose() * r);
    let g = bp.transpose() * &bp;
    let h = bp.transpose() * &rp;
    let beta = -pinv_sym(&g) * &h;
    let gain = -(h.transpose() * &beta)[0];
    (gain.max(0.0), beta.iter().copied().collect())
}

/// The state of the model at the start of a round.
pub(crate) struct Current<'a> {
    pub fitted: &'a Fitted,
    pub geometry: &'a ScanGeometry,
    pub observations: &'a [Observation],
    pub sigma: [f64; 2],
    pub fold: &'a [usize],
    pub folds: usize,
}

/// A scored candidate with its refitted model, if refitted.
pub(crate) struct Scored {
    pub score: CandidateScore,
    pub fitted: Option<Fitted>,
}

fn criteria(n: f64, chi2_0: f64, chi2_1: f64, k: usize) -> (f64, f64) {
    let d = n * (chi2_1.max(1e-300) / chi2_0.max(1e-300)).ln();
    (d + k as f64 * n.ln(), d + 2.0 * k as f64)
}

/// Scores every candidate in `candidates` on top of `current`; sorted best first.
pub(crate) fn round(
    current: &Current,
    candidates: &[Candidate],
    options: &SelectionOptions,
) -> Vec<Scored> {
    let fitted = current.fitted;
    let r = weighted(&fitted.residuals, current.sigma);
    let j = &fitted.jacobian;
    let q = j.clone().qr().q();
    let n = r.len() as f64;
    let chi2_0 = r.norm_squared();
    let cv0 = cv_mean_square(j, &r, current.fold, current.folds);
    let r_slice: Vec<f64> = r.iter().copied().collect();
    let ctx = Context {
        model: &fitted.model,
        geometry: current.geometry,
        observations: current.observations,
        sigma: current.sigma,
        residuals: &r_slice,
    };
    let screened: Vec<(Proposal, f64, Vec<f64>)> = candidates
        .par_iter()
        .filter_map(|&c| {
            let mut best: Option<(Proposal, f64, Vec<f64>)> = None;
            for p in proposals(c, &ctx) {
                let (gain, beta) = screen(&q, &r, &p.columns);
                if best.as_ref().is_none_or(|b| gain > b.1) {
                    best = Some((p, gain, beta));
                }
            }
            // A tip change is refined to the feature times near the best line start.
            if c == Candidate::TipChange
                && let Some((p, _, _)) = &best
                && let Some(t) = p
                    .shape
                    .strip_prefix("t = ")
                    .and_then(|s| s.trim_end_matches(" s").parse::<f64>().ok())
            {
                let lp = current.geometry.line_period();
                let mut times: Vec<f64> = current
                    .observations
                    .iter()
                    .map(|o| o.time_s)
                    .filter(|x| (x - t).abs() < lp)
                    .collect();
                times.sort_by(f64::total_cmp);
                times.dedup();
                for tt in times {
                    if let Some(p) = tip_proposal(&ctx, tt + 1e-9) {
                        let (gain, beta) = screen(&q, &r, &p.columns);
                        if best.as_ref().is_none_or(|b| gain > b.1) {
                            best = Some((p, gain, beta));
                        }
                    }
                }
            }
            best
        })
        .collect();
    let mut scored: Vec<(Scored, Option<Proposal>, Vec<f64>)> = screened
        .into_iter()
        .map(|(p, gain, beta)| {
            let k = p.columns.ncols() + p.extra_parameters;
            let chi2 = chi2_0 - gain;
            let (delta_bic, delta_aic) = criteria(n, chi2_0, chi2, k);
            let cv = cv_mean_square(&hcat(j, &p.columns), &r, current.fold, current.folds);
            let score = CandidateScore {
                candidate: p.candidate,
                shape: p.shape.clone(),
                added_parameters: k,
                chi2,
                delta_chi2: gain,
                delta_bic,
                delta_aic,
                cv_ratio: cv / cv0,
                refitted: false,
                passes: false,
            };
            (
                Scored {
                    score,
                    fitted: None,
                },
                Some(p),
                beta,
            )
        })
        .collect();
    scored.sort_by(|a, b| a.0.score.delta_bic.total_cmp(&b.0.score.delta_bic));
    // Full refits of the best few.
    let top = options.refit_top.min(scored.len());
    let refits: Vec<Option<Fitted>> = scored[..top]
        .par_iter()
        .map(|(_, p, beta)| {
            let p = p.as_ref()?;
            let model = (p.build)(beta)?;
            let r = fit(
                model,
                current.geometry,
                current.observations,
                current.sigma,
                options.max_iterations,
            );
            if let Err(e) = &r
                && std::env::var_os("DHCT_DEBUG").is_some()
            {
                eprintln!("refit failed: {e}");
            }
            r.ok()
        })
        .collect();
    for ((s, _, _), refit) in scored.iter_mut().zip(refits) {
        let Some(f) = refit else { continue };
        let rf = weighted(&f.residuals, current.sigma);
        let chi2 = rf.norm_squared();
        if std::env::var_os("DHCT_DEBUG").is_some() {
            eprintln!(
                "{}: refit χ² {chi2} vs screened {}",
                s.score.candidate, s.score.chi2
            );
        }
        let (delta_bic, delta_aic) = criteria(n, chi2_0, chi2, s.score.added_parameters);
        let cv = cv_mean_square(&f.jacobian, &rf, current.fold, current.folds);
        s.score.chi2 = chi2;
        s.score.delta_chi2 = chi2_0 - chi2;
        s.score.delta_bic = delta_bic;
        s.score.delta_aic = delta_aic;
        s.score.cv_ratio = cv / cv0;
        s.score.refitted = true;
        s.fitted = Some(f);
    }
    let mut out: Vec<Scored> = scored
        .into_iter()
        .map(|(mut s, _, _)| {
            s.score.passes = s.score.cv_ratio < 1.0 - options.min_cv_gain
                && s.score.delta_bic < -options.min_delta_bic;
            s
        })
        .collect();
    // Rank: passing first, then by BIC.
    out.sort_by(|a, b| {
        b.score
            .passes
            .cmp(&a.score.passes)
            .then(a.score.delta_bic.total_cmp(&b.score.delta_bic))
    });
    out
}
