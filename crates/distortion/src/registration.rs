//! The global registration: drift + creep + hysteresis fitted to every indexed feature's
//! *position* against the ideal lattice of the known constant, each feature at its own
//! acquisition time. Beside the paper's route (local distortions from full neighbour
//! shells, then the model fitted to them), it needs no neighbour shells at all: a frame of
//! a few large cells, or a lattice stretched past the NN window, still registers.
//!
//! Model (sample frame, metres): the feature of motif site `s` in cell `(n, m)` of pass `k`,
//! seen at controller position `p_c` at time `t` and line time `τ`, satisfies
//! `p_c + d(t, τ, pass) = o_k + R(θ)·(n·a1 + m·a2 + f_s)`, with `d` the model's displacement
//! ([`DistortionModel::displacement_at`]), `R(θ)` the lattice rotation and `o_k` one origin
//! per pass (the passes are indexed separately, so an index offset between them costs
//! nothing). Fitted: θ, the origins, `v`, `a`, `C` per axis, `t0`, and the hysteresis law's
//! parameters, by Huber-robust least squares with the analytic Jacobian.

use dhct_lattice::{IndexedPoint, Lattice, LatticeFitOptions, fit_calibrated_lattice};
use dhct_numerics::lm::{LmOptions, ResidualFit, Residuals, fit_residuals};
use dhct_numerics::robust::mad_sigma_about;
use dhct_scan::{ScanGeometry, ScanPass};
use nalgebra::DMatrix;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::fit::{
    FitOptions, HysteresisChoice, LogisticLog, correlations, drift_diagnostics, drift_parameters,
    hysteresis_parameters, position_irls, scaled_sigmas,
};
use crate::hysteresis_problem::{Quantity, hysteresis_law, law_gradient, law_parameters};
use crate::model::{DriftCreep, scan_basis};
use crate::thinning::thin;
use crate::{DistortionError, DistortionModel, PassInput};

/// Nanometres per metre: the fit works in nm (and nm/s).
const NM: f64 = 1e9;

/// A feature farther than this fraction of the NN distance from its indexed site (in the
/// frame the start model corrects to) is left out of the registration.
pub const MAX_INDEX_DEVIATION: f64 = 0.3;

/// Most features the registration is fitted to (evenly thinned beyond; all are indexed):
/// a dozen parameters are fixed to well below the localisation noise by a few thousand.
pub const MAX_FITTED: usize = 4000;

/// Scale of the weak prior that keeps the creep amplitudes `C` near zero where the data do
/// not resolve a creep, nanometres: a creep whose `t0` runs to a bound is a second velocity,
/// and `C` and `v` then trade off without limit (micrometres of each) at no cost in fit.
/// Resolved creeps (0.1–10 nm) are fixed by the positions thousands of times more strongly.
const CREEP_PRIOR_NM: f64 = 10.0;

/// Fewest indexed features the registration fits.
pub const MIN_REGISTERED: usize = 24;

/// One feature of the registration: where the controller put it, when, and which lattice
/// site it is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RegisteredFeature {
    /// Index of its pass among the registration's passes (its own origin).
    pub pass_index: usize,
    /// Index of the feature in its pass's input.
    pub feature_index: usize,
    /// Trace or retrace.
    pub pass: ScanPass,
    /// Controller position, metres (display frame).
    pub controller_m: [f64; 2],
    /// Acquisition time, seconds since frame start.
    pub time_s: f64,
    /// Seconds since its line start (its pass's direction).
    pub line_time_s: f64,
    /// Its ideal site in the lattice's own frame, `n·a1 + m·a2 + f_s`, metres.
    pub site_m: [f64; 2],
}

/// The result of [`register`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Registration {
    /// The fitted model (its parameters with 1σ; θ and the origins are not among them).
    pub model: DistortionModel,
    /// Lattice rotation θ, radians (display frame, from +x towards +y).
    pub lattice_angle_rad: f64,
    /// Origin of each pass's lattice, metres.
    pub origins_m: Vec<[f64; 2]>,
    /// Robust RMS of the features' deviations from their sites after the fit, metres.
    pub rms_deviation_m: f64,
    /// Features registered.
    pub features: usize,
}

