//! Joint robust weighted least-squares fit of the drift/creep and hysteresis models to the
//! local distortions of trace and retrace features (pooled).
//!
//! * Drift + creep: `D_x(t)`, `D_y(t)` of every feature against `D(t) = v + a·t + C/(t+t0)`,
//!   7 parameters, `t0` bounded to [line scan time, 100 frames] through a logistic map of
//!   `ln t0`. Start: a log-spaced grid over `t0`
//!   with the (then linear) other six solved exactly; then Levenberg–Marquardt.
//! * Hysteresis: `S` of every feature against the chosen law of `τ` (line time).
//! * Robustness: Huber IRLS (4 rounds, scale from the MAD of the residuals), each axis
//!   weighted by its own robust scale. Uncertainties: `σ̂²·(JᵀWJ)⁻¹`.

use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

pub use crate::hysteresis_problem::{BIC_PREFERENCE, HysteresisChoice};
use crate::hysteresis_problem::{HysteresisData, HysteresisProblem, hysteresis_law};
use crate::model::{
    Bound, DegeneratePair, DistortionModel, DriftCreep, FitDiagnostics, HysteresisLaw, Parameter,
};
use crate::secant::{secant, secant_offsets};
use crate::thinning::thin;
use crate::{DistortionError, LocalDistortion};
use dhct_numerics::lm::{
    Bounds, LmOptions, ResidualFit, Residuals, fit_residuals, fit_residuals_within,
};
use dhct_numerics::robust::{HUBER_K, huber_weights, mad_sigma_about};

/// Options of [`fit_model`]; [`FitOptions::validate`] checks their ranges.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FitOptions {
    /// Hysteresis law (a quartic's `time_scale_s`, when given, 1 µs..=10^6 s).
    pub hysteresis: HysteresisChoice,
    /// Huber IRLS rounds (0 = plain least squares); 0..=50 (each is a full refit).
    pub robust_rounds: usize,
    /// Compare each measurement with the model's secant over the feature's neighbours
    /// (what the local fit actually measures) instead of its derivative at the feature.
    /// Removes the curvature bias of `S` near the line start and of creep near `t = 0`.
    pub secant: bool,
}

impl FitOptions {
    /// Checks every option against its documented range; the error names the key, the
    /// value and the range.
    pub fn validate(&self) -> Result<(), DistortionError> {
        let mut checks = vec![("robust_rounds", self.robust_rounds as f64, 0.0, 50.0)];
        if let HysteresisChoice::Quartic {
            time_scale_s: Some(t),
        } = self.hysteresis
        {
            checks.push(("hysteresis.time_scale_s", t, 1e-6, 1e6));
        }
        for (key, value, low, high) in checks {
            if !(value.is_finite() && (low..=high).contains(&value)) {
                return Err(DistortionError::BadParameter(format!(
                    "fit.{key} = {value} is outside {low}..={high}"
                )));
            }
        }
        Ok(())
    }
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions {
            hysteresis: HysteresisChoice::Best,
            robust_rounds: 4,
            secant: true,
        }
    }
}

/// Minimum number of local distortions for the drift fit.
pub const MIN_FEATURES: usize = 12;

const NM: f64 = 1e9;

/// Fits the model. `frame_duration_s` and `line_scan_time_s` set the search ranges of `t0`
/// and the exponential's time constant, and the quartic's default time scale.
pub fn fit_model(
    local: &[LocalDistortion],
    frame_duration_s: f64,
    line_scan_time_s: f64,
    options: &FitOptions,
) -> Result<DistortionModel, DistortionError> {
    if local.len() < MIN_FEATURES {
        return Err(DistortionError::TooFewFeatures {
            what: "drift/creep model",
            found: local.len(),
            needed: MIN_FEATURES,
        });
    }
    // The two fits share no parameter: they run side by side.
    let (drift, hysteresis) = rayon::join(
        || {
            fit_drift(
                local,
                frame_duration_s,
                line_scan_time_s,
                options.robust_rounds,
                options.secant,
            )
        },
        || fit_hysteresis(local, line_scan_time_s, options),
    );
    let (drift, mut parameters, diagnostics, drift_correlation) = drift?;
    let (hysteresis, more, hysteresis_correlation) = hysteresis?;
    parameters.extend(more);
    Ok(DistortionModel {
        drift,
        hysteresis,
        parameters,
        diagnostics,
        parameter_correlation: block_diagonal(drift_correlation, hysteresis_correlation),
    })
}

/// The correlation matrix of the `n` parameters from `at` of an inverse normal matrix (the
/// reported parameters are each a rising function of one fit parameter, so they share it);
/// 0 off the diagonal where a variance is not positive and finite. `None` without a matrix.
pub(crate) fn correlations(inverse: &Option<DMatrix<f64>>, at: usize, n: usize) -> Correlation {
    let c = inverse.as_ref()?;
    let r = |i: usize, j: usize| {
        let r = c[(i, j)] / (c[(i, i)] * c[(j, j)]).sqrt();
        match (i == j, r.is_finite()) {
            (true, _) => 1.0,
            (false, true) => r.clamp(-1.0, 1.0),
            (false, false) => 0.0,
        }
    };
    Some(
        (at..at + n)
            .map(|i| (at..at + n).map(|j| r(i, j)).collect())
            .collect(),
    )
}

