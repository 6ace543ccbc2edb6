//! One Levenberg–Marquardt driver for weighted, optionally bounded least squares.
//!
//! A problem says what its cost and normal equations are ([`LmProblem`]); the driver owns
//! the damping, the step acceptance and the stopping rules ([`LmOptions`]). Problems given
//! as residuals use [`ResidualProblem`] (forward-difference or analytic Jacobian); a hot loop
//! may form `JᵀWJ`, `JᵀWr` and the cost in one pass and implement [`LmProblem`] directly.

use crate::dot::dot;
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

/// `JᵀWJ`, `JᵀWr` and the cost `rᵀWr` at one parameter vector.
#[derive(Debug, Clone)]
pub struct NormalEquations {
    /// `JᵀWJ` (n × n).
    pub jtwj: DMatrix<f64>,
    /// `JᵀWr` (n).
    pub jtwr: DVector<f64>,
    /// `Σ wᵢ rᵢ²`.
    pub cost: f64,
}

/// A least-squares problem for [`minimise`].
pub trait LmProblem {
    /// The cost `Σ wᵢ rᵢ²` at `p`; `None` (or a non-finite value) when `p` is outside the
    /// problem's domain.
    fn cost(&mut self, p: &[f64]) -> Option<f64>;

    /// The normal equations at `p`, a point whose cost was finite.
    fn normal_equations(&mut self, p: &[f64]) -> NormalEquations;

    /// Moves a trial point into the feasible set (bounds, constraints); `false` when it
    /// cannot be, and the step is then damped further.
    fn project(&self, _p: &mut [f64]) -> bool {
        true
    }

    /// A problem-specific convergence test on an accepted step from `previous` to `next`
    /// (e.g. "the centre moved less than 10⁻³ px"); the generic tests are in [`LmOptions`].
    fn converged(&self, _previous: &[f64], _next: &[f64]) -> bool {
        false
    }
}

/// Damping and stopping rules.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LmOptions {
    /// Iterations (accepted steps) at most; 0 only evaluates the start.
    pub max_iterations: usize,
    /// Damping at the start, relative to the diagonal of `JᵀWJ`.
    pub initial_lambda: f64,
    /// Factor applied to the damping after an accepted step.
    pub lambda_down: f64,
    /// Smallest damping.
    pub min_lambda: f64,
    /// Largest damping tried for one step before the fit is declared at a minimum.
    pub max_lambda: f64,
    /// Stop when an accepted step lowers the cost by less than this fraction ...
    pub relative_decrease: f64,
    /// ... this many times in a row.
    pub stalled_steps: usize,
    /// Stop when every parameter moved by less than this fraction of its size (floored at
    /// 10⁻⁹ absolute).
    pub relative_step: f64,
}

impl Default for LmOptions {
    fn default() -> Self {
        LmOptions {
            max_iterations: 200,
            initial_lambda: 1e-3,
            lambda_down: 0.1,
            min_lambda: 1e-12,
            max_lambda: 1e12,
            relative_decrease: 1e-14,
            stalled_steps: 1,
            relative_step: 1e-12,
        }
    }
}

/// What [`minimise`] found.
#[derive(Debug, Clone)]
pub struct LmFit {
    /// The best parameters.
    pub params: Vec<f64>,
    /// The normal equations (and cost) there.
    pub normal: NormalEquations,
    /// Accepted steps taken.
    pub iterations: usize,
    /// Whether a stopping rule held (rather than the iteration limit).
    pub converged: bool,
}

/// Minimises the problem's cost from `p0` (projected first). `None` when the start is
/// infeasible or its cost is not finite.
pub fn minimise<P: LmProblem + ?Sized>(
    problem: &mut P,
    p0: &[f64],
    options: &LmOptions,
) -> Option<LmFit> {
    let mut p = p0.to_vec();
    if !problem.project(&mut p) {
        return None;
    }
    let start_cost = problem.cost(&p).filter(|c| c.is_finite())?;
    let mut normal = problem.normal_equations(&p);
    normal.cost = start_cost;
    let mut lambda = options.initial_lambda;
    let (mut iterations, mut stalled, mut converged) = (0, 0, false);
    while iterations < options.max_iterations && !converged {
        let Some((trial, trial_cost)) = downhill_step(problem, &p, &normal, &mut lambda, options)
        else {
            converged = true; // No damping gives a downhill step: a minimum.
            break;
        };
        iterations += 1;
        let decrease = (normal.cost - trial_cost) / normal.cost.max(f64::MIN_POSITIVE);
        stalled = if decrease < options.relative_decrease {
            stalled + 1
        } else {
            0
        };
        let small_step = trial
            .iter()
            .zip(&p)
            .all(|(t, p)| (t - p).abs() <= options.relative_step * p.abs().max(1e-9));
        converged =
            stalled >= options.stalled_steps.max(1) || small_step || problem.converged(&p, &trial);
        p = trial;
        normal = problem.normal_equations(&p);
        normal.cost = trial_cost;
        lambda = (lambda * options.lambda_down).max(options.min_lambda);
    }
    p.iter().all(|v| v.is_finite()).then_some(LmFit {
        params: p,
        normal,
        iterations,
        converged,
    })
}