/// Indexes the features of `inputs` (inside each mask) against `lattice`, with positions
/// corrected by `start` (a model from the local route, or one that undoes the measured
/// affine map): features within [`MAX_INDEX_DEVIATION`] of their site. Those positions are
/// at the lattice's scale, so the indexing starts from its constant
/// ([`fit_calibrated_lattice`]), not from the features' median spacing, which scattered
/// features make short.
pub fn index_features(
    inputs: &[PassInput],
    geometry: &ScanGeometry,
    lattice: &dyn Lattice,
    start: &DistortionModel,
) -> Result<Vec<RegisteredFeature>, DistortionError> {
    let kept: Vec<Vec<usize>> = inputs
        .iter()
        .map(|input| {
            let raw: Vec<[f64; 2]> = input.features.iter().map(|f| [f.x_px, f.y_px]).collect();
            let inside = crate::neighbours::inside_mask(&raw, input.mask);
            (0..raw.len()).filter(|&i| inside[i]).collect()
        })
        .collect();
    let corrected: Vec<Vec<[f64; 2]>> = inputs
        .iter()
        .zip(&kept)
        .map(|(input, kept)| {
            let at = |i: &usize| {
                let f = &input.features[*i];
                start.to_sample(geometry, f.pass, f.x_px, f.y_px)
            };
            kept.iter().map(at).collect()
        })
        .collect();
    let sets: Vec<&[[f64; 2]]> = corrected.iter().map(|c| c.as_slice()).collect();
    let fit = fit_calibrated_lattice(lattice, &sets, &LatticeFitOptions::default())
        .map_err(DistortionError::Indexing)?;
    let limit = MAX_INDEX_DEVIATION * lattice.nearest_neighbour_distance();
    let mut features = Vec::new();
    for (k, (input, kept)) in inputs.iter().zip(&kept).enumerate() {
        for (point, &i) in fit.points[k].iter().zip(kept) {
            if point.deviation_m[0].hypot(point.deviation_m[1])
                > limit * fit.scale[0].max(fit.scale[1])
            {
                continue;
            }
            let f = &input.features[i];
            let time = geometry.acquisition_time(f.pass, f.x_px, f.y_px);
            features.push(RegisteredFeature {
                pass_index: k,
                feature_index: i,
                pass: f.pass,
                controller_m: [f.x_px * geometry.pitch_x(), f.y_px * geometry.pitch_y()],
                time_s: time.since_frame_start,
                line_time_s: time.since_line_start,
                site_m: site_of(lattice, point),
            });
        }
    }
    Ok(features)
}

/// `n·a1 + m·a2 + f_s` of an indexed point, metres.
fn site_of(lattice: &dyn Lattice, point: &IndexedPoint) -> [f64; 2] {
    let [a1, a2] = lattice.primitive_vectors();
    let s = a1 * point.n as f64 + a2 * point.m as f64 + lattice.site_position(point.site);
    [s.x, s.y]
}

