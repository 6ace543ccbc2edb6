//! Symmetric positive-definite solves that use the matrix's zeros: a few parameters that
//! touch everything (a rotation, an origin, a gain, creep amplitudes) beside many that touch
//! only their neighbours (a spline's coefficients). The dense parameters are moved last and
//! the rest keep their order, so that every row's non-zeros start close to the diagonal (its
//! envelope); a Cholesky factor has no non-zero outside the envelope, and computing it
//! inside costs `O(n·w²)` for the banded part plus `O(d·n·w + d²·n)` for `d` dense
//! parameters, against `O(n³/3)` dense.

use crate::dot::dot;
use nalgebra::{DMatrix, DVector};

/// A parameter whose column has more than this fraction of non-zeros is moved last.
const DENSE_FRACTION: f64 = 0.25;

/// The solution of `A x = b` for a symmetric positive-definite `A`, by a Cholesky
/// factorisation inside the envelope of `A` reordered with its dense parameters last;
/// `None` when `A` is not positive definite (a pivot not above 0) or not square.
///
/// ```
/// use dhct_numerics::envelope::solve_positive_definite;
/// use nalgebra::{DMatrix, DVector};
/// // A tridiagonal matrix bordered by one dense parameter (index 0).
/// let n = 6;
/// let a = DMatrix::from_fn(n, n, |i, j| match (i, j) {
///     (i, j) if i == j => 4.0,
///     (0, _) | (_, 0) => 0.5,
///     (i, j) if i.abs_diff(j) == 1 => -1.0,
///     _ => 0.0,
/// });
/// let b = DVector::from_fn(n, |i, _| i as f64 - 2.0);
/// let x = solve_positive_definite(&a, &b).expect("positive definite");
/// assert!((&a * &x - &b).norm() < 1e-12);
/// ```
pub fn solve_positive_definite(a: &DMatrix<f64>, b: &DVector<f64>) -> Option<DVector<f64>> {
    let n = a.nrows();
    if a.ncols() != n || b.len() != n {
        return None;
    }
    let order = sparse_first(a);
    let factor = Envelope::factorise(a, &order)?;
    let pb: Vec<f64> = order.iter().map(|&k| b[k]).collect();
    let z = factor.backward(factor.forward(pb));
    let mut x = DVector::zeros(n);
    for (k, &at) in order.iter().enumerate() {
        x[at] = z[k];
    }
    Some(x)
}

/// The parameters with few non-zeros in their column in their own order, then the dense
/// ones in theirs.
fn sparse_first(a: &DMatrix<f64>) -> Vec<usize> {
    let n = a.nrows();
    let limit = (DENSE_FRACTION * n as f64).ceil() as usize;
    let dense: Vec<bool> = (0..n)
        .map(|j| a.column(j).iter().filter(|v| **v != 0.0).count() > limit)
        .collect();
    let sparse = (0..n).filter(|&j| !dense[j]);
    sparse.chain((0..n).filter(|&j| dense[j])).collect()
}

/// A lower-triangular factor stored inside its envelope: row `i` holds columns
/// `first[i]..=i`, contiguous.
struct Envelope {
    first: Vec<usize>,
    rows: Vec<Vec<f64>>,
}

impl Envelope {
    /// The Cholesky factor of `a` reordered by `order`; `None` at a pivot that is not
    /// positive.
    fn factorise(a: &DMatrix<f64>, order: &[usize]) -> Option<Envelope> {
        let n = order.len();
        let at = |i: usize, j: usize| a[(order[i], order[j])];
        let first: Vec<usize> = (0..n)
            .map(|i| (0..i).find(|&j| at(i, j) != 0.0).unwrap_or(i))
            .collect();
        let mut rows: Vec<Vec<f64>> = Vec::with_capacity(n);
        for i in 0..n {
            let mut row: Vec<f64> = (first[i]..=i).map(|j| at(i, j)).collect();
            for j in first[i]..=i {
                let from = first[i].max(first[j]);
                let mine = &row[from - first[i]..j - first[i]];
                let theirs = match j < i {
                    true => &rows[j][from - first[j]..j - first[j]],
                    false => mine,
                };
                let s = row[j - first[i]] - dot(mine, theirs);
                if j < i {
                    row[j - first[i]] = s / rows[j][j - first[j]];
                } else if s > 0.0 && s.is_finite() {
                    row[i - first[i]] = s.sqrt();
                } else {
                    return None;
                }
            }
            rows.push(row);
        }
        Some(Envelope { first, rows })
    }

    fn diagonal(&self, i: usize) -> f64 {
        self.rows[i][i - self.first[i]]
    }

    /// `L y = b`.
    fn forward(&self, mut y: Vec<f64>) -> Vec<f64> {
        for i in 0..y.len() {
            let left = &self.rows[i][..i - self.first[i]];
            y[i] = (y[i] - dot(left, &y[self.first[i]..i])) / self.diagonal(i);
        }
        y
    }

    /// `Lᵀ x = y` (row by row of `L`, each row's entries taken out of the ones before).
    fn backward(&self, mut x: Vec<f64>) -> Vec<f64> {
        for i in (0..x.len()).rev() {
            x[i] /= self.diagonal(i);
            let xi = x[i];
            let left = &self.rows[i][..i - self.first[i]];
            for (v, l) in x[self.first[i]..i].iter_mut().zip(left) {
                *v -= l * xi;
            }
        }
        x
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The normal matrix of a cubic spline fit bordered by dense parameters at both ends
    /// (as the series fit orders them), plus a ridge.
    fn spline_like(n: usize, dense: &[usize]) -> DMatrix<f64> {
        let mut a = DMatrix::zeros(n, n);
        for i in 0..n {
            for j in 0..n {
                let near = i.abs_diff(j) <= 3;
                let bordered = dense.contains(&i) || dense.contains(&j);
                if near || bordered {
                    a[(i, j)] = 1.0 / (1.0 + (i + j) as f64 % 7.0);
                }
            }
        }
        // Diagonally dominant: positive definite.
        for i in 0..n {
            let row: f64 = a.row(i).iter().map(|v| v.abs()).sum();
            a[(i, i)] = row + 1.0;
        }
        a
    }

    #[test]
    fn it_solves_as_a_dense_cholesky_does() {
        let n = 120;
        let a = spline_like(n, &[0, 1, 2, 117, 118]);
        let b = DVector::from_fn(n, |i, _| ((i * 37) % 11) as f64 - 5.0);
        let ours = solve_positive_definite(&a, &b).expect("positive definite");
        let dense = a.clone().cholesky().expect("positive definite").solve(&b);
        assert!(
            (&ours - &dense).norm() < 1e-10 * dense.norm(),
            "{}",
            (&ours - &dense).norm()
        );
    }

    #[test]
    fn a_matrix_that_is_not_positive_definite_is_refused() {
        let mut a = spline_like(40, &[0]);
        a[(20, 20)] = -1.0;
        assert!(solve_positive_definite(&a, &DVector::zeros(40)).is_none());
        assert!(solve_positive_definite(&DMatrix::zeros(3, 4), &DVector::zeros(3)).is_none());
    }
}
