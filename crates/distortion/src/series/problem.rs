//! The series fit as a least-squares problem over every indexed feature of every frame.
//!
//! Parameters (nm, nm/s units): `[θ, o_x, o_y, ε_y, c_x1 … c_x(B−1), c_y1 … c_y(B−1),
//! (C_x, C_y, q(t0)) per creep, hysteresis law …]`, the spline's first coefficient fixed at 0
//! (so `D(0) = 0` and the origin `o` is not degenerate with a constant drift). `ε_y` is the
//! scanner's instrument-y gain error relative to its x (`g_y = 1 + ε_y`, `g_x = 1`): a
//! common factor of both gains is the fast-axis hysteresis scale's, so only their ratio is
//! fitted; the instrument x's pixel size is taken as the files state it. Residuals:
//! the x deviations of every feature, then the y deviations, then two per creep (a weak
//! prior that keeps an unresolved creep's amplitude near 0, as in the registration).

use dhct_numerics::lm::Residuals;
use dhct_scan::ScanPass;
use nalgebra::DMatrix;
use rayon::prelude::*;

use super::frame::SeriesFeature;
use super::session_drift::{MoveCreep, SessionDrift};
use super::spline::SplineBasis;
use crate::fit::{HysteresisChoice, LogisticLog};
use crate::hysteresis_problem::{Quantity, hysteresis_law, law_gradient, law_parameters};
use crate::model::HysteresisLaw;

/// Nanometres per metre.
pub(super) const NM: f64 = 1e9;

/// Scale of the creep amplitudes' prior, nm (see the registration's).
const CREEP_PRIOR_NM: f64 = 10.0;

/// Index of the first spline coefficient (after θ, the origin and `ε_y`).
pub(super) const SPLINE_AT: usize = 4;

/// One feature's spline row: the first basis index and the four non-zero values.
#[derive(Debug, Clone, Copy)]
struct SplineRow {
    first: usize,
    values: [f64; 4],
}

/// The series fit's residuals and Jacobian.
pub(super) struct SeriesProblem<'a> {
    pub features: &'a [SeriesFeature],
    pub basis: SplineBasis,
    pub creep_starts: Vec<f64>,
    pub choice: HysteresisChoice,
    pub line_time_s: f64,
    pub t0_map: LogisticLog,
    rows: Vec<SplineRow>,
}

impl<'a> SeriesProblem<'a> {
    pub fn new(
        features: &'a [SeriesFeature],
        basis: SplineBasis,
        creep_starts: Vec<f64>,
        choice: HysteresisChoice,
        line_time_s: f64,
        t0_map: LogisticLog,
    ) -> Self {
        let rows = features
            .iter()
            .map(|f| {
                let (first, values) = basis.nonzero(f.time_s);
                SplineRow { first, values }
            })
            .collect();
        SeriesProblem {
            features,
            basis,
            creep_starts,
            choice,
            line_time_s,
            t0_map,
            rows,
        }
    }

    /// Spline coefficients fitted per axis (the first is fixed).
    fn free_coefficients(&self) -> usize {
        self.basis.len() - 1
    }

    /// Index of the first creep parameter.
    pub fn creep_at(&self) -> usize {
        SPLINE_AT + 2 * self.free_coefficients()
    }

    /// Index of the first hysteresis parameter.
    pub fn hysteresis_at(&self) -> usize {
        self.creep_at() + 3 * self.creep_starts.len()
    }

    /// Number of residuals.
    pub fn rows(&self) -> usize {
        2 * self.features.len() + 2 * self.creep_starts.len()
    }

    /// Weights before the data's scale is known (positions as if to 10 pm).
    pub fn plain_weights(&self) -> Vec<f64> {
        let mut w = vec![1e4; self.rows()];
        w[2 * self.features.len()..].fill(1.0);
        w
    }