/// The rigid placement of the ideal lattice that best fits `corrected` (sample-frame
/// positions of `features`, metres): one rotation θ for all passes and one origin per pass
/// (closed form: Procrustes with known correspondences). Returns θ and the origins.
pub fn place_lattice(
    features: &[RegisteredFeature],
    corrected: &[[f64; 2]],
    passes: usize,
) -> (f64, Vec<[f64; 2]>) {
    let mut sums = vec![[0.0f64; 4]; passes];
    let mut counts = vec![0usize; passes];
    for (f, p) in features.iter().zip(corrected) {
        let s = &mut sums[f.pass_index];
        s[0] += p[0];
        s[1] += p[1];
        s[2] += f.site_m[0];
        s[3] += f.site_m[1];
        counts[f.pass_index] += 1;
    }
    let means: Vec<[f64; 4]> = sums
        .iter()
        .zip(&counts)
        .map(|(s, &n)| {
            let n = n.max(1) as f64;
            [s[0] / n, s[1] / n, s[2] / n, s[3] / n]
        })
        .collect();
    let (mut cross, mut dot) = (0.0, 0.0);
    for (f, p) in features.iter().zip(corrected) {
        let m = means[f.pass_index];
        let (px, py) = (p[0] - m[0], p[1] - m[1]);
        let (ux, uy) = (f.site_m[0] - m[2], f.site_m[1] - m[3]);
        dot += ux * px + uy * py;
        cross += ux * py - uy * px;
    }
    let theta = cross.atan2(dot);
    let (s, c) = theta.sin_cos();
    let origins = means
        .iter()
        .map(|m| [m[0] - (c * m[2] - s * m[3]), m[1] - (s * m[2] + c * m[3])])
        .collect();
    (theta, origins)
}

/// Deviations (metres) of `features` corrected by `model` from the lattice placed at
/// `theta` and `origins`.
pub fn deviations(
    features: &[RegisteredFeature],
    model: &DistortionModel,
    geometry: &ScanGeometry,
    theta: f64,
    origins: &[[f64; 2]],
) -> Vec<[f64; 2]> {
    let (s, c) = theta.sin_cos();
    features
        .iter()
        .map(|f| {
            let p = corrected_position(f, model, geometry);
            let o = origins[f.pass_index];
            let [ux, uy] = f.site_m;
            [
                p[0] - o[0] - (c * ux - s * uy),
                p[1] - o[1] - (s * ux + c * uy),
            ]
        })
        .collect()
}

/// Sample-frame position (metres) of a registered feature under `model`.
pub fn corrected_position(
    f: &RegisteredFeature,
    model: &DistortionModel,
    geometry: &ScanGeometry,
) -> [f64; 2] {
    let d = model.displacement_at(geometry, f.pass, f.time_s, f.line_time_s);
    [f.controller_m[0] + d[0], f.controller_m[1] + d[1]]
}

/// Most rounds of [`register_from`]: index, fit, index again in the new corrected frame.
pub const MAX_INDEX_ROUNDS: usize = 4;

/// Indexes the features of `inputs` in the frame `start` corrects to and registers them;
/// from a rough start (the identity, an affine map), whose first indexing keeps only the
/// features it already puts near their sites, indexes again in the registered frame and
/// registers again while that indexes markedly more features (up to [`MAX_INDEX_ROUNDS`]). Returns the registration and the features of its last indexing.
pub fn register_from(
    inputs: &[PassInput],
    geometry: &ScanGeometry,
    lattice: &dyn Lattice,
    start: &DistortionModel,
    quality: StartQuality,
    options: &FitOptions,
) -> Result<(Registration, Vec<RegisteredFeature>), DistortionError> {
    let mut features = index_features(inputs, geometry, lattice, start)?;
    let mut registration = register(&features, geometry, start, quality, options)?;
    // A fitted start already indexes every feature it can.
    let rounds = match quality {
        StartQuality::Fitted => 1,
        StartQuality::Rough => MAX_INDEX_ROUNDS,
    };
    for _ in 1..rounds {
        let Ok(again) = index_features(inputs, geometry, lattice, &registration.model) else {
            break;
        };
        if (again.len() as f64) < 1.02 * features.len() as f64 {
            break;
        }
        let fitted = StartQuality::Fitted;
        let Ok(better) = register(&again, geometry, &registration.model, fitted, options) else {
            break;
        };
        features = again;
        registration = better;
    }
    Ok((registration, features))
}

/// Creep time constants tried from a rough start, in frame durations: `t0` is the one
/// strongly non-linear parameter, and a fit started far from it settles in another basin.
const T0_STARTS_FRAMES: [f64; 6] = [0.003, 0.01, 0.03, 0.1, 0.3, 1.0];

