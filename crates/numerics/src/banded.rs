//! Symmetric positive-definite banded systems: storage, accumulation and a Cholesky solve
//! in `O(n·w²)` for half-bandwidth `w` (a dense solve would be `O(n³)`).

/// A symmetric `n × n` matrix with `A[i][j] = 0` for `|i − j| > w`, lower band stored row by
/// row: `band[i·(w + 1) + (w − (i − j))]` holds `A[i][j]` for `i − w ≤ j ≤ i`.
#[derive(Debug, Clone, PartialEq)]
pub struct SymmetricBand {
    n: usize,
    w: usize,
    band: Vec<f64>,
}

impl SymmetricBand {
    /// The zero matrix of size `n` and half-bandwidth `w`.
    pub fn zeros(n: usize, w: usize) -> SymmetricBand {
        SymmetricBand {
            n,
            w,
            band: vec![0.0; n * (w + 1)],
        }
    }

    /// Size.
    pub fn size(&self) -> usize {
        self.n
    }

    /// Half-bandwidth.
    pub fn half_bandwidth(&self) -> usize {
        self.w
    }

    fn index(&self, i: usize, j: usize) -> Option<usize> {
        let (i, j) = if i >= j { (i, j) } else { (j, i) };
        (i < self.n && i - j <= self.w).then(|| i * (self.w + 1) + self.w - (i - j))
    }

    /// `A[i][j]` (0 outside the band).
    pub fn get(&self, i: usize, j: usize) -> f64 {
        self.index(i, j).map_or(0.0, |k| self.band[k])
    }

    /// Adds `v` to `A[i][j]` (and so to `A[j][i]`); `false` (nothing added) outside the band
    /// or the matrix.
    pub fn add(&mut self, i: usize, j: usize, v: f64) -> bool {
        match self.index(i, j) {
            Some(k) => {
                self.band[k] += v;
                true
            }
            None => false,
        }
    }

    /// Adds `other` (same size and bandwidth) element by element.
    pub fn add_matrix(&mut self, other: &SymmetricBand) {
        for (a, b) in self.band.iter_mut().zip(&other.band) {
            *a += b;
        }
    }

    /// Solves `A·x = b` by banded Cholesky; `None` if `A` is not positive definite (or `b`
    /// has the wrong length).
    pub fn solve(&self, b: &[f64]) -> Option<Vec<f64>> {
        let (n, w) = (self.n, self.w);
        if b.len() != n {
            return None;
        }
        // L in the same lower-band layout.
        let mut l = self.band.clone();
        let at = |i: usize, j: usize| i * (w + 1) + w - (i - j);
        for i in 0..n {
            let lo = i.saturating_sub(w);
            for j in lo..=i {
                let mut sum = l[at(i, j)];
                for k in lo.max(j.saturating_sub(w))..j {
                    sum -= l[at(i, k)] * l[at(j, k)];
                }
                if i == j {
                    if !(sum > 0.0 && sum.is_finite()) {
                        return None;
                    }
                    l[at(i, i)] = sum.sqrt();
                } else {
                    l[at(i, j)] = sum / l[at(j, j)];
                }
            }
        }
        // Forward (L·y = b), then back (Lᵀ·x = y) substitution.
        let mut y = b.to_vec();
        for i in 0..n {
            for k in i.saturating_sub(w)..i {
                y[i] -= l[at(i, k)] * y[k];
            }
            y[i] /= l[at(i, i)];
        }
        for i in (0..n).rev() {
            for k in i + 1..(i + w + 1).min(n) {
                y[i] -= l[at(k, i)] * y[k];
            }
            y[i] /= l[at(i, i)];
        }
        Some(y)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{DMatrix, DVector};

    #[test]
    fn banded_solve_matches_a_dense_solve() {
        let (n, w) = (40, 3);
        let mut band = SymmetricBand::zeros(n, w);
        let mut dense = DMatrix::<f64>::zeros(n, n);
        for i in 0..n {
            for j in i.saturating_sub(w)..=i {
                let v = if i == j {
                    10.0 + i as f64 * 0.1
                } else {
                    ((i * 7 + j * 3) % 5) as f64 * 0.4 - 0.8
                };
                assert!(band.add(i, j, v));
                dense[(i, j)] = v;
                dense[(j, i)] = v;
            }
        }
        assert!(!band.add(10, 2, 1.0), "outside the band");
        assert_eq!(band.get(2, 5), dense[(2, 5)]);
        let b: Vec<f64> = (0..n).map(|i| (i as f64 * 0.37).sin()).collect();
        let x = band.solve(&b).expect("positive definite");
        let expected = dense.cholesky().expect("spd").solve(&DVector::from(b));
        for (a, e) in x.iter().zip(expected.iter()) {
            assert!((a - e).abs() < 1e-12, "{a} vs {e}");
        }
    }

    #[test]
    fn an_indefinite_band_is_refused() {
        let mut band = SymmetricBand::zeros(3, 1);
        band.add(0, 0, 1.0);
        band.add(1, 0, 2.0);
        band.add(1, 1, 1.0);
        band.add(2, 2, 1.0);
        assert!(band.solve(&[1.0, 1.0, 1.0]).is_none());
    }
}
