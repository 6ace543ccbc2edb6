//! Levenberg–Marquardt fit of a [`GlobalModel`] to the observations: weighted residuals
//! `r/σ_axis`, numerical derivatives for effect parameters (in the fit space of
//! [`crate::model::global::Transform`]), analytic ones for the lattice, uncertainties from
//! `χ²/dof·(JᵀJ)⁻¹` (pseudo-inverse, so degenerate directions get no spurious precision).

use dhct_numerics::linalg::pseudo_inverse_symmetric;
use dhct_numerics::lm::{LmOptions, ResidualProblem, Residuals, minimise};
use dhct_scan::ScanGeometry;
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::DiagnoseError;
use crate::model::data::{Observation, whiten};
use crate::model::global::{GlobalModel, Transform, term_displacements};

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

impl FittedParameter {
    /// The SI unit its name ends with (`velocity_x_m_per_s` → `m/s`); empty for a ratio.
    pub fn unit(&self) -> &'static str {
        const SUFFIXES: [(&str, &str); 6] = [
            ("_m_per_s2", "m/s^2"),
            ("_m_per_s", "m/s"),
            ("_m", "m"),
            ("_s", "s"),
            ("_hz", "Hz"),
            ("_rad", "rad"),
        ];
        SUFFIXES
            .iter()
            .find(|(suffix, _)| self.name.ends_with(suffix))
            .map_or("", |(_, unit)| unit)
    }
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
        let base_p = term.effect.parameters();
        let base_d = term_displacements(term.effect.as_ref(), geometry, observations);
        for (k, t) in term.effect.transforms().iter().enumerate() {
            if !term.free[k] {
                continue;
            }
            let u = t.fit_value_of(base_p[k]);
            let h = t.step(base_p[k]);
            let mut trial = base_p.clone();
            trial[k] = t.parameter_of(u + h);
            let (effect, h) = match term.effect.with_parameters(&trial) {
                Some(e) => (e, h),
                None => {
                    // At a bound: step the other way.
                    trial[k] = t.parameter_of(u - h);
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
            let dsite = whiten(&o.whitening, *dsite);
            j[(2 * i, column + k)] = -dsite[0] / sigma[0];
            j[(2 * i + 1, column + k)] = -dsite[1] / sigma[1];
        }
    }
    j
}

/// Pseudo-inverse of a symmetric positive semi-definite matrix (relative cut 1e-12).
pub(crate) fn pinv_sym(a: &DMatrix<f64>) -> DMatrix<f64> {
    pseudo_inverse_symmetric(a, 1e-12)
}

/// The model's weighted residuals `r/σ_axis` as a function of its free parameters, for the
/// shared Levenberg–Marquardt; parameters outside the model's domain give NaN residuals.
struct ModelResiduals<'a> {
    model: &'a GlobalModel,
    geometry: &'a ScanGeometry,
    observations: &'a [Observation],
    sigma: [f64; 2],
}

impl Residuals for ModelResiduals<'_> {
    fn residuals(&self, u: &[f64], r: &mut [f64]) {
        match self.model.with_free_vector(u) {
            Some(model) => {
                let w = weighted(
                    &model.residuals(self.geometry, self.observations),
                    self.sigma,
                );
                r.copy_from_slice(w.as_slice());
            }
            None => r.fill(f64::NAN),
        }
    }

    fn jacobian(&self, u: &[f64], _r0: &[f64]) -> DMatrix<f64> {
        let model = self
            .model
            .with_free_vector(u)
            .expect("the driver asks for Jacobians only where the residuals were finite");
        jacobian(&model, self.geometry, self.observations, self.sigma)
    }
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
    let residuals = ModelResiduals {
        model: &model,
        geometry,
        observations,
        sigma,
    };
    let mut problem = ResidualProblem::new(&residuals, n_res, vec![1.0; n_res]);
    let options = LmOptions {
        max_iterations,
        lambda_down: 0.2,
        min_lambda: 1e-9,
        relative_decrease: 1e-9,
        stalled_steps: 3,
        relative_step: 0.0,
        ..LmOptions::default()
    };
    let failed = |reason: &str| DiagnoseError::FitFailed {
        model: label(),
        reason: reason.into(),
    };
    let fit = minimise(&mut problem, &model.free_vector(), &options)
        .ok_or_else(|| failed("non-finite residuals at the start"))?;
    let current = model
        .with_free_vector(&fit.params)
        .ok_or_else(|| failed("the optimum left the model's domain"))?;
    let jacobian = problem.jacobian_at(&fit.params);
    let dof = (n_res - p) as f64;
    let covariance = pinv_sym(&fit.normal.jtwj) * (fit.normal.cost / dof).max(1.0);
    Ok(Fitted {
        residuals: current.residuals(geometry, observations),
        model: current,
        jacobian,
        covariance,
    })
}