/// How good the start of [`register`] is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StartQuality {
    /// A fitted model (the local route's): one fit from it.
    Fitted,
    /// A rough one (the identity, an affine map): fits from several creep time constants,
    /// the best kept.
    Rough,
}

/// Fits the model to the positions of `features` (from [`index_features`]), starting from
/// `start` (whose hysteresis law family is kept when `options.hysteresis` is that family;
/// [`HysteresisChoice::Best`] fits `start`'s family).
pub fn register(
    features: &[RegisteredFeature],
    geometry: &ScanGeometry,
    start: &DistortionModel,
    quality: StartQuality,
    options: &FitOptions,
) -> Result<Registration, DistortionError> {
    if features.len() < MIN_REGISTERED {
        return Err(DistortionError::TooFewFeatures {
            what: "global registration",
            found: features.len(),
            needed: MIN_REGISTERED,
        });
    }
    let passes = features.iter().map(|f| f.pass_index + 1).max().unwrap_or(1);
    let features = &thin(features, MAX_FITTED);
    let choice = options.hysteresis.resolved(&start.hysteresis);
    let problem = RegistrationProblem::new(features, geometry, passes, choice);
    let corrected: Vec<[f64; 2]> = features
        .iter()
        .map(|f| corrected_position(f, start, geometry))
        .collect();
    let (theta, origins) = place_lattice(features, &corrected, passes);
    let p0 = match quality {
        StartQuality::Fitted => problem.start(start, theta, &origins),
        StartQuality::Rough => best_t0_start(&problem, start, theta, &origins)?,
    };
    let (fit, weights) = position_irls(
        &problem,
        (problem.rows(), problem.features.len()),
        problem.plain_weights(),
        p0,
        options.robust_rounds,
        "global registration",
        None,
    )?;
    problem.result(&fit, &weights)
}

/// The parameters of the plain least-squares fit with the smallest squared error among
/// those started at each of [`T0_STARTS_FRAMES`] (and at `start`'s own `t0`).
fn best_t0_start(
    problem: &RegistrationProblem,
    start: &DistortionModel,
    theta: f64,
    origins: &[[f64; 2]],
) -> Result<Vec<f64>, DistortionError> {
    let frame = problem.geometry.frame_duration();
    let mut t0s: Vec<f64> = T0_STARTS_FRAMES.iter().map(|f| f * frame).collect();
    t0s.push(start.drift.t0_s);
    let lm = LmOptions {
        max_iterations: 100,
        ..LmOptions::default()
    };
    let fits: Vec<ResidualFit> = t0s
        .iter()
        .filter_map(|&t0| {
            let mut from = start.clone();
            from.drift.t0_s = t0;
            let p0 = problem.start(&from, theta, origins);
            fit_residuals(problem, problem.rows(), &p0, &problem.plain_weights(), &lm)
        })
        .collect();
    let cost = |f: &ResidualFit| f.residuals.iter().map(|r| r * r).sum::<f64>();
    fits.into_iter()
        .filter(|f| cost(f).is_finite())
        .min_by(|a, b| cost(a).total_cmp(&cost(b)))
        .map(|f| f.params)
        .ok_or(DistortionError::FitFailed("global registration"))
}

/// The registration as a least-squares problem; parameters (nm units)
/// `[θ, o_0x, o_0y, …, v_x, a_x, C_x, v_y, a_y, C_y, q(t0), hysteresis…]`, residuals the x
/// deviations of every feature, then the y deviations.
struct RegistrationProblem<'a> {
    features: &'a [RegisteredFeature],
    geometry: &'a ScanGeometry,
    passes: usize,
    choice: HysteresisChoice,
    t0_map: LogisticLog,
    /// `−v_f·ê_trace`, nm/s: the displacement per second of hysteresis lag.
    lag_direction: [f64; 2],
}