/// The first damped step from `p` that does not raise the cost, raising the damping until
/// one does (`None` past [`LmOptions::max_lambda`]).
fn downhill_step<P: LmProblem + ?Sized>(
    problem: &mut P,
    p: &[f64],
    normal: &NormalEquations,
    lambda: &mut f64,
    options: &LmOptions,
) -> Option<(Vec<f64>, f64)> {
    while *lambda <= options.max_lambda {
        if let Some(step) = damped_step(normal, *lambda) {
            let mut trial: Vec<f64> = p.iter().zip(step.iter()).map(|(p, s)| p + s).collect();
            if problem.project(&mut trial)
                && let Some(cost) = problem.cost(&trial).filter(|c| c.is_finite())
                && cost <= normal.cost
            {
                return Some((trial, cost));
            }
        }
        *lambda *= 10.0;
    }
    None
}

/// Parameters from which a damped step is solved inside the normal matrix's envelope
/// ([`crate::envelope`]) instead of by a dense Cholesky factorisation.
const ENVELOPE_FROM: usize = 64;

/// Solves `(JᵀWJ + λ diag(JᵀWJ)) δ = −JᵀWr` (Cholesky, LU when that fails).
fn damped_step(normal: &NormalEquations, lambda: f64) -> Option<DVector<f64>> {
    let mut damped = normal.jtwj.clone();
    for k in 0..damped.nrows() {
        damped[(k, k)] += lambda * normal.jtwj[(k, k)].max(1e-12);
    }
    let rhs = -&normal.jtwr;
    // Large problems are mostly zeros (a spline's coefficients touch only their neighbours):
    // their factor is computed inside its envelope.
    let solved = match damped.nrows() >= ENVELOPE_FROM {
        true => crate::envelope::solve_positive_definite(&damped, &rhs),
        false => damped.clone().cholesky().map(|c| c.solve(&rhs)),
    };
    solved
        .or_else(|| damped.lu().solve(&rhs))
        .filter(|step| step.iter().all(|v| v.is_finite()))
}

/// Residuals `r(p)` of a weighted least-squares problem, for [`ResidualProblem`]. Any
/// `Fn(&[f64], &mut [f64]) + Sync` writing the residuals is one (with a forward-difference
/// Jacobian); a non-finite residual marks `p` as outside the domain.
pub trait Residuals: Sync {
    /// Writes the residuals at `p` into `r`.
    fn residuals(&self, p: &[f64], r: &mut [f64]);

    /// The Jacobian `∂r/∂p` at `p` (`r0`: the residuals there); forward differences unless
    /// the problem knows it analytically.
    fn jacobian(&self, p: &[f64], r0: &[f64]) -> DMatrix<f64> {
        forward_difference(self, p, r0)
    }

    /// `JᵀWJ`, `JᵀWr` and the cost at `p` (`r`: the residuals there, `w`: their weights),
    /// from the dense [`Residuals::jacobian`] unless the problem forms them itself (a
    /// Jacobian with few non-zeros per row: [`crate::sparse_rows`]).
    fn normal_equations(&self, p: &[f64], r: &[f64], w: &[f64]) -> NormalEquations {
        weighted_normal_equations(&self.jacobian(p, r), r, w)
    }
}

impl<F: Fn(&[f64], &mut [f64]) + Sync> Residuals for F {
    fn residuals(&self, p: &[f64], r: &mut [f64]) {
        self(p, r)
    }
}

