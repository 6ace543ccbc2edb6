//! The displacement of the tip relative to the sample over a whole session of frames:
//! a smooth drift (a cubic spline in session time) plus a logarithmic creep after each move
//! of the scan frame.

use serde::{Deserialize, Serialize};

use super::spline::SplineBasis;

/// A creep that starts when the scan frame was moved: displacement `C·ln(1 + (T − T_m)/t0)`
/// for session time `T > T_m` (instrument frame, metres), zero before.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MoveCreep {
    /// `T_m`, session seconds (the start of the first frame after the move).
    pub start_s: f64,
    /// `C`, metres, instrument frame `[x, y]`.
    pub coefficient_m: [f64; 2],
    /// `t0`, seconds (> 0).
    pub t0_s: f64,
}

impl MoveCreep {
    /// `ln(1 + (T − T_m)/t0)`, 0 before the move.
    pub fn log_term(&self, t: f64) -> f64 {
        let elapsed = t - self.start_s;
        if elapsed <= 0.0 {
            0.0
        } else {
            (elapsed / self.t0_s).ln_1p()
        }
    }
}

/// `D(T)`: where the tip is relative to the sample, minus where the controller put it,
/// metres, instrument frame (display axes of the unrotated scanner), at session time `T`
/// (seconds since the start of the first frame's first line). `D` averages to zero over the
/// first frame's features: the first frame fixes the session frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SessionDrift {
    /// The spline the smooth drift is expressed in.
    pub basis: SplineBasis,
    /// Spline coefficients per axis, metres (`[x, y]` per basis function).
    pub coefficients_m: Vec<[f64; 2]>,
    /// The creeps, in time order.
    pub creeps: Vec<MoveCreep>,
}

impl SessionDrift {
    /// No drift over `[0, end_s]`.
    pub fn none(end_s: f64) -> SessionDrift {
        let basis = SplineBasis {
            start_s: 0.0,
            end_s: end_s.max(1e-9),
            interior_knots: 0,
        };
        SessionDrift {
            coefficients_m: vec![[0.0; 2]; basis.len()],
            basis,
            creeps: Vec::new(),
        }
    }

    /// `D(T)`, metres, instrument frame.
    pub fn displacement(&self, t: f64) -> [f64; 2] {
        let (first, values) = self.basis.nonzero(t);
        let mut d = [0.0; 2];
        for (b, c) in values.iter().zip(&self.coefficients_m[first..]) {
            d[0] += b * c[0];
            d[1] += b * c[1];
        }
        for creep in &self.creeps {
            let log = creep.log_term(t);
            d[0] += creep.coefficient_m[0] * log;
            d[1] += creep.coefficient_m[1] * log;
        }
        d
    }

    /// The drift velocity `dD/dT`, m/s (central difference over 1 ms).
    pub fn velocity(&self, t: f64) -> [f64; 2] {
        let h = 1e-3;
        let (a, b) = (self.displacement(t - h), self.displacement(t + h));
        [(b[0] - a[0]) / (2.0 * h), (b[1] - a[1]) / (2.0 * h)]
    }
}