    /// The parameter vector of a start.
    pub fn start(
        &self,
        (theta, origin_m, gain_y): (f64, [f64; 2], f64),
        drift: &SessionDrift,
        law: &HysteresisLaw,
    ) -> Vec<f64> {
        let mut p = vec![theta, origin_m[0] * NM, origin_m[1] * NM, gain_y - 1.0];
        for axis in 0..2 {
            p.extend(drift.coefficients_m[1..].iter().map(|c| c[axis] * NM));
        }
        for creep in &drift.creeps {
            p.extend([
                creep.coefficient_m[0] * NM,
                creep.coefficient_m[1] * NM,
                self.t0_map.parameter(creep.t0_s),
            ]);
        }
        p.extend(law_parameters(self.choice, law, self.line_time_s));
        p
    }

    /// The session drift of `p`.
    pub fn drift(&self, p: &[f64]) -> SessionDrift {
        let b = self.free_coefficients();
        let mut coefficients_m = vec![[0.0; 2]];
        coefficients_m.extend((0..b).map(|j| [p[SPLINE_AT + j] / NM, p[SPLINE_AT + b + j] / NM]));
        let at = self.creep_at();
        let creeps = self
            .creep_starts
            .iter()
            .enumerate()
            .map(|(m, &start_s)| MoveCreep {
                start_s,
                coefficient_m: [p[at + 3 * m] / NM, p[at + 3 * m + 1] / NM],
                t0_s: self.t0_map.t0(p[at + 3 * m + 2]),
            })
            .collect();
        SessionDrift {
            basis: self.basis.clone(),
            coefficients_m,
            creeps,
        }
    }

    /// The hysteresis law of `p`.
    pub fn law(&self, p: &[f64]) -> HysteresisLaw {
        hysteresis_law(self.choice, self.line_time_s, &p[self.hysteresis_at()..])
    }

    /// Hysteresis lag (seconds of fast travel) of `f` under `law`.
    fn lag(&self, law: &HysteresisLaw, f: &SeriesFeature) -> f64 {
        match f.pass {
            ScanPass::Trace => law.excess_integral(f.line_time_s),
            ScanPass::Retrace => {
                law.excess_integral(self.line_time_s) - law.excess_integral(f.line_time_s)
            }
        }
    }

    /// Session position (nm) of feature `i` under `p`'s drift and law, before the lattice.
    fn position(&self, p: &[f64], law: &HysteresisLaw, i: usize) -> [f64; 2] {
        let f = &self.features[i];
        let row = &self.rows[i];
        let b = self.free_coefficients();
        let lag = self.lag(law, f);
        let mut d = [
            f.controller_m[0] * NM + f.lag_direction_m_per_s[0] * NM * lag,
            (f.controller_m[1] + p[3] * (f.controller_m[1] - f.centre_m[1])) * NM
                + f.lag_direction_m_per_s[1] * NM * lag,
        ];
        for (r, value) in row.values.iter().enumerate() {
            let j = row.first + r;
            if j > 0 {
                d[0] += value * p[SPLINE_AT + j - 1];
                d[1] += value * p[SPLINE_AT + b + j - 1];
            }
        }
        let at = self.creep_at();
        for (m, &start) in self.creep_starts.iter().enumerate() {
            let elapsed = f.time_s - start;
            if elapsed > 0.0 {
                let log = (elapsed / self.t0_map.t0(p[at + 3 * m + 2])).ln_1p();
                d[0] += p[at + 3 * m] * log;
                d[1] += p[at + 3 * m + 1] * log;
            }
        }
        d
    }
}