/// The label of the base model's creep term, whose `t0` [`fit_profiled`] profiles.
pub(crate) const BASE_CREEP: &str = "creep";

/// Fits `model` with the base creep's `t0` (term [`BASE_CREEP`], held fixed inside each
/// fit) chosen by profiling: a log-spaced grid over `t0_bounds` (seconds) plus the current
/// value, each fitted in parallel, then a parabola through the best and its neighbours in
/// `ln t0`. Freeing `t0` in the fit itself does not converge: with drift velocity and
/// acceleration free, `C·ln(1 + t/t0)` has a valley towards large `t0` (coefficient and
/// `t0` growing together) along which Levenberg–Marquardt crawls for hundreds of
/// iterations and stops anywhere on it. Without such a term, a plain [`fit`].
pub(crate) fn fit_profiled(
    model: GlobalModel,
    geometry: &ScanGeometry,
    observations: &[Observation],
    sigma: [f64; 2],
    max_iterations: usize,
    t0_bounds: (f64, f64),
) -> Result<Fitted, DiagnoseError> {
    let Some(slot) = creep_t0_slot(&model) else {
        return fit(model, geometry, observations, sigma, max_iterations);
    };
    let (lo, hi) = (t0_bounds.0.ln(), t0_bounds.1.ln());
    const GRID: usize = 10;
    let current = model.terms[slot.0].effect.parameters()[slot.1];
    let mut grid: Vec<f64> = (0..GRID)
        .map(|k| lo + (hi - lo) * k as f64 / (GRID - 1) as f64)
        .collect();
    if current.is_finite() && current > 0.0 {
        grid.push(current.ln().clamp(lo, hi));
    }
    // Inside the profile, the shapes (onsets, time constants, phases) of terms beyond the
    // base model are held: with the base creep changed under them a free shape can escape
    // to where its term does nothing (an onset after the frame end) and stay there.
    let held = hold_shapes(&model);
    let run = |ln_t0: f64| -> Option<(f64, Fitted)> {
        let m = with_t0(&held, slot, ln_t0.exp(), geometry, observations)?;
        let f = fit(m, geometry, observations, sigma, max_iterations).ok()?;
        let chi2 = weighted(&f.residuals, sigma).norm_squared();
        chi2.is_finite().then_some((chi2, f))
    };
    let fits: Vec<(f64, Option<(f64, Fitted)>)> = grid.par_iter().map(|&g| (g, run(g))).collect();
    let mut points: Vec<(f64, f64)> = fits
        .iter()
        .filter_map(|(g, r)| r.as_ref().map(|(c, _)| (*g, *c)))
        .collect();
    points.sort_by(|a, b| a.0.total_cmp(&b.0));
    let Some(best) = fits
        .into_iter()
        .filter_map(|(_, r)| r)
        .min_by(|a, b| a.0.total_cmp(&b.0))
    else {
        // Every grid point failed: report the plain fit's error.
        return fit(model, geometry, observations, sigma, max_iterations);
    };
    let best = refined_minimum(&run, &points, best);
    if !same_free(&held, &model) {
        let mut m = best.1.model;
        for (term, original) in m.terms.iter_mut().zip(&model.terms) {
            term.free.clone_from(&original.free);
        }
        return fit(m, geometry, observations, sigma, max_iterations);
    }
    Ok(best.1)
}

