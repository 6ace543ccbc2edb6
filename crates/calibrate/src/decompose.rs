//! Decompositions of a 2 × 2 map (controller → sample, metres per metre): its singular
//! values and its split into scale-and-shear times rotation.

use nalgebra::{Matrix2, Vector2};

/// Singular values `(s1 ≥ s2)` of a 2 × 2 matrix.
pub(crate) fn singular_values(a: &Matrix2<f64>) -> (f64, f64) {
    let ata = a.transpose() * a;
    let (t, d) = (ata.trace(), ata.determinant());
    let root = (0.25 * t * t - d).max(0.0).sqrt();
    ((0.5 * t + root).sqrt(), (0.5 * t - root).max(0.0).sqrt())
}

/// `A = K·Q` with `K` upper triangular (positive diagonal) and `Q` a rotation; needs
/// `det A > 0`. Returns `(K, rotation angle of Q in radians)`.
pub(crate) fn rq(a: &Matrix2<f64>) -> (Matrix2<f64>, f64) {
    let ky = a[(1, 0)].hypot(a[(1, 1)]);
    let row2 = Vector2::new(a[(1, 0)], a[(1, 1)]) / ky;
    let row1 = Vector2::new(row2.y, -row2.x);
    let top = Vector2::new(a[(0, 0)], a[(0, 1)]);
    let k = Matrix2::new(top.dot(&row1), top.dot(&row2), 0.0, ky);
    (k, row2.x.atan2(row2.y))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rq_splits_scale_shear_and_rotation() {
        let k = Matrix2::new(1.2, 0.1, 0.0, 0.8);
        let angle = 0.3f64;
        let q = Matrix2::new(angle.cos(), -angle.sin(), angle.sin(), angle.cos());
        let (found, rotation) = rq(&(k * q));
        assert!((found - k).abs().max() < 1e-12, "{found}");
        assert!((rotation - angle).abs() < 1e-12);
    }

    #[test]
    fn singular_values_of_a_stretch() {
        let (s1, s2) = singular_values(&Matrix2::new(0.0, 3.0, -2.0, 0.0));
        assert!((s1 - 3.0).abs() < 1e-12 && (s2 - 2.0).abs() < 1e-12);
    }
}
