//! Covariances from normal equations whose parameters are not all determined.

use nalgebra::DMatrix;

/// `(JᵀWJ)⁻¹`, or, when that is singular because some parameters are not determined (e.g.
/// one pinned at a bound, where its derivative vanishes), the inverse over the determined
/// parameters with NaN variance and no correlations for the others. `None` when even that
/// fails.
pub fn inverse_with_undetermined(jtwj: &DMatrix<f64>) -> Option<DMatrix<f64>> {
    if let Some(inverse) = jtwj.clone().try_inverse()
        && inverse
            .diagonal()
            .iter()
            .all(|v| v.is_finite() && *v >= 0.0)
    {
        return Some(inverse);
    }
    let n = jtwj.nrows();
    let largest = jtwj.diagonal().iter().cloned().fold(0.0, f64::max);
    let kept: Vec<usize> = (0..n).filter(|&k| jtwj[(k, k)] > 1e-12 * largest).collect();
    let sub = DMatrix::from_fn(kept.len(), kept.len(), |i, j| jtwj[(kept[i], kept[j])]);
    let sub_inverse = sub.try_inverse()?;
    let mut full = DMatrix::<f64>::zeros(n, n);
    for k in (0..n).filter(|k| !kept.contains(k)) {
        full[(k, k)] = f64::NAN;
    }
    for (i, &a) in kept.iter().enumerate() {
        for (j, &b) in kept.iter().enumerate() {
            full[(a, b)] = sub_inverse[(i, j)];
        }
    }
    Some(full)
}

/// Pseudo-inverse of a symmetric positive semi-definite matrix: scaled to unit diagonal,
/// eigenvalues below `cut × largest` dropped (their directions get no variance).
pub fn pseudo_inverse_symmetric(a: &DMatrix<f64>, cut: f64) -> DMatrix<f64> {
    let n = a.nrows();
    let d: Vec<f64> = (0..n)
        .map(|k| {
            let v = a[(k, k)];
            if v > 0.0 { 1.0 / v.sqrt() } else { 1.0 }
        })
        .collect();
    let scaled = DMatrix::from_fn(n, n, |r, c| a[(r, c)] * d[r] * d[c]);
    let eigen = scaled.symmetric_eigen();
    let largest = eigen.eigenvalues.iter().cloned().fold(0.0, f64::max);
    let mut inverse = DMatrix::zeros(n, n);
    for k in 0..n {
        let l = eigen.eigenvalues[k];
        if l > cut * largest {
            let v = eigen.eigenvectors.column(k);
            inverse += v * v.transpose() / l;
        }
    }
    DMatrix::from_fn(n, n, |r, c| inverse[(r, c)] * d[r] * d[c])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_undetermined_parameter_gets_nan_variance() {
        let a = DMatrix::from_row_slice(2, 2, &[4.0, 0.0, 0.0, 0.0]);
        let inverse = inverse_with_undetermined(&a).unwrap();
        assert_eq!(inverse[(0, 0)], 0.25);
        assert!(inverse[(1, 1)].is_nan());
    }

    #[test]
    fn pseudo_inverse_inverts_the_determined_subspace() {
        let a = DMatrix::from_row_slice(2, 2, &[2.0, 2.0, 2.0, 2.0]); // rank 1
        let p = pseudo_inverse_symmetric(&a, 1e-12);
        assert!((&a * &p * &a - &a).norm() < 1e-12);
        let b = DMatrix::from_row_slice(2, 2, &[2.0, 1.0, 1.0, 3.0]);
        let q = pseudo_inverse_symmetric(&b, 1e-12);
        assert!((q - b.try_inverse().unwrap()).norm() < 1e-12);
    }
}