/// Two independent blocks as one correlation matrix (empty when either is unknown).
fn block_diagonal(a: Correlation, b: Correlation) -> Vec<Vec<f64>> {
    let (Some(a), Some(b)) = (a, b) else {
        return Vec::new();
    };
    let (na, nb) = (a.len(), b.len());
    let mut out = vec![vec![0.0; na + nb]; na + nb];
    for (i, row) in a.iter().enumerate() {
        out[i][..na].copy_from_slice(row);
    }
    for (i, row) in b.iter().enumerate() {
        out[na + i][na..].copy_from_slice(row);
    }
    out
}

fn linear_ls(design: &DMatrix<f64>, y: &DVector<f64>) -> Option<DVector<f64>> {
    let jtj = design.transpose() * design;
    let jty = design.transpose() * y;
    jtj.lu().solve(&jty)
}

pub(crate) fn parameter(name: &str, value: f64, sigma: f64, unit: &str) -> Parameter {
    Parameter {
        name: name.to_string(),
        value,
        sigma,
        unit: unit.to_string(),
    }
}

pub(crate) fn sigmas(inverse: &Option<DMatrix<f64>>, scale2: f64, n: usize) -> Vec<f64> {
    (0..n)
        .map(|k| {
            inverse
                .as_ref()
                // An undetermined parameter has NaN variance: keep it NaN (f64::max drops NaN).
                .map_or(f64::NAN, |c| {
                    let variance = c[(k, k)] * scale2;
                    if variance.is_nan() {
                        f64::NAN
                    } else {
                        variance.max(0.0).sqrt()
                    }
                })
        })
        .collect()
}

/// The drift/creep fit's data, one entry per local distortion: feature times `t` (s), the
/// secant offsets to its neighbours (s; empty without secants), the acceleration column
/// `secant(t²/2)` and the measured drift velocities `dx`, `dy` (nm/s).
struct DriftData<'a> {
    t: Vec<f64>,
    offsets: Vec<&'a [f64]>,
    quadratic: Vec<f64>,
    dx: Vec<f64>,
    dy: Vec<f64>,
}

