//! `JᵀWJ`, `JᵀWr` and the cost of a Jacobian given row by row as its non-zero entries.
//!
//! A fit over many observations where each observation touches a few of many parameters
//! (a drift spline over a long session: 4 of hundreds of coefficients per feature) would
//! spend almost all its time on zeros with a dense Jacobian — `m·n²/2` products and `m·n`
//! doubles held. Given sparse rows, the products cost `m·k²/2` for `k` non-zeros per row
//! and nothing of size `m·n` is held.

use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

use crate::lm::NormalEquations;

/// Rows accumulated per parallel piece at least: enough that a piece's own `n × n`
/// accumulator is paid back many times over.
const ROWS_PER_PIECE: usize = 2048;

/// Pieces at most: each holds an `n × n` accumulator (2.2 MB at 530 parameters), which is
/// zeroed and summed whatever the rows; a few per core keep the cores busy. The pieces
/// depend only on the row count, and are summed in order: the same result on any number of
/// threads.
const MAX_PIECES: usize = 8;

/// The normal equations of `m` residuals `r` with weights `w` (both length `m`) over `n`
/// parameters, row `i`'s non-zero Jacobian entries `(parameter, ∂rᵢ/∂p)` written by
/// `row(i, entries)` (into a cleared `entries`; no parameter twice in one row).
///
/// ```
/// use dhct_numerics::lm::weighted_normal_equations;
/// use dhct_numerics::sparse_rows::sparse_normal_equations;
/// use nalgebra::DMatrix;
/// // Row i touches parameters i % 3 and 3.
/// let dense = DMatrix::from_fn(5, 4, |i, k| if k == i % 3 { 1.0 + i as f64 } else if k == 3 { 0.5 } else { 0.0 });
/// let (r, w) = ([1.0, -2.0, 0.5, 3.0, 1.0], [1.0, 2.0, 1.0, 0.5, 1.0]);
/// let sparse = sparse_normal_equations(4, &r, &w, |i, entries| {
///     entries.extend([(i % 3, 1.0 + i as f64), (3, 0.5)]);
/// });
/// let expected = weighted_normal_equations(&dense, &r, &w);
/// assert!((sparse.jtwj - expected.jtwj).norm() < 1e-12);
/// assert!((sparse.jtwr - expected.jtwr).norm() < 1e-12);
/// ```
pub fn sparse_normal_equations<F>(n: usize, r: &[f64], w: &[f64], row: F) -> NormalEquations
where
    F: Fn(usize, &mut Vec<(usize, f64)>) + Sync,
{
    assert_eq!(r.len(), w.len(), "one weight per residual");
    let m = r.len();
    let pieces = m.div_ceil(ROWS_PER_PIECE).clamp(1, MAX_PIECES);
    let size = m.div_ceil(pieces);
    let parts: Vec<(DMatrix<f64>, DVector<f64>, f64)> = (0..pieces)
        .into_par_iter()
        .map(|p| accumulate(n, r, w, &row, (p * size).min(m)..((p + 1) * size).min(m)))
        .collect();
    let mut parts = parts.into_iter();
    let first = parts
        .next()
        .unwrap_or_else(|| accumulate(n, r, w, &row, 0..0));
    let (lower, jtwr, cost) = parts.fold(first, |(mut a, mut b, c), (d, e, f)| {
        a += d;
        b += e;
        (a, b, c + f)
    });
    NormalEquations {
        jtwj: symmetric_from_lower(lower),
        jtwr,
        cost,
    }
}