/// Forward-difference Jacobian, columns in parallel (each column is computed the same way
/// whatever the thread count, so the result is deterministic).
pub fn forward_difference<R: Residuals + ?Sized>(
    residuals: &R,
    p: &[f64],
    r0: &[f64],
) -> DMatrix<f64> {
    let (m, n) = (r0.len(), p.len());
    let columns: Vec<Vec<f64>> = (0..n)
        .into_par_iter()
        .map(|j| {
            let mut q = p.to_vec();
            let mut r = vec![0.0; m];
            let h = 1e-7 * p[j].abs().max(1e-3);
            q[j] = p[j] + h;
            residuals.residuals(&q, &mut r);
            r.iter().zip(r0).map(|(r, r0)| (r - r0) / h).collect()
        })
        .collect();
    DMatrix::from_fn(m, n, |i, j| columns[j][i])
}

/// Box bounds on the parameters: `lower[k] ≤ p[k] ≤ upper[k]` (use ±∞ for a free side).
#[derive(Debug, Clone, PartialEq)]
pub struct Bounds {
    /// Lower bound of each parameter.
    pub lower: Vec<f64>,
    /// Upper bound of each parameter.
    pub upper: Vec<f64>,
}

impl Bounds {
    /// Clamps `p` into the box; `false` when `p` has the wrong length or a NaN.
    pub fn clamp(&self, p: &mut [f64]) -> bool {
        if p.len() != self.lower.len() || p.len() != self.upper.len() {
            return false;
        }
        for ((v, lo), hi) in p.iter_mut().zip(&self.lower).zip(&self.upper) {
            if v.is_nan() {
                return false;
            }
            *v = v.max(*lo).min(*hi);
        }
        true
    }
}

/// `Σ wᵢ rᵢ²` of `m` residuals with weights `w` as an [`LmProblem`], optionally inside
/// box [`Bounds`].
pub struct ResidualProblem<'a, R: Residuals + ?Sized> {
    residuals: &'a R,
    weights: Vec<f64>,
    bounds: Option<Bounds>,
    /// The residuals at `at` (the last point evaluated).
    r: Vec<f64>,
    at: Vec<f64>,
}

impl<'a, R: Residuals + ?Sized> ResidualProblem<'a, R> {
    /// `m` residuals weighted by `weights` (length `m`).
    pub fn new(residuals: &'a R, m: usize, weights: Vec<f64>) -> Self {
        assert_eq!(weights.len(), m, "one weight per residual");
        ResidualProblem {
            residuals,
            weights,
            bounds: None,
            r: vec![f64::NAN; m],
            at: Vec::new(),
        }
    }

    /// Keeps every trial point inside `bounds` (projection after each step).
    pub fn with_bounds(mut self, bounds: Bounds) -> Self {
        self.bounds = Some(bounds);
        self
    }

    /// The (unweighted) residuals at `p`.
    pub fn residuals_at(&mut self, p: &[f64]) -> &[f64] {
        if self.at != p {
            self.residuals.residuals(p, &mut self.r);
            self.at = p.to_vec();
        }
        &self.r
    }

    /// The Jacobian at `p`.
    pub fn jacobian_at(&mut self, p: &[f64]) -> DMatrix<f64> {
        self.residuals_at(p);
        self.residuals.jacobian(p, &self.r)
    }
}

impl<R: Residuals + ?Sized> LmProblem for ResidualProblem<'_, R> {
    fn cost(&mut self, p: &[f64]) -> Option<f64> {
        let weights = std::mem::take(&mut self.weights);
        let cost = self
            .residuals_at(p)
            .iter()
            .zip(&weights)
            .map(|(r, w)| w * r * r)
            .sum::<f64>();
        self.weights = weights;
        cost.is_finite().then_some(cost)
    }

    fn normal_equations(&mut self, p: &[f64]) -> NormalEquations {
        self.residuals_at(p);
        self.residuals.normal_equations(p, &self.r, &self.weights)
    }

    fn project(&self, p: &mut [f64]) -> bool {
        self.bounds.as_ref().is_none_or(|b| b.clamp(p))
    }
}

/// What [`fit_residuals`] found.
#[derive(Debug, Clone)]
pub struct ResidualFit {
    /// The best parameters.
    pub params: Vec<f64>,
    /// The (unweighted) residuals there.
    pub residuals: Vec<f64>,
    /// `JᵀWJ` there (its inverse, the unscaled covariance, is
    /// [`ResidualFit::inverse_normal`]).
    pub normal: DMatrix<f64>,
    /// Accepted steps taken.
    pub iterations: usize,
}