impl<'a> DriftData<'a> {
    fn new(local: &'a [LocalDistortion], secant_mode: bool) -> DriftData<'a> {
        let t: Vec<f64> = local.iter().map(|l| l.time_s).collect();
        let offsets = secant_offsets(local, secant_mode, |l| &l.neighbour_dt_s);
        let dx: Vec<f64> = local.iter().map(|l| l.drift_m_per_s[0] * NM).collect();
        let dy: Vec<f64> = local.iter().map(|l| l.drift_m_per_s[1] * NM).collect();
        // The acceleration column does not depend on any parameter: computed once.
        let quadratic: Vec<f64> = t
            .iter()
            .zip(&offsets)
            .map(|(&t, offsets)| secant(|x| 0.5 * x * x, t, offsets))
            .collect();
        DriftData {
            t,
            offsets,
            quadratic,
            dx,
            dy,
        }
    }

    /// The start grid's creep column for the time constant `t0` (s): the derivative
    /// `1/(t0 + t)` of `ln(1 + t/t0)` at each feature rather than its secant over the
    /// neighbours, which costs a logarithm per neighbour at each of the grid's 49 points;
    /// the fit from the start uses the secant.
    fn start_creep_column(&self, t0: f64) -> Vec<f64> {
        self.t.iter().map(|&t| 1.0 / (t0 + t)).collect()
    }
}

fn fit_drift(
    local: &[LocalDistortion],
    frame_duration_s: f64,
    line_scan_time_s: f64,
    robust_rounds: usize,
    secant_mode: bool,
) -> Result<DriftResult, DistortionError> {
    let data = DriftData::new(local, secant_mode);
    let span = frame_duration_s.max(1e-9);
    let (start, t0_start) = drift_start(&data, span)?;
    // t0 is bounded to [one line's scanning time, 100 frames]: creep faster than the slow
    // axis samples time cannot be resolved (t0 → 0 makes ln(1 + t/t0) diverge, the Matlab's
    // singularity), and beyond 100 frames it is indistinguishable from v + a·t. A logistic
    // map of ln t0 keeps the fit unconstrained ([`LogisticLog`]).
    let t0_map = LogisticLog::for_frame(line_scan_time_s, span);
    let mut p0 = start.to_vec();
    p0.push(t0_map.parameter(t0_start));
    let residuals = DriftProblem {
        t: &data.t,
        offsets: &data.offsets,
        quadratic: &data.quadratic,
        dx: &data.dx,
        dy: &data.dy,
        t0_map,
    };
    let (fit, weights) = drift_irls(&residuals, p0, robust_rounds)?;
    drift_result(&fit, &weights, t0_map)
}

/// The start of the drift/creep fit: a log-spaced grid of `t0` over 10⁻³..10² × `span`
/// (the frame duration, s), the other six parameters (nm/s units) solved linearly at each
/// point. Returns `[v_x, a_x, C_x, v_y, a_y, C_y]` and `t0` (s) of the smallest squared
/// error.
fn drift_start(data: &DriftData, span: f64) -> Result<([f64; 6], f64), DistortionError> {
    let (dx, dy) = (&data.dx, &data.dy);
    let m = data.t.len();
    // Start: grid over t0 (in parallel; the first best in grid order wins), linear in the
    // rest.
    let grid: Vec<Option<(f64, [f64; 6], f64)>> = (0..=48)
        .into_par_iter()
        .map(|k| {
            let t0 = span * 10f64.powf(-3.0 + 5.0 * k as f64 / 48.0);
            let log = data.start_creep_column(t0);
            let design = DMatrix::from_fn(m, 3, |i, j| match j {
                0 => 1.0,
                1 => data.quadratic[i],
                _ => log[i],
            });
            let px = linear_ls(&design, &DVector::from_column_slice(dx))?;
            let py = linear_ls(&design, &DVector::from_column_slice(dy))?;
            let fx = &design * &px;
            let fy = &design * &py;
            let sse: f64 = (0..m)
                .map(|i| (fx[i] - dx[i]).powi(2) + (fy[i] - dy[i]).powi(2))
                .sum();
            sse.is_finite()
                .then_some((sse, [px[0], px[1], px[2], py[0], py[1], py[2]], t0))
        })
        .collect();
    let mut best: Option<(f64, [f64; 6], f64)> = None;
    for candidate in grid.into_iter().flatten() {
        if best.as_ref().is_none_or(|b| candidate.0 < b.0) {
            best = Some(candidate);
        }
    }
    let Some((_, start, t0_start)) = best else {
        return Err(DistortionError::FitFailed("drift/creep"));
    };
    Ok((start, t0_start))
}

/// Huber IRLS of the drift/creep fit from `p0`, x and y residuals each weighted by their
/// own robust scale. Returns the last fit, its normal matrix evaluated once more with the
/// final weights, and those weights.
fn drift_irls(
    residuals: &DriftProblem,
    mut p0: Vec<f64>,
    robust_rounds: usize,
) -> Result<(ResidualFit, Vec<f64>), DistortionError> {
    let m = residuals.t.len();
    let mut weights = vec![1.0; 2 * m];
    let mut result = None;
    for round in 0..=robust_rounds.max(1) {
        let fit = fit_residuals(residuals, 2 * m, &p0, &weights, &iterations(200))
            .ok_or(DistortionError::FitFailed("drift/creep"))?;
        p0.clone_from(&fit.params);
        weights = axis_weights(&fit.residuals, m, robust_rounds > 0 && round > 0);
        result = Some(fit);
    }
    let fit = result.ok_or(DistortionError::FitFailed("drift/creep"))?;
    // One more evaluation of the normal matrix with the final weights.
    let fit = fit_residuals(residuals, 2 * m, &fit.params, &weights, &iterations(0)).unwrap_or(fit);
    Ok((fit, weights))
}

/// The drift/creep model, its parameters in SI units (m/s, m/s², m, s) with their scaled
/// uncertainties, and the fit's degeneracies and bounds hit, from the final fit.
fn drift_result(
    fit: &ResidualFit,
    weights: &[f64],
    t0_map: LogisticLog,
) -> Result<DriftResult, DistortionError> {
    let p = &fit.params;
    let s = scaled_sigmas(fit, weights, 7);
    let t0 = t0_map.t0(p[6]);
    let drift = DriftCreep {
        velocity_m_per_s: [p[0] / NM, p[3] / NM],
        acceleration_m_per_s2: [p[1] / NM, p[4] / NM],
        creep_m: [p[2] / NM, p[5] / NM],
        t0_s: t0,
    };
    if !(t0.is_finite() && p.iter().all(|v| v.is_finite())) {
        return Err(DistortionError::FitFailed("drift/creep"));
    }
    let parameters = drift_parameters(&p[..7], &s[..7], t0_map);
    let inverse = fit.inverse_normal();
    let diagnostics = drift_diagnostics(&inverse, p[6], t0_map);
    let correlation = correlations(&inverse, 0, 7);
    Ok((drift, parameters, diagnostics, correlation))
}

/// A correlation matrix, `None` when the fit could not give one.
type Correlation = Option<Vec<Vec<f64>>>;

/// The drift/creep fit's model, reported parameters, weak spots and parameter correlation.
type DriftResult = (DriftCreep, Vec<Parameter>, FitDiagnostics, Correlation);

/// The hysteresis fit's law, reported parameters and parameter correlation.
type HysteresisResult = (HysteresisLaw, Vec<Parameter>, Correlation);

/// The drift/creep fit's degenerate pairs (from `inverse`, the inverse normal matrix of
/// the seven drift parameters in fit order) and `t0` at a bound of its range (`q` its fit
/// parameter).
pub(crate) fn drift_diagnostics(
    inverse: &Option<DMatrix<f64>>,
    q: f64,
    t0_map: LogisticLog,
) -> FitDiagnostics {
    FitDiagnostics {
        degenerate_pairs: strong_correlations(inverse, &DRIFT_NAMES),
        at_bounds: if t0_map.at_bound(q) {
            vec![Bound {
                parameter: "t0".into(),
                value: t0_map.t0(q),
                range: [t0_map.lo.exp(), t0_map.hi.exp()],
            }]
        } else {
            Vec::new()
        },
    }
}

/// Names of the drift/creep parameters, in fit order.
const DRIFT_NAMES: [&str; 7] = ["v_x", "a_x", "C_x", "v_y", "a_y", "C_y", "t0"];

/// The reported drift/creep parameters (SI units) of the fit parameters
/// `p = [v_x, a_x, C_x, v_y, a_y, C_y, q]` (nm units, `t0 = t0_map.t0(q)`) and their 1σ `s`.
pub(crate) fn drift_parameters(p: &[f64], s: &[f64], t0_map: LogisticLog) -> Vec<Parameter> {
    let units = ["m/s", "m/s^2", "m", "m/s", "m/s^2", "m"];
    let mut parameters: Vec<Parameter> = (0..6)
        .map(|k| parameter(DRIFT_NAMES[k], p[k] / NM, s[k] / NM, units[k]))
        .collect();
    let t0 = t0_map.t0(p[6]);
    parameters.push(parameter("t0", t0, t0_map.derivative(p[6]) * s[6], "s"));
    parameters
}

/// 1σ uncertainties of the first `n` parameters of `fit`: `σ̂²·(JᵀWJ)⁻¹` with `σ̂²` the
/// weighted χ² per degree of freedom (at least one).
pub(crate) fn scaled_sigmas(fit: &ResidualFit, weights: &[f64], n: usize) -> Vec<f64> {
    let chi2: f64 = fit
        .residuals
        .iter()
        .zip(weights)
        .map(|(r, w)| w * r * r)
        .sum();
    let scale2 = chi2 / fit.residuals.len().saturating_sub(n).max(1) as f64;
    sigmas(&fit.inverse_normal(), scale2, n)
}

/// Correlation beyond which two parameters count as nearly degenerate (only a combination
/// of them is measured).
pub const DEGENERATE_CORRELATION: f64 = 0.95;

/// Pairs of parameters whose estimates correlate beyond ±[`DEGENERATE_CORRELATION`], from
/// the inverse normal matrix.
fn strong_correlations(inverse: &Option<DMatrix<f64>>, names: &[&str]) -> Vec<DegeneratePair> {
    let Some(c) = inverse else {
        return Vec::new();
    };
    let mut pairs = Vec::new();
    for i in 0..names.len() {
        for j in i + 1..names.len() {
            let r = c[(i, j)] / (c[(i, i)] * c[(j, j)]).sqrt();
            if r.is_finite() && r.abs() > DEGENERATE_CORRELATION {
                pairs.push(DegeneratePair {
                    first: names[i].into(),
                    second: names[j].into(),
                    correlation: r,
                });
            }
        }
    }
    pairs
}

/// `t0 = exp(lo + (hi − lo)·σ(p))`: the creep time constant as a function of an
/// unconstrained parameter `p` (σ the logistic function), bounded to `[e^lo, e^hi]`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct LogisticLog {
    lo: f64,
    hi: f64,
}