/// A profiled fit `(χ², fit)`, or `None` where it failed.
type ProfilePoint = Option<(f64, Fitted)>;

/// The profile's minimum refined from the best grid point `best` (`points`: the grid's
/// `(ln t0, χ²)`, sorted): a parabola through it and its neighbours, then narrower ones
/// about the vertex until χ² improves by less than [`PROFILE_CONVERGED_CHI2`]. An
/// exponential creep's τ must be right to within a per cent (a 4 % error of a 0.4 nm
/// relaxation leaves several pm), which one parabola over the grid's factor-2.5 steps does
/// not reach. `run(ln t0)` fits at one point.
fn refined_minimum(
    run: &(impl Fn(f64) -> ProfilePoint + Sync),
    points: &[(f64, f64)],
    mut best: (f64, Fitted),
) -> (f64, Fitted) {
    let Some(i) = points.iter().position(|p| p.1 == best.0) else {
        return best;
    };
    if i == 0 || i + 1 >= points.len() {
        return best;
    }
    let Some(vertex) = parabola_vertex([points[i - 1], points[i], points[i + 1]]) else {
        return best;
    };
    let mut centre = points[i].0;
    if let Some(r) = run(vertex)
        && r.0 < best.0
    {
        (best, centre) = (r, vertex);
    }
    let mut half_width = 0.125 * (points[i + 1].0 - points[i - 1].0);
    for _ in 0..PROFILE_REFINEMENTS {
        let before = best.0;
        let xs = [centre - half_width, centre + half_width];
        let sides: Vec<ProfilePoint> = xs.par_iter().map(|&g| run(g)).collect();
        let (Some(lo), Some(hi)) = (&sides[0], &sides[1]) else {
            break;
        };
        let vertex = parabola_vertex([(xs[0], lo.0), (centre, best.0), (xs[1], hi.0)]);
        for (x, side) in xs.into_iter().zip(sides) {
            if let Some(r) = side
                && r.0 < best.0
            {
                (best, centre) = (r, x);
            }
        }
        if let Some(v) = vertex
            && let Some(r) = run(v)
            && r.0 < best.0
        {
            (best, centre) = (r, v);
        }
        if before - best.0 < PROFILE_CONVERGED_CHI2 {
            break;
        }
        half_width *= 0.25;
    }
    best
}

/// Narrower parabolas tried about the profile's first vertex, at most.
const PROFILE_REFINEMENTS: usize = 3;

/// χ² improvement of a refinement below which the profile has converged.
const PROFILE_CONVERGED_CHI2: f64 = 0.5;

/// The vertex of the parabola through three points `(x, y)` (`x` distinct), clamped to
/// their range; `None` unless it opens upwards.
fn parabola_vertex(points: [(f64, f64); 3]) -> Option<f64> {
    let [(x0, y0), (x1, y1), (x2, y2)] = points;
    let denom = (x0 - x1) * (x0 - x2) * (x1 - x2);
    let a = (x2 * (y1 - y0) + x1 * (y0 - y2) + x0 * (y2 - y1)) / denom;
    let b = (x2 * x2 * (y0 - y1) + x1 * x1 * (y2 - y0) + x0 * x0 * (y1 - y2)) / denom;
    let (lo, hi) = (x0.min(x2), x0.max(x2));
    (a > 0.0 && a.is_finite()).then(|| (-b / (2.0 * a)).clamp(lo, hi))
}

/// Labels of the base model's terms (their parameters stay free while `t0` is profiled).
const BASE_TERMS: [&str; 3] = ["thermal-drift", BASE_CREEP, "fast-hysteresis"];