impl<'a> RegistrationProblem<'a> {
    fn new(
        features: &'a [RegisteredFeature],
        geometry: &'a ScanGeometry,
        passes: usize,
        choice: HysteresisChoice,
    ) -> Self {
        let (trace_fast, _) = scan_basis(geometry, ScanPass::Trace);
        let v = geometry.fast_speed() * NM;
        RegistrationProblem {
            features,
            geometry,
            passes,
            choice,
            t0_map: LogisticLog::for_frame(geometry.line_scan_time(), geometry.frame_duration()),
            lag_direction: [-v * trace_fast[0], -v * trace_fast[1]],
        }
    }

    /// Index of the first drift parameter.
    fn drift_at(&self) -> usize {
        1 + 2 * self.passes
    }

    /// Residuals: x then y deviations of every feature (nm), then the creep prior's two.
    fn rows(&self) -> usize {
        2 * self.features.len() + 2
    }

    /// The weights before the data's own scale is known: positions as if to 10 pm
    /// (`1/σ²`, nm⁻²), the prior's own on the creep amplitudes.
    fn plain_weights(&self) -> Vec<f64> {
        let mut w = vec![1e4; self.rows()];
        let m = self.features.len();
        w[2 * m] = 1.0;
        w[2 * m + 1] = 1.0;
        w
    }

    fn start(&self, model: &DistortionModel, theta: f64, origins: &[[f64; 2]]) -> Vec<f64> {
        let mut p = vec![theta];
        for o in origins {
            p.extend([o[0] * NM, o[1] * NM]);
        }
        let d = &model.drift;
        for k in 0..2 {
            p.extend([
                d.velocity_m_per_s[k] * NM,
                d.acceleration_m_per_s2[k] * NM,
                d.creep_m[k] * NM,
            ]);
        }
        p.push(self.t0_map.parameter(d.t0_s));
        p.extend(law_parameters(
            self.choice,
            &model.hysteresis,
            self.geometry.line_scan_time(),
        ));
        p
    }

    fn model(&self, p: &[f64]) -> DistortionModel {
        let at = self.drift_at();
        let d = &p[at..];
        DistortionModel::new(
            DriftCreep {
                velocity_m_per_s: [d[0] / NM, d[3] / NM],
                acceleration_m_per_s2: [d[1] / NM, d[4] / NM],
                creep_m: [d[2] / NM, d[5] / NM],
                t0_s: self.t0_map.t0(d[6]),
            },
            hysteresis_law(self.choice, self.geometry.line_scan_time(), &d[7..]),
        )
    }

    fn result(&self, fit: &ResidualFit, weights: &[f64]) -> Result<Registration, DistortionError> {
        let p = &fit.params;
        if !p.iter().all(|v| v.is_finite()) {
            return Err(DistortionError::FitFailed("global registration"));
        }
        let n = p.len();
        let sigma = scaled_sigmas(fit, weights, n);
        let mut model = self.model(p);
        let at = self.drift_at();
        model.parameters = drift_parameters(&p[at..at + 7], &sigma[at..at + 7], self.t0_map);
        model.parameters.extend(hysteresis_parameters(
            self.choice,
            &p[at + 7..],
            &sigma[at + 7..],
        ));
        let inverse = fit.inverse_normal();
        let drift_block = inverse
            .as_ref()
            .map(|c| c.view((at, at), (7, 7)).clone_owned());
        model.diagnostics = drift_diagnostics(&drift_block, p[at + 6], self.t0_map);
        model.parameter_correlation = correlations(&inverse, at, n - at).unwrap_or_default();
        let m = self.features.len();
        let robust = mad_sigma_about(&fit.residuals[..2 * m], 0.0).unwrap_or(f64::NAN);
        Ok(Registration {
            model,
            lattice_angle_rad: p[0],
            origins_m: (0..self.passes)
                .map(|k| [p[1 + 2 * k] / NM, p[2 + 2 * k] / NM])
                .collect(),
            rms_deviation_m: robust * std::f64::consts::SQRT_2 / NM,
            features: m,
        })
    }
}