impl LogisticLog {
    /// The range of the creep time constant `t0`: one line's scanning time (creep faster
    /// than the slow axis samples time cannot be resolved) to 100 frames (beyond, it is
    /// indistinguishable from `v + a·t`).
    pub(crate) fn for_frame(line_scan_time_s: f64, frame_duration_s: f64) -> LogisticLog {
        LogisticLog {
            lo: line_scan_time_s.max(1e-6).ln(),
            hi: (100.0 * frame_duration_s.max(1e-9)).ln(),
        }
    }

    fn logistic(p: f64) -> f64 {
        1.0 / (1.0 + (-p).exp())
    }

    pub(crate) fn t0(&self, p: f64) -> f64 {
        (self.lo + (self.hi - self.lo) * Self::logistic(p)).exp()
    }

    /// `dt0/dp = t0·(hi − lo)·σ(p)·(1 − σ(p))`.
    pub(crate) fn derivative(&self, p: f64) -> f64 {
        let s = Self::logistic(p);
        self.t0(p) * (self.hi - self.lo) * s * (1.0 - s)
    }

    /// Whether `t0(p)` lies within 1 % (in log) of a bound of the range.
    pub(crate) fn at_bound(&self, p: f64) -> bool {
        let fraction = Self::logistic(p);
        !(0.01..=0.99).contains(&fraction)
    }