/// One piece's lower triangle of `JᵀWJ` (each product stored at `(max, min)` of its two
/// parameters), `JᵀWr` and cost.
fn accumulate<F>(
    n: usize,
    r: &[f64],
    w: &[f64],
    row: &F,
    rows: std::ops::Range<usize>,
) -> (DMatrix<f64>, DVector<f64>, f64)
where
    F: Fn(usize, &mut Vec<(usize, f64)>),
{
    let mut lower = DMatrix::<f64>::zeros(n, n);
    let mut jtwr = DVector::<f64>::zeros(n);
    let mut cost = 0.0;
    let mut entries = Vec::new();
    for i in rows {
        let (ri, wi) = (r[i], w[i]);
        cost += wi * ri * ri;
        entries.clear();
        row(i, &mut entries);
        for (k, &(a, va)) in entries.iter().enumerate() {
            let weighted = wi * va;
            jtwr[a] += weighted * ri;
            for &(b, vb) in &entries[..=k] {
                lower[(a.max(b), a.min(b))] += weighted * vb;
            }
        }
    }
    (lower, jtwr, cost)
}

/// The full symmetric matrix from its lower triangle.
fn symmetric_from_lower(mut m: DMatrix<f64>) -> DMatrix<f64> {
    let n = m.nrows();
    for a in 0..n {
        for b in 0..a {
            m[(b, a)] = m[(a, b)];
        }
    }
    m
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lm::weighted_normal_equations;

    /// Many rows (several pieces, and more rows than the most pieces take at their
    /// smallest), entries in no particular order, against the dense products.
    #[test]
    fn sparse_rows_give_the_dense_normal_equations() {
        for m in [
            3 * ROWS_PER_PIECE + 17,
            (MAX_PIECES + 1) * ROWS_PER_PIECE + 5,
        ] {
            check_against_dense(m);
        }
    }

    /// The same sums, to the bit, on one thread as on several.
    #[test]
    fn the_sums_do_not_depend_on_the_threads() {
        let (m, n) = (5 * ROWS_PER_PIECE + 3, 6);
        let r: Vec<f64> = (0..m).map(|i| (0.37 * i as f64).sin()).collect();
        let w: Vec<f64> = (0..m).map(|i| 1.0 + (0.11 * i as f64).cos()).collect();
        let rows = |i: usize, out: &mut Vec<(usize, f64)>| {
            out.extend([
                (i % n, 0.3 + (0.7 * i as f64).sin()),
                ((i + 2) % n, 1e-3 * i as f64),
            ])
        };
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .expect("a pool")
            .install(|| sparse_normal_equations(n, &r, &w, rows));
        let many = rayon::ThreadPoolBuilder::new()
            .num_threads(3)
            .build()
            .expect("a pool")
            .install(|| sparse_normal_equations(n, &r, &w, rows));
        assert_eq!(one.jtwj, many.jtwj);
        assert_eq!(one.jtwr, many.jtwr);
        assert_eq!(one.cost.to_bits(), many.cost.to_bits());
    }

    fn check_against_dense(m: usize) {
        let n = 9;
        let entries = |i: usize| -> Vec<(usize, f64)> {
            let a = (i * 7) % n;
            let b = (a + 1 + i % (n - 1)) % n;
            vec![
                (b, 0.5 + (i % 5) as f64),
                (a, -1.0 + (i % 3) as f64),
                (n - 1, 0.25),
            ]
            .into_iter()
            .fold(Vec::new(), |mut v, e| {
                if !v.iter().any(|(k, _)| *k == e.0) {
                    v.push(e);
                }
                v
            })
        };
        let dense = DMatrix::from_fn(m, n, |i, k| {
            entries(i)
                .iter()
                .find(|(j, _)| *j == k)
                .map_or(0.0, |e| e.1)
        });
        let r: Vec<f64> = (0..m).map(|i| ((i * 5) % 13) as f64 - 6.0).collect();
        let w: Vec<f64> = (0..m).map(|i| 1.0 + (i % 3) as f64).collect();
        let sparse = sparse_normal_equations(n, &r, &w, |i, out| out.extend(entries(i)));
        let expected = weighted_normal_equations(&dense, &r, &w);
        let scale = expected.jtwj.norm();
        assert!((sparse.jtwj - expected.jtwj).norm() < 1e-12 * scale);
        assert!((sparse.jtwr - expected.jtwr).norm() < 1e-12 * scale);
        assert!((sparse.cost - expected.cost).abs() < 1e-9 * expected.cost);
    }
}
