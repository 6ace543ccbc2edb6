//! A small weighted Levenberg–Marquardt, used for the RDF, drift/creep and hysteresis fits
//! (few parameters, up to ~10⁵ residuals). The Jacobian is the problem's own where it
//! knows it analytically, forward differences otherwise.

use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

/// Result of [`levenberg_marquardt`].
pub(crate) struct LmResult {
    /// Best parameters.
    pub params: Vec<f64>,
    /// Residuals at the best parameters (unweighted).
    pub residuals: Vec<f64>,
    /// `(Jᵀ W J)⁻¹` at the best parameters (unscaled), if invertible.
    pub inverse_normal: Option<DMatrix<f64>>,
}

/// A weighted least-squares problem for [`levenberg_marquardt`]. Any
/// `Fn(&[f64], &mut [f64])` writing the residuals is one (with a finite-difference Jacobian).
pub(crate) trait Problem: Sync {
    /// Writes the residuals at `p` into `r`.
    fn residuals(&self, p: &[f64], r: &mut [f64]);

    /// The Jacobian `∂r/∂p` at `p` (`r0`: the residuals there); forward differences unless
    /// the problem knows it analytically.
    fn jacobian(&self, p: &[f64], r0: &[f64]) -> DMatrix<f64> {
        forward_difference(self, p, r0)
    }
}

impl<F: Fn(&[f64], &mut [f64]) + Sync> Problem for F {
    fn residuals(&self, p: &[f64], r: &mut [f64]) {
        self(p, r)
    }
}

/// Forward-difference Jacobian, one column per parameter, columns in parallel (each column
/// is computed the same way whatever the thread count, so the result is deterministic).
fn forward_difference<P: Problem + ?Sized>(problem: &P, p: &[f64], r0: &[f64]) -> DMatrix<f64> {
    let (m, n) = (r0.len(), p.len());
    let columns: Vec<Vec<f64>> = (0..n)
        .into_par_iter()
        .map(|j| {
            let mut q = p.to_vec();
            let mut r = vec![0.0; m];
            let h = 1e-7 * p[j].abs().max(1e-3);
            q[j] = p[j] + h;
            problem.residuals(&q, &mut r);
            r.iter().zip(r0).map(|(r, r0)| (r - r0) / h).collect()
        })
        .collect();
    DMatrix::from_fn(m, n, |i, j| columns[j][i])
}

fn cost(r: &[f64], w: &[f64]) -> f64 {
    r.iter().zip(w).map(|(r, w)| w * r * r).sum()
}

/// Minimises `Σ w_i r_i(p)²` of the `m` residuals of `problem` from `p0`.
pub(crate) fn levenberg_marquardt<P: Problem + ?Sized>(
    problem: &P,
    m: usize,
    p0: &[f64],
    weights: &[f64],
    max_iterations: usize,
) -> Option<LmResult> {
    let n = p0.len();
    let mut p = p0.to_vec();
    let mut r = vec![0.0; m];
    problem.residuals(&p, &mut r);
    let mut c = cost(&r, weights);
    if !c.is_finite() {
        return None;
    }
    let mut lambda = 1e-3;
    let mut trial = vec![0.0; m];
    for _ in 0..max_iterations {
        let jac = problem.jacobian(&p, &r);
        let mut jtj = DMatrix::<f64>::zeros(n, n);
        let mut jtr = DVector::<f64>::zeros(n);
        for i in 0..m {
            let w = weights[i];
            for a in 0..n {
                let ja = jac[(i, a)] * w;
                jtr[a] += ja * r[i];
                for b in 0..=a {
                    jtj[(a, b)] += ja * jac[(i, b)];
                }
            }
        }
        for a in 0..n {
            for b in 0..a {
                jtj[(b, a)] = jtj[(a, b)];
            }
        }
        let mut improved = false;
        for _ in 0..30 {
            let mut damped = jtj.clone();
            for a in 0..n {
                damped[(a, a)] += lambda * jtj[(a, a)].max(1e-300);
            }
            let Some(step) = damped.lu().solve(&(-&jtr)) else {
                lambda *= 10.0;
                continue;
            };
            let q: Vec<f64> = p.iter().zip(step.iter()).map(|(p, s)| p + s).collect();
            problem.residuals(&q, &mut trial);
            let ct = cost(&trial, weights);
            if ct.is_finite() && ct <= c {
                let small = step
                    .iter()
                    .zip(&p)
                    .all(|(s, p)| s.abs() <= 1e-12 * p.abs().max(1e-9));
                let relative = (c - ct) / c.max(1e-300);
                p = q;
                std::mem::swap(&mut r, &mut trial);
                c = ct;
                lambda = (lambda / 10.0).max(1e-12);
                improved = !(small || relative < 1e-14);
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            break;
        }
    }
    let jac = problem.jacobian(&p, &r);
    let mut jtj = DMatrix::<f64>::zeros(n, n);
    for (i, w) in weights.iter().enumerate().take(m) {
        let row = jac.row(i);
        jtj += row.transpose() * row * *w;
    }
    let inverse_normal = covariance_inverse(&jtj);
    if p.iter().all(|v| v.is_finite()) {
        Some(LmResult {
            params: p,
            residuals: r,
            inverse_normal,
        })
    } else {
        None
    }
}

/// `(JᵀWJ)⁻¹`, or, when that is singular because some parameters are not determined (e.g.
/// one pinned at a bound, where its derivative vanishes), the inverse over the determined
/// parameters with NaN variance and no correlations for the others.
fn covariance_inverse(jtj: &DMatrix<f64>) -> Option<DMatrix<f64>> {
    if let Some(inverse) = jtj.clone().try_inverse()
        && inverse
            .diagonal()
            .iter()
            .all(|v| v.is_finite() && *v >= 0.0)
    {
        return Some(inverse);
    }
    let n = jtj.nrows();
    let largest = jtj.diagonal().iter().cloned().fold(0.0, f64::max);
    let kept: Vec<usize> = (0..n).filter(|&k| jtj[(k, k)] > 1e-12 * largest).collect();
    let sub = DMatrix::from_fn(kept.len(), kept.len(), |i, j| jtj[(kept[i], kept[j])]);
    let sub_inverse = sub.try_inverse()?;
    let mut full = DMatrix::<f64>::zeros(n, n);
    for k in 0..n {
        if !kept.contains(&k) {
            full[(k, k)] = f64::NAN;
        }
    }
    for (i, &a) in kept.iter().enumerate() {
        for (j, &b) in kept.iter().enumerate() {
            full[(a, b)] = sub_inverse[(i, j)];
        }
    }
    Some(full)
}

/// Huber weights for residuals `r` with scale `sigma` (tuning constant 1.345).
pub(crate) fn huber_weights(r: &[f64], sigma: f64) -> Vec<f64> {
    let k = 1.345 * sigma;
    r.iter()
        .map(|r| if r.abs() <= k { 1.0 } else { k / r.abs() })
        .collect()
}

/// Robust scale: 1.4826 · median |r|.
pub(crate) fn mad_sigma(r: &[f64]) -> f64 {
    let mut a: Vec<f64> = r
        .iter()
        .map(|r| r.abs())
        .filter(|r| r.is_finite())
        .collect();
    if a.is_empty() {
        return 0.0;
    }
    a.sort_by(f64::total_cmp);
    1.4826 * a[a.len() / 2]
}