    /// The `p` of `t0` (clamped just inside the bounds).
    pub(crate) fn parameter(&self, t0: f64) -> f64 {
        let fraction = ((t0.ln() - self.lo) / (self.hi - self.lo)).clamp(1e-6, 1.0 - 1e-6);
        (fraction / (1.0 - fraction)).ln()
    }
}

/// The drift/creep fit: measured local drift velocities `(dx, dy)` (nm/s) against the
/// secant of `v + a·t + C·ln(1 + t/t0)`'s derivative. Parameters
/// `[v_x, a_x, C_x, v_y, a_y, C_y, p]` with `t0 = t0_map.t0(p)`; residuals x then y.
/// Linear in all but `p`, so the Jacobian is analytic and cheap.
struct DriftProblem<'a> {
    t: &'a [f64],
    offsets: &'a [&'a [f64]],
    quadratic: &'a [f64],
    dx: &'a [f64],
    dy: &'a [f64],
    t0_map: LogisticLog,
}

impl DriftProblem<'_> {
    fn creep_column(&self, t0: f64) -> Vec<f64> {
        self.t
            .par_iter()
            .zip(self.offsets)
            .map(|(&t, offsets)| secant(|x| (x / t0).ln_1p(), t, offsets))
            .collect()
    }
}

impl Residuals for DriftProblem<'_> {
    fn residuals(&self, p: &[f64], r: &mut [f64]) {
        let m = self.t.len();
        let log = self.creep_column(self.t0_map.t0(p[6]));
        let (rx, ry) = r.split_at_mut(m);
        for i in 0..m {
            rx[i] = p[0] + p[1] * self.quadratic[i] + p[2] * log[i] - self.dx[i];
            ry[i] = p[3] + p[4] * self.quadratic[i] + p[5] * log[i] - self.dy[i];
        }
    }

    fn jacobian(&self, p: &[f64], _r0: &[f64]) -> DMatrix<f64> {
        let m = self.t.len();
        let t0 = self.t0_map.t0(p[6]);
        let log = self.creep_column(t0);
        // ∂ ln(1 + x/t0) / ∂t0 = −x / (t0·(t0 + x)), through the same (linear) secant.
        let dt0 = self.t0_map.derivative(p[6]);
        let dlog: Vec<f64> = self
            .t
            .par_iter()
            .zip(self.offsets)
            .map(|(&t, offsets)| dt0 * secant(|x| -x / (t0 * (t0 + x)), t, offsets))
            .collect();
        let mut jac = DMatrix::zeros(2 * m, 7);
        for i in 0..m {
            jac[(i, 0)] = 1.0;
            jac[(i, 1)] = self.quadratic[i];
            jac[(i, 2)] = log[i];
            jac[(i, 6)] = p[2] * dlog[i];
            jac[(m + i, 3)] = 1.0;
            jac[(m + i, 4)] = self.quadratic[i];
            jac[(m + i, 5)] = log[i];
            jac[(m + i, 6)] = p[5] * dlog[i];
        }
        jac
    }
}

fn fit_hysteresis(
    local: &[LocalDistortion],
    line_scan_time_s: f64,
    options: &FitOptions,
) -> Result<HysteresisResult, DistortionError> {
    let choice = match options.hysteresis {
        HysteresisChoice::Best => best_family(local, line_scan_time_s, options)?,
        choice => choice,
    };
    let data = HysteresisData::new(local, options.secant);
    fit_hysteresis_as(&data, choice, line_scan_time_s, options).map(|fit| fit.result)
}

/// Local distortions the law family is chosen on under [`HysteresisChoice::Best`] (every
/// k-th, in time order): enough for BIC to tell the laws apart, few enough that choosing
/// costs little beside the one full fit.
const FAMILY_CHOICE_MAX: usize = 3000;

/// The hysteresis law family with the lowest BIC on (at most [`FAMILY_CHOICE_MAX`] of)
/// `local`.
fn best_family(
    local: &[LocalDistortion],
    line_scan_time_s: f64,
    options: &FitOptions,
) -> Result<HysteresisChoice, DistortionError> {
    let sample = thin(local, FAMILY_CHOICE_MAX);
    let data = HysteresisData::new(&sample, options.secant);
    let fits: Vec<(HysteresisChoice, Result<HysteresisFit, DistortionError>)> = [
        HysteresisChoice::Power,
        HysteresisChoice::Exponential,
        HysteresisChoice::Quartic { time_scale_s: None },
    ]
    .into_iter()
    .map(|c| (c, fit_hysteresis_as(&data, c, line_scan_time_s, options)))
    .collect();
    best_by_bic(fits)
}

/// One hysteresis law fitted: the result and its residuals (predicted − measured scale).
struct HysteresisFit {
    result: HysteresisResult,
    residuals: Vec<f64>,
}

