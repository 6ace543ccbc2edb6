//! Levenberg–Marquardt fit of a [`GlobalModel`] to the observations: weighted residuals
//! `r/σ_axis`, numerical derivatives for effect parameters (in the fit space of
//! [`crate::model::Transform`]), analytic ones for the lattice, uncertainties from
//! `χ²/dof·(JᵀJ)⁻¹` (pseudo-inverse, so degenerate directions get no spurious precision).

use dhct_scan::ScanGeometry;
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use crate::DiagnoseError;
use crate::data::Observation;
use crate::model::{GlobalModel, Transform, term_displacements, transform_of};

/// A fitted model with what the ranking needs.
#[derive(Debug, Clone)]
pub(crate) struct Fitted {
    pub model: GlobalModel,
    /// Unweighted residuals, metres, sample frame.
    pub residuals: Vec<[f64; 2]>,
    /// Weighted Jacobian at the solution, rows `[x0, y0, x1, y1, …]`.
    pub jacobian: DMatrix<f64>,
    /// Covariance of the free parameters in fit space (scaled by `max(χ²/dof, 1)`).
    pub covariance: DMatrix<f64>,
}

/// One fitted parameter of an effect, with its 1σ uncertainty (SI units).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FittedParameter {
    /// The effect's config kind (e.g. `"tip-change"`).
    pub effect: String,
    /// The parameter's name as in the simulator's effect (unit in the name, SI).
    pub name: String,
    /// Value (SI).
    pub value: f64,
    /// 1σ uncertainty (SI); `None` when held fixed (e.g. a change time chosen on a grid).
    pub sigma: Option<f64>,
}

pub(crate) fn weighted(residuals: &[[f64; 2]], sigma: [f64; 2]) -> DVector<f64> {
    DVector::from_iterator(
        2 * residuals.len(),
        residuals
            .iter()
            .flat_map(|r| [r[0] / sigma[0], r[1] / sigma[1]]),
    )
}

/// Weighted Jacobian `∂(r/σ)/∂u` of every free parameter.
pub(crate) fn jacobian(
    model: &GlobalModel,
    geometry: &ScanGeometry,
    observations: &[Observation],
    sigma: [f64; 2],
) -> DMatrix<f64> {
    let n = observations.len();
    let p = model.free_count();
    let mut j = DMatrix::zeros(2 * n, p);
    let mut column = 0;
    for term in &model.terms {
        let names = term.effect.parameter_names();
        let base_p = term.effect.parameters();
        let base_d = term_displacements(term.effect.as_ref(), geometry, observations);
        for (k, name) in names.iter().enumerate() {
            if !term.free[k] {
                continue;
            }
            let (forward, h) = match transform_of(name) {
                Transform::Log => (base_p[k] * 1e-5f64.exp(), 1e-5),
                Transform::Linear { typical } => {
                    let h = 1e-5 * base_p[k].abs().max(typical);
                    (base_p[k] + h, h)
                }
            };
            let mut trial = base_p.clone();
            trial[k] = forward;
            let (effect, h) = match term.effect.with_parameters(&trial) {
                Some(e) => (e, h),
                None => {
                    // At a bound: step the other way.
                    trial[k] = match transform_of(name) {
                        Transform::Log => base_p[k] * (-1e-5f64).exp(),
                        Transform::Linear { .. } => 2.0 * base_p[k] - forward,
                    };
                    match term.effect.with_parameters(&trial) {
                        Some(e) => (e, -h),
                        None => {
                            column += 1;
                            continue;
                        }
                    }
                }
            };
            let d = term_displacements(effect.as_ref(), geometry, observations);
            for i in 0..n {
                j[(2 * i, column)] = (d[i][0] - base_d[i][0]) / h / sigma[0];
                j[(2 * i + 1, column)] = (d[i][1] - base_d[i][1]) / h / sigma[1];
            }
            column += 1;
        }
    }
    for (i, o) in observations.iter().enumerate() {
        for (k, dsite) in model
            .lattice
            .derivatives(o.lattice_vector_m)
            .iter()
            .enumerate()
        {
            j[(2 * i, column + k)] = -dsite[0] / sigma[0];
            j[(2 * i + 1, column + k)] = -dsite[1] / sigma[1];
        }
    }
    j
}

/// Pseudo-inverse of a symmetric positive semi-definite matrix (relative cut 1e-12).
pub(crate) fn pinv_sym(a: &DMatrix<f64>) -> DMatrix<f64> {
    pinv_sym_cut(a, 1e-12)
}

