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

use dhct_numerics::lm::{NormalEquations, Residuals};
use dhct_numerics::sparse_rows::sparse_normal_equations;
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

/// Index of the scanner's y gain error `ε_y`.
pub(super) const GAIN_AT: usize = 3;

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
            (f.controller_m[1] + p[GAIN_AT] * (f.controller_m[1] - f.centre_m[1])) * NM
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

/// What every Jacobian row at one parameter vector shares.
struct RowContext {
    law: HysteresisLaw,
    /// The law's gradient of the excess integral over a whole line (the retrace's lag).
    end: [f64; 5],
    /// Hysteresis parameters fitted.
    hysteresis_count: usize,
    sin_theta: f64,
    cos_theta: f64,
}

impl SeriesProblem<'_> {
    fn row_context(&self, p: &[f64]) -> RowContext {
        let law = self.law(p);
        let hysteresis_count = p.len() - self.hysteresis_at();
        let mut end = [0.0; 5];
        law_gradient(
            &law,
            self.line_time_s,
            Quantity::ExcessIntegral,
            &mut end[..hysteresis_count],
        );
        let (sin_theta, cos_theta) = p[0].sin_cos();
        RowContext {
            law,
            end,
            hysteresis_count,
            sin_theta,
            cos_theta,
        }
    }

    /// Row `i` of `∂r/∂p` as its non-zero entries (the residuals' order: every feature's
    /// x, every feature's y, then the creeps' priors).
    fn jacobian_row(
        &self,
        p: &[f64],
        context: &RowContext,
        i: usize,
        entries: &mut Vec<(usize, f64)>,
    ) {
        let m = self.features.len();
        let at = self.creep_at();
        if i >= 2 * m {
            let k = i - 2 * m;
            entries.push((at + 3 * (k / 2) + k % 2, 1.0 / CREEP_PRIOR_NM));
            return;
        }
        let axis = i / m;
        let f = &self.features[i % m];
        let [ux, uy] = [f.site_m[0] * NM, f.site_m[1] * NM];
        let (s, c) = (context.sin_theta, context.cos_theta);
        if axis == 0 {
            entries.extend([(0, s * ux + c * uy), (1, -1.0)]);
        } else {
            entries.extend([
                (0, -(c * ux - s * uy)),
                (2, -1.0),
                (3, (f.controller_m[1] - f.centre_m[1]) * NM),
            ]);
        }
        let spline = &self.rows[i % m];
        let axis_at = SPLINE_AT + axis * self.free_coefficients();
        for (r, value) in spline.values.iter().enumerate() {
            let j = spline.first + r;
            if j > 0 {
                entries.push((axis_at + j - 1, *value));
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
            entries.extend([
                (at + 3 * k + axis, log),
                (at + 3 * k + 2, p[at + 3 * k + axis] * dlog),
            ]);
        }
        let mut lag = [0.0; 5];
        let count = context.hysteresis_count;
        law_gradient(
            &context.law,
            f.line_time_s,
            Quantity::ExcessIntegral,
            &mut lag[..count],
        );
        let h_at = self.hysteresis_at();
        for (j, (lag, end)) in lag[..count].iter().zip(&context.end).enumerate() {
            let g = match f.pass {
                ScanPass::Trace => *lag,
                ScanPass::Retrace => end - lag,
            };
            entries.push((h_at + j, f.lag_direction_m_per_s[axis] * NM * g));
        }
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
        let n = p.len();
        let context = self.row_context(p);
        let mut dense = vec![0.0; self.rows() * n];
        dense.par_chunks_mut(n).enumerate().for_each(|(i, row)| {
            let mut entries = Vec::new();
            self.jacobian_row(p, &context, i, &mut entries);
            for (k, value) in entries {
                row[k] = value;
            }
        });
        DMatrix::from_row_slice(self.rows(), n, &dense)
    }

    /// From the Jacobian's few non-zeros per row (θ, the origin, `ε_y`, four spline
    /// coefficients, the creeps, the law): a long session's hundreds of spline coefficients
    /// would make a dense Jacobian's products the whole fit's cost.
    fn normal_equations(&self, p: &[f64], r: &[f64], w: &[f64]) -> NormalEquations {
        let context = self.row_context(p);
        sparse_normal_equations(p.len(), r, w, |i, entries| {
            self.jacobian_row(p, &context, i, entries)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use dhct_numerics::lm::{forward_difference, weighted_normal_equations};

    /// Features of two frames, both passes, with sites and times spread over a session.
    fn features() -> Vec<SeriesFeature> {
        (0..60)
            .map(|i| {
                let t = i as f64 * 1.7;
                SeriesFeature {
                    frame: i / 30,
                    input: i % 2,
                    feature_index: i,
                    pass: if i % 2 == 0 {
                        ScanPass::Trace
                    } else {
                        ScanPass::Retrace
                    },
                    controller_m: [1e-9 * (i % 7) as f64, 1e-9 * (i / 7) as f64],
                    centre_m: [3e-9, 4e-9],
                    time_s: t,
                    line_time_s: 0.001 + 0.018 * ((i * 5) % 11) as f64 / 11.0,
                    lag_direction_m_per_s: [-2e-7, 3e-8],
                    site_m: [0.25e-9 * (i % 7) as f64, 0.2e-9 * (i / 7) as f64],
                }
            })
            .collect()
    }

    /// The analytic Jacobian (the rows the sparse normal equations use) equals forward
    /// differences, and the sparse normal equations equal the dense ones, with a creep
    /// that starts mid-session and two hysteresis laws.
    #[test]
    fn jacobian_rows_match_forward_differences_and_the_dense_products() {
        let features = features();
        let basis = SplineBasis {
            start_s: 0.0,
            end_s: 100.0,
            interior_knots: 3,
        };
        let t0_map = LogisticLog::for_frame(0.02, 50.0);
        for (choice, law) in [
            (HysteresisChoice::Power, vec![0.9, -0.03]),
            (HysteresisChoice::Exponential, vec![0.05, (0.004f64).ln()]),
        ] {
            let problem =
                SeriesProblem::new(&features, basis.clone(), vec![40.0], choice, 0.02, t0_map);
            let mut p = vec![0.1, 0.3, -0.2, 0.01];
            p.extend((0..2 * (basis.len() - 1)).map(|j| 0.05 * j as f64 - 0.2));
            p.extend([0.4, -0.3, 0.5]);
            p.extend(law);
            let mut r0 = vec![0.0; problem.rows()];
            problem.residuals(&p, &mut r0);
            let analytic = problem.jacobian(&p, &r0);
            let numeric = forward_difference(&problem, &p, &r0);
            for (k, (a, b)) in analytic
                .column_iter()
                .zip(numeric.column_iter())
                .enumerate()
            {
                let size = b.amax();
                assert!(size > 0.0, "{choice:?}: parameter {k} moves nothing");
                assert!((a - b).amax() <= 1e-4 * size, "{choice:?}: parameter {k}");
            }
            let w: Vec<f64> = (0..r0.len()).map(|i| 1.0 + (i % 4) as f64).collect();
            let sparse = problem.normal_equations(&p, &r0, &w);
            let dense = weighted_normal_equations(&analytic, &r0, &w);
            assert!((sparse.jtwj - &dense.jtwj).amax() <= 1e-12 * dense.jtwj.amax());
            assert!((sparse.jtwr - &dense.jtwr).amax() <= 1e-12 * dense.jtwj.amax());
        }
    }
}