/// The family with the lowest BIC among `fits`, the power law kept unless another is
/// lower by [`BIC_PREFERENCE`]. Every law is scored on one noise scale, the smallest robust
/// scale of their residuals, with Huber's loss (what the fits minimise):
/// `BIC = 2·Σρ(r/σ) + k·ln m`. The power law's error when no law could be fitted.
fn best_by_bic(
    fits: Vec<(HysteresisChoice, Result<HysteresisFit, DistortionError>)>,
) -> Result<HysteresisChoice, DistortionError> {
    let scale = fits
        .iter()
        .filter_map(|(_, f)| f.as_ref().ok())
        .filter_map(|f| mad_sigma_about(&f.residuals, 0.0))
        .filter(|s| *s > 0.0)
        .fold(f64::INFINITY, f64::min);
    let bic = |f: &HysteresisFit| {
        let k = HUBER_K;
        let loss: f64 = f
            .residuals
            .iter()
            .map(|r| (r / scale).abs())
            .map(|a| {
                if a <= k {
                    0.5 * a * a
                } else {
                    k * a - 0.5 * k * k
                }
            })
            .sum();
        let m = f.residuals.len() as f64;
        2.0 * loss + f.result.1.len() as f64 * m.ln()
    };
    let mut best: Option<(f64, HysteresisChoice)> = None;
    let mut power_error = None;
    for (choice, fit) in fits {
        let fit = match fit {
            Ok(fit) => fit,
            Err(e) => {
                if choice == HysteresisChoice::Power {
                    power_error = Some(e);
                }
                continue;
            }
        };
        let preference = if choice == HysteresisChoice::Power {
            0.0
        } else {
            BIC_PREFERENCE
        };
        let score = bic(&fit) + preference;
        // Residuals all exactly 0 leave the scale infinite: every loss is then 0 and the
        // parameter count decides. A law whose residuals are not finite is never kept.
        if score.is_finite() && best.as_ref().is_none_or(|(b, _)| score < *b) {
            best = Some((score, choice));
        }
    }
    match (best, power_error) {
        (Some((_, choice)), _) => Ok(choice),
        (None, Some(e)) => Err(e),
        (None, None) => Err(DistortionError::FitFailed("hysteresis")),
    }
}

/// Fits the hysteresis law `choice` to `data`.
fn fit_hysteresis_as(
    data: &HysteresisData,
    choice: HysteresisChoice,
    line_scan_time_s: f64,
    options: &FitOptions,
) -> Result<HysteresisFit, DistortionError> {
    let m = data.tau.len();
    let Some(p0) = hysteresis_start(data, choice, line_scan_time_s)? else {
        return Ok(HysteresisFit {
            result: (HysteresisLaw::none(), Vec::new(), Some(Vec::new())),
            residuals: Vec::new(),
        });
    };
    let n = p0.len();
    if m < n + 3 {
        return Err(DistortionError::TooFewFeatures {
            what: "hysteresis model",
            found: m,
            needed: n + 3,
        });
    }
    let problem = HysteresisProblem {
        data,
        choice,
        line_scan_time_s,
    };
    let (fit, weights) = hysteresis_irls(&problem, m, p0, options.robust_rounds)?;
    let sg = scaled_sigmas(&fit, &weights, n);
    let p = &fit.params;
    let law = hysteresis_law(choice, line_scan_time_s, p);
    if let HysteresisLaw::Power { k, n } = law
        && !(k > 0.0 && n > -1.0)
    {
        // ∫S dτ diverges at τ = 0 for n ≤ −1.
        return Err(DistortionError::FitFailed(
            "hysteresis (the power law left its domain k > 0, n > −1)",
        ));
    }
    let correlation = correlations(&fit.inverse_normal(), 0, n);
    let parameters = hysteresis_parameters(choice, p, &sg);
    Ok(HysteresisFit {
        result: (law, parameters, correlation),
        residuals: fit.residuals,
    })
}

/// The start of the hysteresis fit for `choice` (`None` for no hysteresis): linear least
/// squares for the quartic and (in logs) the power law, a grid over the time constant for
/// the exponential.
fn hysteresis_start(
    data: &HysteresisData,
    choice: HysteresisChoice,
    line_scan_time_s: f64,
) -> Result<Option<Vec<f64>>, DistortionError> {
    let (tau, s) = (&data.tau, &data.s);
    let m = tau.len();
    let p0: Vec<f64> = match choice {
        HysteresisChoice::None => return Ok(None),
        HysteresisChoice::Quartic { time_scale_s } => {
            let ts = time_scale_s.unwrap_or(line_scan_time_s);
            let design = DMatrix::from_fn(m, 5, |i, j| (tau[i] / ts).powi(j as i32));
            let y = DVector::from_iterator(m, s.iter().map(|s| s - 1.0));
            linear_ls(&design, &y)
                .ok_or(DistortionError::FitFailed("hysteresis"))?
                .iter()
                .copied()
                .collect()
        }
        HysteresisChoice::Power | HysteresisChoice::Best => {
            let pts: Vec<(f64, f64)> = tau
                .iter()
                .zip(s)
                .filter(|(t, s)| **t > 0.0 && **s > 0.0)
                .map(|(t, s)| (t.ln(), s.ln()))
                .collect();
            let design = DMatrix::from_fn(pts.len(), 2, |i, j| if j == 0 { 1.0 } else { pts[i].0 });
            let y = DVector::from_iterator(pts.len(), pts.iter().map(|p| p.1));
            let q = linear_ls(&design, &y).ok_or(DistortionError::FitFailed("hysteresis"))?;
            vec![q[0].exp(), q[1]]
        }
        HysteresisChoice::Exponential => exponential_start(tau, s, line_scan_time_s),
    };
    Ok(Some(p0))
}

