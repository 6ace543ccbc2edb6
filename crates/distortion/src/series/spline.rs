//! A clamped cubic B-spline basis on a time interval: the smooth drift of a session.

use serde::{Deserialize, Serialize};

/// Cubic B-spline basis on `[start, end]` (seconds) with evenly spaced interior knots,
/// clamped at both ends (the first basis function is 1 at `start`, all others 0 there).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SplineBasis {
    /// Start of the interval, seconds.
    pub start_s: f64,
    /// End of the interval, seconds (> start).
    pub end_s: f64,
    /// Interior knots (0: one cubic polynomial over the interval).
    pub interior_knots: usize,
}

const DEGREE: usize = 3;

impl SplineBasis {
    /// Number of basis functions: interior knots + 4.
    pub fn len(&self) -> usize {
        self.interior_knots + DEGREE + 1
    }

    /// Never empty (at least the 4 of a cubic).
    pub fn is_empty(&self) -> bool {
        false
    }

    /// Values of every basis function at `t` (clamped to the interval), written to `out`
    /// (length [`SplineBasis::len`]); they sum to 1.
    pub fn values(&self, t: f64, out: &mut [f64]) {
        out.iter_mut().for_each(|v| *v = 0.0);
        let (first, values) = self.nonzero(t);
        out[first..first + 4].copy_from_slice(&values);
    }

    /// The four basis functions that may be non-zero at `t` (clamped to the interval):
    /// the index of the first and their values.
    pub fn nonzero(&self, t: f64) -> (usize, [f64; 4]) {
        let t = t.clamp(self.start_s, self.end_s);
        let pieces = self.interior_knots + 1;
        let at = (t - self.start_s) / (self.end_s - self.start_s) * pieces as f64;
        let piece = (at as usize).min(pieces - 1);
        // Away from the clamped ends (the knots piece − 2 ..= piece + 3 all evenly spaced)
        // the basis is the uniform cubic B-spline's, in closed form.
        if piece >= 2 && piece + 3 <= pieces {
            return (piece, uniform_cubic(at - piece as f64));
        }
        (piece, self.cox_de_boor(t, piece))
    }

    /// The four basis functions non-zero on `piece` at `t` (inside the interval), by the
    /// Cox–de Boor recursion over the clamped knot vector.
    fn cox_de_boor(&self, t: f64, piece: usize) -> [f64; 4] {
        let span_s = self.end_s - self.start_s;
        let pieces = self.interior_knots + 1;
        // Knot j of the full vector (start repeated 4 times, end 4 times).
        let knot = |j: isize| -> f64 {
            let inner = j - DEGREE as isize;
            if inner <= 0 {
                self.start_s
            } else if inner as usize >= pieces {
                self.end_s
            } else {
                self.start_s + span_s * inner as f64 / pieces as f64
            }
        };
        let span = (piece + DEGREE) as isize;
        // Triangular: the degree-d functions span−d..=span.
        let mut n = [0.0; DEGREE + 1];
        n[0] = 1.0;
        for d in 1..=DEGREE as isize {
            let mut saved = 0.0;
            for r in 0..d {
                let left = knot(span + 1 + r - d);
                let right = knot(span + 1 + r);
                let term = n[r as usize] / (right - left);
                n[r as usize] = saved + (right - t) * term;
                saved = (t - left) * term;
            }
            n[d as usize] = saved;
        }
        n
    }
}

/// The four uniform cubic B-spline functions non-zero on a piece, at `u` ∈ [0, 1] of it.
fn uniform_cubic(u: f64) -> [f64; 4] {
    let (u2, u3) = (u * u, u * u * u);
    let v = 1.0 - u;
    [
        v * v * v / 6.0,
        (3.0 * u3 - 6.0 * u2 + 4.0) / 6.0,
        (-3.0 * u3 + 3.0 * u2 + 3.0 * u + 1.0) / 6.0,
        u3 / 6.0,
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn partition_of_unity_clamped_ends_and_polynomials_reproduced() {
        for inner in [0, 1, 4] {
            let b = SplineBasis {
                start_s: 2.0,
                end_s: 12.0,
                interior_knots: inner,
            };
            let mut v = vec![0.0; b.len()];
            for k in 0..=100 {
                let t = 2.0 + 0.1 * k as f64;
                b.values(t, &mut v);
                assert!((v.iter().sum::<f64>() - 1.0).abs() < 1e-12, "{inner} {t}");
                assert!(v.iter().all(|x| *x >= -1e-15));
            }
            b.values(2.0, &mut v);
            assert!((v[0] - 1.0).abs() < 1e-15);
            b.values(12.0, &mut v);
            assert!((v[b.len() - 1] - 1.0).abs() < 1e-15);
        }
        // With no interior knots the basis is Bernstein's: t ↦ t reproduced by the
        // Greville abscissae as coefficients.
        let b = SplineBasis {
            start_s: 0.0,
            end_s: 3.0,
            interior_knots: 0,
        };
        let mut v = vec![0.0; 4];
        b.values(1.3, &mut v);
        let t: f64 = v.iter().enumerate().map(|(j, x)| j as f64 * x).sum();
        assert!((t - 1.3).abs() < 1e-12);
    }

    /// The closed form used away from the clamped ends is the recursion's basis.
    #[test]
    fn the_uniform_closed_form_equals_the_recursion() {
        let b = SplineBasis {
            start_s: 3.0,
            end_s: 53.0,
            interior_knots: 9,
        };
        let mut interior = 0;
        for k in 0..=1000 {
            let t = 3.0 + 0.05 * k as f64;
            let (piece, fast) = b.nonzero(t);
            let slow = b.cox_de_boor(t, piece);
            for (a, r) in fast.iter().zip(slow) {
                assert!((a - r).abs() < 1e-14, "t {t}: {fast:?} against {slow:?}");
            }
            interior += usize::from((2..=7).contains(&piece));
        }
        assert!(
            interior > 500,
            "{interior} samples on the closed form's pieces"
        );
    }
}