/// `model` with every parameter of a term beyond the base fixed unless it enters the
/// displacement as an amplitude (a linear parameter whose name is no time, phase or
/// frequency).
fn hold_shapes(model: &GlobalModel) -> GlobalModel {
    let mut m = model.clone();
    for term in m.terms.iter_mut() {
        if BASE_TERMS.contains(&term.label.as_str()) {
            continue;
        }
        let names = term.effect.parameter_names();
        let transforms = term.effect.transforms();
        for (k, name) in names.iter().enumerate() {
            let shape = !matches!(transforms[k], Transform::Linear { .. })
                || name.ends_with("_s")
                || name.ends_with("_rad")
                || name.ends_with("_hz");
            if shape {
                term.free[k] = false;
            }
        }
    }
    m
}

fn same_free(a: &GlobalModel, b: &GlobalModel) -> bool {
    a.terms.iter().zip(&b.terms).all(|(x, y)| x.free == y.free)
}

/// `(term, parameter)` index of the base creep's `t0` (its `τ` when the creep is an
/// exponential relaxation).
fn creep_t0_slot(model: &GlobalModel) -> Option<(usize, usize)> {
    let term = model.terms.iter().position(|t| t.label == BASE_CREEP)?;
    let k = model.terms[term]
        .effect
        .parameter_names()
        .iter()
        .position(|n| *n == "t0_s" || *n == "time_constant_s")?;
    Some((term, k))
}

/// `model` with the base creep's `t0` (or `τ`) set to `t0` and its coefficients (the
/// parameters named `coefficient_*` or `amplitude_*`, entering linearly) re-solved per axis by least squares with
/// everything else held: the previous coefficients belong to the previous `t0`, and with
/// them a refit can start far off and stall.
fn with_t0(
    model: &GlobalModel,
    slot: (usize, usize),
    t0: f64,
    geometry: &ScanGeometry,
    observations: &[Observation],
) -> Option<GlobalModel> {
    let mut m = model.clone();
    let names = m.terms[slot.0].effect.parameter_names();
    let coefficients: Vec<usize> = (0..names.len())
        .filter(|&k| names[k].starts_with("coefficient") || names[k].starts_with("amplitude"))
        .collect();
    let mut p = m.terms[slot.0].effect.parameters();
    p[slot.1] = t0;
    for &k in &coefficients {
        p[k] = 0.0;
    }
    m.terms[slot.0].effect = m.terms[slot.0].effect.with_parameters(&p)?;
    if coefficients.len() == 2 {
        let without = m.residuals(geometry, observations);
        let mut unit = p.clone();
        for &k in &coefficients {
            unit[k] = 1e-10;
        }
        let shape = term_displacements(
            m.terms[slot.0].effect.with_parameters(&unit)?.as_ref(),
            geometry,
            observations,
        );
        for (axis, &k) in coefficients.iter().enumerate() {
            let (num, den) = without
                .iter()
                .zip(&shape)
                .fold((0.0, 0.0), |(n, d), (r, f)| {
                    (n + r[axis] * f[axis], d + f[axis] * f[axis])
                });
            if den > 0.0 {
                p[k] = -1e-10 * num / den;
            }
        }
        m.terms[slot.0].effect = m.terms[slot.0].effect.with_parameters(&p)?;
    }
    Some(m)
}

impl Fitted {
    /// The free effect parameters with uncertainties (SI), skipping terms before `from`.
    pub fn parameters(&self, from: usize) -> Vec<FittedParameter> {
        let mut out = Vec::new();
        let mut k = 0;
        for (index, term) in self.model.terms.iter().enumerate() {
            let names = term.effect.parameter_names();
            let transforms = term.effect.transforms();
            for (j, (name, value)) in names.iter().zip(term.effect.parameters()).enumerate() {
                let sigma = if term.free[j] {
                    let su = self.covariance[(k, k)].max(0.0).sqrt();
                    k += 1;
                    Some(transforms[j].slope(value) * su)
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