/// `[A, ln τ_h]` of `S = 1 + A·exp(−τ/τ_h)` minimising the squared error over a grid of
/// `τ_h` from 10⁻³ to 10 line scan times (s), `A` solved linearly at each point.
fn exponential_start(tau: &[f64], s: &[f64], line_scan_time_s: f64) -> Vec<f64> {
    let mut best = (f64::INFINITY, 0.0, line_scan_time_s.ln());
    for k in 0..=40 {
        let th = line_scan_time_s * 10f64.powf(-3.0 + 4.0 * k as f64 / 40.0);
        let e: Vec<f64> = tau.iter().map(|t| (-t / th).exp()).collect();
        let ee: f64 = e.iter().map(|e| e * e).sum();
        let ey: f64 = e.iter().zip(s).map(|(e, s)| e * (s - 1.0)).sum();
        let a = ey / ee.max(1e-300);
        let sse: f64 = e
            .iter()
            .zip(s)
            .map(|(e, s)| (a * e - (s - 1.0)).powi(2))
            .sum();
        if sse < best.0 {
            best = (sse, a, th.ln());
        }
    }
    vec![best.1, best.2]
}

/// Huber IRLS of the `m` hysteresis residuals from `p0`. Returns the last fit, its normal
/// matrix evaluated once more with the final weights, and those weights.
fn hysteresis_irls<R: Residuals>(
    residuals: &R,
    m: usize,
    mut p: Vec<f64>,
    robust_rounds: usize,
) -> Result<(ResidualFit, Vec<f64>), DistortionError> {
    let mut weights = vec![1.0; m];
    let mut last = None;
    for round in 0..=robust_rounds.max(1) {
        let fit = fit_residuals(residuals, m, &p, &weights, &iterations(200))
            .ok_or(DistortionError::FitFailed("hysteresis"))?;
        p.clone_from(&fit.params);
        let sigma = robust_scale(&fit.residuals).max(1e-300);
        let h = if robust_rounds > 0 && round > 0 {
            huber_weights(&fit.residuals, sigma)
        } else {
            vec![1.0; m]
        };
        weights = h.iter().map(|h| h / (sigma * sigma)).collect();
        last = Some(fit);
    }
    let fit = last.ok_or(DistortionError::FitFailed("hysteresis"))?;
    let fit = fit_residuals(residuals, m, &fit.params, &weights, &iterations(0)).unwrap_or(fit);
    Ok((fit, weights))
}

/// The reported hysteresis parameters of `choice` (the exponential's time constant in
/// seconds, its uncertainty propagated from `ln τ_h`).
pub(crate) fn hysteresis_parameters(
    choice: HysteresisChoice,
    p: &[f64],
    sg: &[f64],
) -> Vec<Parameter> {
    match choice {
        HysteresisChoice::None => Vec::new(),
        HysteresisChoice::Quartic { .. } => (0..5)
            .map(|k| parameter(&format!("c{k}"), p[k], sg[k], "1"))
            .collect(),
        HysteresisChoice::Power | HysteresisChoice::Best => vec![
            parameter("k", p[0], sg[0], "s^-n"),
            parameter("n", p[1], sg[1], "1"),
        ],
        HysteresisChoice::Exponential => vec![
            parameter("amplitude", p[0], sg[0], "1"),
            parameter("time_constant", p[1].exp(), p[1].exp() * sg[1], "s"),
        ],
    }
}

/// LM options with at most `max_iterations` steps (0: only the covariance at the start).
fn iterations(max_iterations: usize) -> LmOptions {
    LmOptions {
        max_iterations,
        ..LmOptions::default()
    }
}