impl Residuals for RegistrationProblem<'_> {
    fn residuals(&self, p: &[f64], r: &mut [f64]) {
        let model = self.model(p);
        let m = self.features.len();
        let (s, c) = p[0].sin_cos();
        let (positions, prior) = r.split_at_mut(2 * m);
        let at = self.drift_at();
        prior.copy_from_slice(&[p[at + 2] / CREEP_PRIOR_NM, p[at + 5] / CREEP_PRIOR_NM]);
        let (rx, ry) = positions.split_at_mut(m);
        rx.par_iter_mut()
            .zip(ry.par_iter_mut())
            .zip(self.features.par_iter())
            .for_each(|((rx, ry), f)| {
                let [x, y] = corrected_position(f, &model, self.geometry);
                let (ox, oy) = (p[1 + 2 * f.pass_index], p[2 + 2 * f.pass_index]);
                let [ux, uy] = [f.site_m[0] * NM, f.site_m[1] * NM];
                *rx = x * NM - ox - (c * ux - s * uy);
                *ry = y * NM - oy - (s * ux + c * uy);
            });
    }

    fn jacobian(&self, p: &[f64], _r0: &[f64]) -> DMatrix<f64> {
        let (m, n) = (self.features.len(), p.len());
        let at = self.drift_at();
        let law = hysteresis_law(self.choice, self.geometry.line_scan_time(), &p[at + 7..]);
        let hysteresis_count = n - at - 7;
        let line_time = self.geometry.line_scan_time();
        let t0 = self.t0_map.t0(p[at + 6]);
        let dt0 = self.t0_map.derivative(p[at + 6]);
        let (creep_x, creep_y) = (p[at + 2], p[at + 5]);
        let (s, c) = p[0].sin_cos();
        let mut end = [0.0; 5];
        law_gradient(
            &law,
            line_time,
            Quantity::ExcessIntegral,
            &mut end[..hysteresis_count],
        );
        // Row-major: the x rows of every feature, then the y rows, then the prior's two.
        let mut rows = vec![0.0; self.rows() * n];
        let (positions, prior) = rows.split_at_mut(2 * m * n);
        prior[at + 2] = 1.0 / CREEP_PRIOR_NM;
        prior[n + at + 5] = 1.0 / CREEP_PRIOR_NM;
        let (x_rows, y_rows) = positions.split_at_mut(m * n);
        x_rows
            .par_chunks_mut(n)
            .zip(y_rows.par_chunks_mut(n))
            .zip(self.features.par_iter())
            .for_each(|((row_x, row_y), f)| {
                let [ux, uy] = [f.site_m[0] * NM, f.site_m[1] * NM];
                row_x[0] = s * ux + c * uy;
                row_y[0] = -(c * ux - s * uy);
                row_x[1 + 2 * f.pass_index] = -1.0;
                row_y[2 + 2 * f.pass_index] = -1.0;
                let t = f.time_s;
                let log = (t / t0).ln_1p();
                let dlog = -t / (t0 * (t0 + t)) * dt0;
                row_x[at..at + 3].copy_from_slice(&[t, 0.5 * t * t, log]);
                row_y[at + 3..at + 6].copy_from_slice(&[t, 0.5 * t * t, log]);
                row_x[at + 6] = creep_x * dlog;
                row_y[at + 6] = creep_y * dlog;
                let mut lag = [0.0; 5];
                law_gradient(
                    &law,
                    f.line_time_s,
                    Quantity::ExcessIntegral,
                    &mut lag[..hysteresis_count],
                );
                for j in 0..hysteresis_count {
                    let g = match f.pass {
                        ScanPass::Trace => lag[j],
                        ScanPass::Retrace => end[j] - lag[j],
                    };
                    row_x[at + 7 + j] = self.lag_direction[0] * g;
                    row_y[at + 7 + j] = self.lag_direction[1] * g;
                }
            });
        DMatrix::from_row_slice(self.rows(), n, &rows)
    }
}