/// Pseudo-inverse with eigenvalues below `cut × max` (after unit-diagonal scaling) dropped.
pub(crate) fn pinv_sym_cut(a: &DMatrix<f64>, cut: f64) -> DMatrix<f64> {
    let n = a.nrows();
    // Scale to unit diagonal for conditioning.
    let d: Vec<f64> = (0..n)
        .map(|k| {
            let v = a[(k, k)];
            if v > 0.0 { 1.0 / v.sqrt() } else { 1.0 }
        })
        .collect();
    let scaled = DMatrix::from_fn(n, n, |r, c| a[(r, c)] * d[r] * d[c]);
    let eig = scaled.symmetric_eigen();
    let max = eig.eigenvalues.iter().cloned().fold(0.0, f64::max);
    let mut inv = DMatrix::zeros(n, n);
    for k in 0..n {
        let l = eig.eigenvalues[k];
        if l > cut * max {
            let v = eig.eigenvectors.column(k);
            inv += v * v.transpose() / l;
        }
    }
    DMatrix::from_fn(n, n, |r, c| inv[(r, c)] * d[r] * d[c])
}

/// Fits `model` to `observations` (weights `1/σ` per axis).
pub(crate) fn fit(
    model: GlobalModel,
    geometry: &ScanGeometry,
    observations: &[Observation],
    sigma: [f64; 2],
    max_iterations: usize,
) -> Result<Fitted, DiagnoseError> {
    let label = || {
        model
            .terms
            .iter()
            .map(|t| t.label.clone())
            .collect::<Vec<_>>()
            .join(" + ")
    };
    let n_res = 2 * observations.len();
    let p = model.free_count();
    if n_res <= p + 2 {
        return Err(DiagnoseError::TooFewFeatures {
            what: "position-level fit",
            found: observations.len(),
            needed: p / 2 + 2,
        });
    }
    let mut current = model.clone();
    let mut u = current.free_vector();
    let mut r = weighted(&current.residuals(geometry, observations), sigma);
    let mut chi2 = r.norm_squared();
    if !chi2.is_finite() {
        return Err(DiagnoseError::FitFailed {
            model: label(),
            reason: "non-finite residuals at the start".into(),
        });
    }
    let mut lambda = 1e-3;
    let mut jac = jacobian(&current, geometry, observations, sigma);
    let mut small_steps = 0;
    for _ in 0..max_iterations {
        let jt = jac.transpose();
        let a = &jt * &jac;
        let g = &jt * &r;
        let mut improved = false;
        for _ in 0..12 {
            let mut damped = a.clone();
            for k in 0..p {
                damped[(k, k)] += lambda * a[(k, k)].max(1e-12);
            }
            let Some(delta) = damped.clone().cholesky().map(|c| c.solve(&(-&g))) else {
                lambda *= 10.0;
                continue;
            };
            let trial_u: Vec<f64> = u.iter().zip(delta.iter()).map(|(a, b)| a + b).collect();
            if let Some(trial) = current.with_free_vector(&trial_u) {
                let trial_r = weighted(&trial.residuals(geometry, observations), sigma);
                let trial_chi2 = trial_r.norm_squared();
                if trial_chi2.is_finite() && trial_chi2 <= chi2 {
                    let gain = chi2 - trial_chi2;
                    current = trial;
                    u = trial_u;
                    r = trial_r;
                    if gain <= 1e-9 * chi2.max(1.0) {
                        small_steps += 1;
                    } else {
                        small_steps = 0;
                    }
                    chi2 = trial_chi2;
                    lambda = (lambda * 0.2).max(1e-9);
                    improved = small_steps < 3;
                    break;
                }
            }
            lambda *= 10.0;
        }
        if !improved {
            break;
        }
        jac = jacobian(&current, geometry, observations, sigma);
    }
    let jt = jac.transpose();
    let dof = (n_res - p) as f64;
    let covariance = pinv_sym(&(&jt * &jac)) * (chi2 / dof).max(1.0);
    Ok(Fitted {
        residuals: current.residuals(geometry, observations),
        model: current,
        jacobian: jac,
        covariance,
    })
}

impl Fitted {
    /// The free effect parameters with uncertainties (SI), skipping terms before `from`.
    pub fn parameters(&self, from: usize) -> Vec<FittedParameter> {
        let mut out = Vec::new();
        let mut k = 0;
        for (index, term) in self.model.terms.iter().enumerate() {
            let names = term.effect.parameter_names();
            for (j, (name, value)) in names.iter().zip(term.effect.parameters()).enumerate() {
                let sigma = if term.free[j] {
                    let su = self.covariance[(k, k)].max(0.0).sqrt();
                    k += 1;
                    Some(match transform_of(name) {
                        Transform::Log => value * su,
                        Transform::Linear { .. } => su,
                    })
                } else {
                    None
                };
                if index >= from {
                    out.push(FittedParameter {
                        effect: term.effect.name().to_string(),
                        name: name.to_string(),
                        value,
                        sigma,
                    });
                }
            }
        }
        out
    }
}