impl Residuals for SeriesProblem<'_> {
    fn residuals(&self, p: &[f64], r: &mut [f64]) {
        let m = self.features.len();
        let law = self.law(p);
        let (s, c) = p[0].sin_cos();
        let (positions, prior) = r.split_at_mut(2 * m);
        let at = self.creep_at();
        for k in 0..self.creep_starts.len() {
            prior[2 * k] = p[at + 3 * k] / CREEP_PRIOR_NM;
            prior[2 * k + 1] = p[at + 3 * k + 1] / CREEP_PRIOR_NM;
        }
        let (rx, ry) = positions.split_at_mut(m);
        rx.par_iter_mut()
            .zip(ry.par_iter_mut())
            .enumerate()
            .for_each(|(i, (rx, ry))| {
                let [x, y] = self.position(p, &law, i);
                let [ux, uy] = self.features[i].site_m;
                let (ux, uy) = (ux * NM, uy * NM);
                *rx = x - p[1] - (c * ux - s * uy);
                *ry = y - p[2] - (s * ux + c * uy);
            });
    }

    fn jacobian(&self, p: &[f64], _r0: &[f64]) -> DMatrix<f64> {
        let (m, n) = (self.features.len(), p.len());
        let b = self.free_coefficients();
        let at = self.creep_at();
        let h_at = self.hysteresis_at();
        let law = self.law(p);
        let hysteresis_count = n - h_at;
        let mut end = [0.0; 5];
        law_gradient(
            &law,
            self.line_time_s,
            Quantity::ExcessIntegral,
            &mut end[..hysteresis_count],
        );
        let (s, c) = p[0].sin_cos();
        let mut rows = vec![0.0; self.rows() * n];
        let (positions, prior) = rows.split_at_mut(2 * m * n);
        for k in 0..self.creep_starts.len() {
            prior[2 * k * n + at + 3 * k] = 1.0 / CREEP_PRIOR_NM;
            prior[(2 * k + 1) * n + at + 3 * k + 1] = 1.0 / CREEP_PRIOR_NM;
        }
        let (x_rows, y_rows) = positions.split_at_mut(m * n);
        x_rows
            .par_chunks_mut(n)
            .zip(y_rows.par_chunks_mut(n))
            .enumerate()
            .for_each(|(i, (row_x, row_y))| {
                let f = &self.features[i];
                let [ux, uy] = [f.site_m[0] * NM, f.site_m[1] * NM];
                row_x[0] = s * ux + c * uy;
                row_y[0] = -(c * ux - s * uy);
                row_x[1] = -1.0;
                row_y[2] = -1.0;
                row_y[3] = (f.controller_m[1] - f.centre_m[1]) * NM;
                let spline = &self.rows[i];
                for (r, value) in spline.values.iter().enumerate() {
                    let j = spline.first + r;
                    if j > 0 {
                        row_x[SPLINE_AT + j - 1] = *value;
                        row_y[SPLINE_AT + b + j - 1] = *value;
                    }
                }
                for (k, &start) in self.creep_starts.iter().enumerate() {
                    let elapsed = f.time_s - start;
                    if elapsed <= 0.0 {
                        continue;
                    }
                    let q = p[at + 3 * k + 2];
                    let t0 = self.t0_map.t0(q);
                    let log = (elapsed / t0).ln_1p();
                    let dlog = -elapsed / (t0 * (t0 + elapsed)) * self.t0_map.derivative(q);
                    row_x[at + 3 * k] = log;
                    row_y[at + 3 * k + 1] = log;
                    row_x[at + 3 * k + 2] = p[at + 3 * k] * dlog;
                    row_y[at + 3 * k + 2] = p[at + 3 * k + 1] * dlog;
                }
                let mut lag = [0.0; 5];
                law_gradient(
                    &law,
                    f.line_time_s,
                    Quantity::ExcessIntegral,
                    &mut lag[..hysteresis_count],
                );
                for j in 0..hysteresis_count {
                    let g = match f.pass {
                        ScanPass::Trace => lag[j],
                        ScanPass::Retrace => end[j] - lag[j],
                    };
                    row_x[h_at + j] = f.lag_direction_m_per_s[0] * NM * g;
                    row_y[h_at + j] = f.lag_direction_m_per_s[1] * NM * g;
                }
            });
        DMatrix::from_row_slice(self.rows(), n, &rows)
    }
}