/// Huber IRLS of a position fit from `p`: residuals the `m` x deviations, the `m` y
/// deviations, then `rows − 2m` prior rows. The positions are weighted by each axis's own
/// robust scale (Huber weights after the first round when `robust_rounds > 0`), the priors
/// keep unit weight. Returns the last fit, its normal matrix evaluated once more with the
/// final weights, and those weights. `what` names the fit in its error; `bounds`, when
/// given, keep the parameters inside a box.
pub(crate) fn position_irls<R: Residuals + ?Sized>(
    problem: &R,
    (rows, m): (usize, usize),
    plain_weights: Vec<f64>,
    mut p: Vec<f64>,
    robust_rounds: usize,
    what: &'static str,
    bounds: Option<&Bounds>,
) -> Result<(ResidualFit, Vec<f64>), DistortionError> {
    let mut weights = plain_weights;
    let mut last = None;
    let lm = iterations(100);
    for round in 0..=robust_rounds.max(1) {
        let fit = fit_residuals_within(problem, rows, &p, &weights, bounds.cloned(), &lm)
            .ok_or(DistortionError::FitFailed(what))?;
        p.clone_from(&fit.params);
        weights = axis_weights(&fit.residuals, m, round > 0 && robust_rounds > 0);
        weights.extend(std::iter::repeat_n(1.0, rows - 2 * m));
        last = Some(fit);
    }
    let fit = last.ok_or(DistortionError::FitFailed(what))?;
    let fit = fit_residuals(problem, rows, &fit.params, &weights, &iterations(0)).unwrap_or(fit);
    Ok((fit, weights))
}

/// Weights of `2m` residuals, the `m` x ones then the `m` y ones: each axis by its own
/// robust scale (`1/σ²`), times Huber weights when `huber`.
pub(crate) fn axis_weights(residuals: &[f64], m: usize, huber: bool) -> Vec<f64> {
    let (rx, ry) = residuals[..2 * m].split_at(m);
    let (sx, sy) = (robust_scale(rx).max(1e-300), robust_scale(ry).max(1e-300));
    let (hx, hy) = if huber {
        (huber_weights(rx, sx), huber_weights(ry, sy))
    } else {
        (vec![1.0; m], vec![1.0; m])
    };
    hx.iter()
        .map(|h| h / (sx * sx))
        .chain(hy.iter().map(|h| h / (sy * sy)))
        .collect()
}

/// Robust scale of fit residuals about zero (0 when there are none).
fn robust_scale(residuals: &[f64]) -> f64 {
    mad_sigma_about(residuals, 0.0).unwrap_or(0.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fitted law of `parameters` parameters with `residuals`.
    fn fit(parameters: usize, residuals: Vec<f64>) -> Result<HysteresisFit, DistortionError> {
        let names = ["p"; 5];
        Ok(HysteresisFit {
            result: (
                HysteresisLaw::none(),
                (0..parameters)
                    .map(|k| parameter(names[k], 0.0, 0.0, "1"))
                    .collect(),
                None,
            ),
            residuals,
        })
    }

    /// Residuals of scale `sigma` (a fixed alternating pattern, so the test is exact).
    fn noise(sigma: f64) -> Vec<f64> {
        (0..400)
            .map(|k| sigma * [1.0, -0.5, 0.25, -1.2][k % 4])
            .collect()
    }

    const POWER: HysteresisChoice = HysteresisChoice::Power;
    const EXPONENTIAL: HysteresisChoice = HysteresisChoice::Exponential;
    const QUARTIC: HysteresisChoice = HysteresisChoice::Quartic { time_scale_s: None };

    #[test]
    fn the_law_with_clearly_smaller_residuals_wins() {
        let choice = best_by_bic(vec![
            (POWER, fit(2, noise(2.0))),
            (EXPONENTIAL, fit(2, noise(1.0))),
            (QUARTIC, fit(5, noise(1.0))),
        ]);
        assert_eq!(choice.unwrap(), EXPONENTIAL);
    }

    #[test]
    fn the_power_law_stays_unless_clearly_beaten() {
        // Equal residuals: the preference keeps the power law.
        let tie = best_by_bic(vec![
            (POWER, fit(2, noise(1.0))),
            (EXPONENTIAL, fit(2, noise(1.0))),
            (QUARTIC, fit(5, noise(0.999))),
        ]);
        assert_eq!(tie.unwrap(), POWER);
        // Residuals all exactly zero: the parameter count (and the preference) decide.
        let exact = best_by_bic(vec![
            (POWER, fit(2, vec![0.0; 50])),
            (EXPONENTIAL, fit(2, vec![0.0; 50])),
        ]);
        assert_eq!(exact.unwrap(), POWER);
    }

    #[test]
    fn a_law_that_failed_or_left_nan_is_never_chosen() {
        let mut nan = noise(0.1);
        nan[3] = f64::NAN;
        let choice = best_by_bic(vec![
            (POWER, Err(DistortionError::FitFailed("hysteresis"))),
            (EXPONENTIAL, fit(2, nan)),
            (QUARTIC, fit(5, noise(1.0))),
        ]);
        assert_eq!(choice.unwrap(), QUARTIC);
        let none = best_by_bic(vec![(POWER, Err(DistortionError::FitFailed("power")))]);
        assert!(matches!(none, Err(DistortionError::FitFailed("power"))));
    }
}