impl ResidualFit {
    /// `(JᵀWJ)⁻¹` at the optimum (unscaled; see
    /// [`crate::linalg::inverse_with_undetermined`]), computed when asked for: a fit whose
    /// uncertainties are not read (a robust round, a cross-validation fold) does not pay
    /// for it.
    pub fn inverse_normal(&self) -> Option<DMatrix<f64>> {
        crate::linalg::inverse_with_undetermined(&self.normal)
    }
}

/// Minimises `Σ wᵢ rᵢ(p)²` of the `m` residuals of `residuals` from `p0`, and returns the
/// residuals and the unscaled covariance at the optimum. `None` when the start or the
/// optimum is not finite.
pub fn fit_residuals<R: Residuals + ?Sized>(
    residuals: &R,
    m: usize,
    p0: &[f64],
    weights: &[f64],
    options: &LmOptions,
) -> Option<ResidualFit> {
    fit_residuals_within(residuals, m, p0, weights, None, options)
}

/// [`fit_residuals`] with the parameters kept inside `bounds` (when given).
pub fn fit_residuals_within<R: Residuals + ?Sized>(
    residuals: &R,
    m: usize,
    p0: &[f64],
    weights: &[f64],
    bounds: Option<Bounds>,
    options: &LmOptions,
) -> Option<ResidualFit> {
    let mut problem = ResidualProblem::new(residuals, m, weights.to_vec());
    problem.bounds = bounds;
    let fit = minimise(&mut problem, p0, options)?;
    let r = problem.residuals_at(&fit.params).to_vec();
    Some(ResidualFit {
        normal: fit.normal.jtwj,
        params: fit.params,
        residuals: r,
        iterations: fit.iterations,
    })
}

/// `JᵀWJ`, `JᵀWr` and `rᵀWr` for a Jacobian `J` (m × n), residuals `r` and weights `w`.
pub fn weighted_normal_equations(j: &DMatrix<f64>, r: &[f64], w: &[f64]) -> NormalEquations {
    let n = j.ncols();
    let (jtwj, jtwr) = if j.nrows() >= COLUMN_WISE_ROWS {
        column_wise_products(j, r, w)
    } else {
        row_wise_products(j, r, w)
    };
    let cost = r.iter().zip(w).map(|(r, w)| w * r * r).sum();
    debug_assert_eq!(jtwj.nrows(), n);
    NormalEquations { jtwj, jtwr, cost }
}

/// From this many residuals on, `JᵀWJ` is accumulated column by column (contiguous in the
/// column-major Jacobian: ~10× faster on tens of thousands of rows); below, row by row
/// without the scratch column (the many small fits, e.g. one per feature).
const COLUMN_WISE_ROWS: usize = 256;

fn row_wise_products(j: &DMatrix<f64>, r: &[f64], w: &[f64]) -> (DMatrix<f64>, DVector<f64>) {
    let n = j.ncols();
    let mut jtwj = DMatrix::<f64>::zeros(n, n);
    let mut jtwr = DVector::<f64>::zeros(n);
    for (i, (&ri, &wi)) in r.iter().zip(w).enumerate() {
        for a in 0..n {
            let ja = j[(i, a)] * wi;
            jtwr[a] += ja * ri;
            for b in 0..=a {
                jtwj[(a, b)] += ja * j[(i, b)];
            }
        }
    }
    for a in 0..n {
        for b in 0..a {
            jtwj[(b, a)] = jtwj[(a, b)];
        }
    }
    (jtwj, jtwr)
}

fn column_wise_products(j: &DMatrix<f64>, r: &[f64], w: &[f64]) -> (DMatrix<f64>, DVector<f64>) {
    let n = j.ncols();
    let mut jtwj = DMatrix::<f64>::zeros(n, n);
    let mut jtwr = DVector::<f64>::zeros(n);
    let m = j.nrows();
    // Column-major storage: column `a` is `data[a·m .. (a + 1)·m]`.
    let data = j.as_slice();
    let column = |a: usize| &data[a * m..(a + 1) * m];
    let mut weighted = vec![0.0; m];
    for a in 0..n {
        for ((out, &ja), &wi) in weighted.iter_mut().zip(column(a)).zip(w) {
            *out = ja * wi;
        }
        jtwr[a] = dot(&weighted, r);
        for b in 0..=a {
            let value = dot(&weighted, column(b));
            jtwj[(a, b)] = value;
            jtwj[(b, a)] = value;
        }
    }
    (jtwj, jtwr)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rosenbrock as residuals: (1 − x, 10 (y − x²)); minimum at (1, 1).
    fn rosenbrock(p: &[f64], r: &mut [f64]) {
        r[0] = 1.0 - p[0];
        r[1] = 10.0 * (p[1] - p[0] * p[0]);
    }

    #[test]
    fn finds_the_rosenbrock_minimum() {
        let mut problem = ResidualProblem::new(&rosenbrock, 2, vec![1.0; 2]);
        let fit = minimise(&mut problem, &[-1.2, 1.0], &LmOptions::default()).unwrap();
        assert!((fit.params[0] - 1.0).abs() < 1e-8, "{:?}", fit.params);
        assert!((fit.params[1] - 1.0).abs() < 1e-8);
        assert!(fit.converged && fit.normal.cost < 1e-20);
    }

    struct Bounded;
    impl LmProblem for Bounded {
        fn cost(&mut self, p: &[f64]) -> Option<f64> {
            Some((p[0] - 3.0).powi(2))
        }
        fn normal_equations(&mut self, p: &[f64]) -> NormalEquations {
            NormalEquations {
                jtwj: DMatrix::from_element(1, 1, 1.0),
                jtwr: DVector::from_element(1, p[0] - 3.0),
                cost: (p[0] - 3.0).powi(2),
            }
        }
        fn project(&self, p: &mut [f64]) -> bool {
            p[0] = p[0].min(2.0);
            true
        }
    }

    #[test]
    fn a_bound_holds_the_fit_at_the_boundary() {
        let fit = minimise(&mut Bounded, &[0.0], &LmOptions::default()).unwrap();
        assert!((fit.params[0] - 2.0).abs() < 1e-12, "{:?}", fit.params);
    }

    #[test]
    fn residual_bounds_hold_and_a_free_side_stays_free() {
        // Unbounded minimum at (3, −4); the box caps the first at 2, the second is free.
        let residuals = |p: &[f64], r: &mut [f64]| {
            r[0] = p[0] - 3.0;
            r[1] = p[1] + 4.0;
        };
        let bounds = Bounds {
            lower: vec![f64::NEG_INFINITY; 2],
            upper: vec![2.0, f64::INFINITY],
        };
        let fit = fit_residuals_within(
            &residuals,
            2,
            &[0.0, 0.0],
            &[1.0, 1.0],
            Some(bounds),
            &LmOptions::default(),
        )
        .unwrap();
        assert!((fit.params[0] - 2.0).abs() < 1e-12, "{:?}", fit.params);
        assert!((fit.params[1] + 4.0).abs() < 1e-9, "{:?}", fit.params);
    }

    #[test]
    fn an_infeasible_start_is_refused() {
        let nan = |_: &[f64], r: &mut [f64]| r[0] = f64::NAN;
        let mut problem = ResidualProblem::new(&nan, 1, vec![1.0]);
        assert!(minimise(&mut problem, &[0.0], &LmOptions::default()).is_none());
    }

    #[test]
    fn weighted_normal_equations_match_the_matrix_products() {
        let j = DMatrix::from_row_slice(3, 2, &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
        let (r, w) = ([1.0, -1.0, 2.0], [1.0, 2.0, 0.5]);
        let ne = weighted_normal_equations(&j, &r, &w);
        let wm = DMatrix::from_diagonal(&DVector::from_row_slice(&w));
        let rv = DVector::from_row_slice(&r);
        assert!((ne.jtwj - j.transpose() * &wm * &j).norm() < 1e-12);
        assert!((ne.jtwr - j.transpose() * &wm * &rv).norm() < 1e-12);
        assert!((ne.cost - 5.0).abs() < 1e-12);
    }

    /// The column-wise accumulation (many rows) agrees with the row-wise one.
    #[test]
    fn column_and_row_wise_products_agree() {
        let m = 3 * COLUMN_WISE_ROWS;
        let j = DMatrix::from_fn(m, 4, |i, k| {
            ((i * 7 + k * 3) % 11) as f64 - 5.0 + 0.1 * k as f64
        });
        let r: Vec<f64> = (0..m).map(|i| ((i * 5) % 13) as f64 - 6.0).collect();
        let w: Vec<f64> = (0..m).map(|i| 1.0 + (i % 3) as f64).collect();
        let (a, b) = (
            column_wise_products(&j, &r, &w),
            row_wise_products(&j, &r, &w),
        );
        assert!((a.0 - b.0).norm() < 1e-9 && (a.1 - b.1).norm() < 1e-9);
    }
}
