//! The session's drift from what the images alone show, for frames without a resolved
//! lattice: where a part of one frame reappears in the next. Such a comparison measures a
//! *difference* of the drift, `D(T₁) − D(T₀)` between the two moments that scanned the same
//! sample point; a smooth `D` (the session's cubic spline, [`SplineBasis`]) is fitted to many
//! of them by robust linear least squares.
//!
//! What differences cannot tell (and so what this route leaves undetermined):
//! * a constant displacement (`D` is pinned to average zero over the first frame's times);
//! * anything the same in every frame: the scanner's pixel size and its calibration, the
//!   fast-scan hysteresis, a frame-periodic part of the drift;
//! * a drift the spline cannot follow between comparisons (knots closer than about a frame
//!   apart leave frame-periodic patterns unmeasured: they are damped, not fitted).

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use super::fit::TrajectoryPoint;
use super::session_drift::{MoveCreep, SessionDrift};
use super::spline::SplineBasis;
use crate::DistortionError;

/// One comparison of two moments of the session that scanned the same sample point.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DriftDifference {
    /// Session time of the later scan of the point, seconds.
    pub later_s: f64,
    /// Session time of the earlier scan of it, seconds.
    pub earlier_s: f64,
    /// `D(later) − D(earlier)`, metres, instrument frame.
    pub difference_m: [f64; 2],
}

/// [`fit_drift_differences`]'s result.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DifferenceDriftFit {
    /// The drift over the session (no creep terms: the spline takes any creep).
    pub drift: SessionDrift,
    /// `D(T)` sampled over the session with its 1σ (the uncertainty of `D(T) − D(0)`).
    pub trajectory: Vec<TrajectoryPoint>,
    /// `D` at each frame's start with its 1σ.
    pub frame_starts: Vec<TrajectoryPoint>,
    /// Robust rms of the comparisons about the fitted differences, metres, per axis.
    pub rms_residual_m: [f64; 2],
    /// Comparisons used.
    pub comparisons: usize,
    /// Comparisons given less than half weight by the robust fit (a part of a frame that
    /// changed, a tip change, a wrong match).
    pub outliers: usize,
}

/// Frames placed by their images: the drift over the session and the offset between the
/// passes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ImageRegistration {
    /// The drift fitted to the comparisons.
    pub fit: DifferenceDriftFit,
    /// The tip's displacement from where the controller put it in the retrace less in the
    /// trace, metres, instrument frame: the hysteresis's difference between the passes,
    /// measured as the shift between the two images (`[0, 0]` without a retrace). Each
    /// pass is moved by half of it, so the registered passes meet halfway.
    pub retrace_offset_m: [f64; 2],
}

/// Iterations of the robust reweighting.
const ROBUST_ROUNDS: usize = 8;

/// Points of the sampled trajectory.
const TRAJECTORY_POINTS: usize = 400;

/// Relative weight of the smoothness penalty (second differences of the spline
/// coefficients) against the data: small enough to leave any measured drift alone, large
/// enough that a pattern no comparison sees comes out flat rather than arbitrary.
const SMOOTHING: f64 = 1e-6;

/// Fits `D(T)` on `basis` (interior knots chosen by the caller) to `differences`, pinned
/// to average zero over `first_frame_times_s`; `frame_starts_s` are the frames' starts
/// (session seconds) at which `D` is reported.
pub fn fit_drift_differences(
    differences: &[DriftDifference],
    basis: SplineBasis,
    moves: &[MoveTiming],
    first_frame_times_s: &[f64],
    frame_starts_s: &[f64],
) -> Result<DifferenceDriftFit, DistortionError> {
    // D(0) = 0 fixes the constant (the first coefficient); the rest are free, with one
    // creep amplitude per move.
    let unknowns = basis.len() - 1 + moves.len();
    if differences.len() < unknowns + 2 {
        return Err(DistortionError::TooFewFeatures {
            what: "drift from image comparisons (comparisons of frames)",
            found: differences.len(),
            needed: unknowns + 2,
        });
    }
    // Each creep's time constant profiled on a grid, one move after the other.
    let mut t0s: Vec<f64> = moves.iter().map(|m| m.t0_grid_s().1).collect();
    for (i, m) in moves.iter().enumerate() {
        let mut best = (f64::INFINITY, t0s[i]);
        for t0 in m.t0_grid_s().0 {
            t0s[i] = t0;
            let cost =
                solve_both(differences, &basis, moves, &t0s).map_or(f64::INFINITY, |s| s.cost);
            if cost < best.0 {
                best = (cost, t0);
            }
        }
        t0s[i] = best.1;
    }
    let solved = solve_both(differences, &basis, moves, &t0s)
        .ok_or(DistortionError::FitFailed("drift from image comparisons"))?;
    let n = basis.len();
    let mut drift = SessionDrift {
        basis,
        coefficients_m: (0..n)
            .map(|j| match j {
                0 => [0.0; 2],
                _ => [
                    solved.axes[0].coefficients[j - 1],
                    solved.axes[1].coefficients[j - 1],
                ],
            })
            .collect(),
        creeps: moves
            .iter()
            .zip(&t0s)
            .enumerate()
            .map(|(i, (m, &t0_s))| MoveCreep {
                start_s: m.start_s,
                coefficient_m: [
                    solved.axes[0].coefficients[n - 1 + i],
                    solved.axes[1].coefficients[n - 1 + i],
                ],
                t0_s,
            })
            .collect(),
    };
    let rms = [solved.axes[0].sigma, solved.axes[1].sigma];
    let low_weight: Vec<bool> = (0..differences.len())
        .map(|r| solved.axes.iter().any(|a| a.weights[r] < 0.5))
        .collect();
    let covariances: Vec<DMatrix<f64>> = solved.axes.into_iter().map(|a| a.covariance).collect();
    recentre(&mut drift, first_frame_times_s);
    let point = |t: f64| trajectory_point(&drift, &covariances, t);
    let end = drift.basis.end_s;
    Ok(DifferenceDriftFit {
        trajectory: (0..=TRAJECTORY_POINTS)
            .map(|i| point(end * i as f64 / TRAJECTORY_POINTS as f64))
            .collect(),
        frame_starts: frame_starts_s.iter().map(|&t| point(t)).collect(),
        rms_residual_m: rms,
        comparisons: differences.len(),
        outliers: low_weight.iter().filter(|&&f| f).count(),
        drift,
    })
}

/// When the scan frame was moved, for the creep that follows.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MoveTiming {
    /// Session time the creep starts (the start of the first frame after the move), s.
    pub start_s: f64,
    /// One line's scan time (the shortest time constant tried), s.
    pub line_time_s: f64,
    /// One frame's duration (twice it is the longest time constant tried), s.
    pub frame_s: f64,
}

/// Time constants tried per creep.
const T0_GRID: usize = 12;

impl MoveTiming {
    /// The time constants tried (log-spaced from two lines to two frames) and the middle
    /// one, seconds.
    fn t0_grid_s(&self) -> (Vec<f64>, f64) {
        let (low, high) = (2.0 * self.line_time_s, 2.0 * self.frame_s);
        let grid: Vec<f64> = (0..T0_GRID)
            .map(|j| low * (high / low).powf(j as f64 / (T0_GRID - 1) as f64))
            .collect();
        let middle = grid[T0_GRID / 2];
        (grid, middle)
    }
}

/// Both axes solved under given creep time constants.
struct BothAxes {
    axes: Vec<RobustSolution>,
    /// Sum over the axes of Huber's loss, m² (what the creeps' profile minimises).
    cost: f64,
}

fn solve_both(
    differences: &[DriftDifference],
    basis: &SplineBasis,
    moves: &[MoveTiming],
    t0s: &[f64],
) -> Option<BothAxes> {
    let design = difference_design(differences, basis, moves, t0s);
    let spline_columns = basis.len() - 1;
    let mut axes = Vec::with_capacity(2);
    let mut cost = 0.0;
    for axis in 0..2 {
        let b = DVector::from_iterator(
            differences.len(),
            differences.iter().map(|d| d.difference_m[axis]),
        );
        let solved = robust_solve(&design, &b, spline_columns)?;
        cost += solved.cost;
        axes.push(solved);
    }
    Some(BothAxes { axes, cost })
}

/// Rows `B(later) − B(earlier)` without the first basis function (fixed at 0), then per
/// move its creep's log term at `later` less at `earlier` under `t0s`.
fn difference_design(
    differences: &[DriftDifference],
    basis: &SplineBasis,
    moves: &[MoveTiming],
    t0s: &[f64],
) -> DMatrix<f64> {
    let n = basis.len();
    let (mut later, mut earlier) = (vec![0.0; n], vec![0.0; n]);
    let mut a = DMatrix::<f64>::zeros(differences.len(), n - 1 + moves.len());
    for (row, d) in differences.iter().enumerate() {
        basis.values(d.later_s, &mut later);
        basis.values(d.earlier_s, &mut earlier);
        for j in 1..n {
            a[(row, j - 1)] = later[j] - earlier[j];
        }
        for (i, (m, &t0_s)) in moves.iter().zip(t0s).enumerate() {
            let creep = MoveCreep {
                start_s: m.start_s,
                coefficient_m: [0.0; 2],
                t0_s,
            };
            a[(row, n - 1 + i)] = creep.log_term(d.later_s) - creep.log_term(d.earlier_s);
        }
    }
    a
}

/// One axis's robust solution.
struct RobustSolution {
    coefficients: DVector<f64>,
    /// Robust scale of the residuals.
    sigma: f64,
    /// Final Huber weights.
    weights: Vec<f64>,
    /// `σ²·(AᵀWA + λP)⁻¹`.
    covariance: DMatrix<f64>,
    /// Huber's loss of the residuals, m² (the sum of squares where none is an outlier).
    cost: f64,
}

/// Huber-reweighted least squares of `a·c ≈ b` with a light second-difference penalty on
/// the first `smoothed` columns (the spline's).
fn robust_solve(a: &DMatrix<f64>, b: &DVector<f64>, smoothed: usize) -> Option<RobustSolution> {
    let (rows, columns) = a.shape();
    let mut penalty = DMatrix::<f64>::zeros(columns, columns);
    penalty
        .view_mut((0, 0), (smoothed, smoothed))
        .copy_from(&second_difference_penalty(smoothed));
    let mut weights = vec![1.0; rows];
    let mut result = None;
    for _ in 0..ROBUST_ROUNDS {
        let mut normal = DMatrix::<f64>::zeros(columns, columns);
        let mut rhs = DVector::<f64>::zeros(columns);
        for (r, w) in weights.iter().enumerate() {
            let row = a.row(r);
            normal += *w * row.transpose() * row;
            rhs += *w * b[r] * row.transpose();
        }
        let scale = normal.diagonal().max().max(f64::MIN_POSITIVE);
        normal += SMOOTHING * scale * &penalty;
        let inverse = normal.clone().try_inverse()?;
        let c = &inverse * rhs;
        let residuals: Vec<f64> = (0..rows).map(|r| b[r] - (a.row(r) * &c)[0]).collect();
        let sigma = dhct_numerics::robust::mad_sigma_about(&residuals, 0.0)?.max(f64::MIN_POSITIVE);
        if !c.iter().all(|v| v.is_finite()) {
            return None;
        }
        weights = dhct_numerics::robust::huber_weights(&residuals, sigma);
        let cost = sigma * sigma * residuals.iter().map(|r| huber_loss(*r, sigma)).sum::<f64>();
        result = Some(RobustSolution {
            coefficients: c,
            sigma,
            weights: weights.clone(),
            covariance: inverse * (sigma * sigma),
            cost,
        });
    }
    result
}

/// Huber's loss of residual `r` at scale `sigma`, in units of σ² (quadratic within
/// [`dhct_numerics::robust::HUBER_K`]·σ, linear beyond).
fn huber_loss(r: f64, sigma: f64) -> f64 {
    let k = dhct_numerics::robust::HUBER_K;
    let u = (r / sigma).abs();
    if u <= k { u * u } else { 2.0 * k * u - k * k }
}

/// `DᵀD` of the second-difference operator on `n` coefficients.
fn second_difference_penalty(n: usize) -> DMatrix<f64> {
    let mut p = DMatrix::<f64>::zeros(n, n);
    for i in 0..n.saturating_sub(2) {
        let idx = [i, i + 1, i + 2];
        let w = [1.0, -2.0, 1.0];
        for (a, wa) in idx.iter().zip(w) {
            for (b, wb) in idx.iter().zip(w) {
                p[(*a, *b)] += wa * wb;
            }
        }
    }
    p
}

/// Moves `drift` so that it averages zero over `times` (the clamped basis sums to one: one
/// shift of every coefficient moves `D`).
fn recentre(drift: &mut SessionDrift, times: &[f64]) {
    if times.is_empty() {
        return;
    }
    let sum = times.iter().fold([0.0; 2], |a, &t| {
        let d = drift.displacement(t);
        [a[0] + d[0], a[1] + d[1]]
    });
    let shift = [sum[0] / times.len() as f64, sum[1] / times.len() as f64];
    for c in &mut drift.coefficients_m {
        c[0] -= shift[0];
        c[1] -= shift[1];
    }
}

/// `D(t)` with its 1σ from the per-axis covariances of the free coefficients (the spline's
/// but the first, then the creeps' amplitudes; their time constants taken as exact).
fn trajectory_point(drift: &SessionDrift, covariances: &[DMatrix<f64>], t: f64) -> TrajectoryPoint {
    let n = drift.basis.len();
    let mut values = vec![0.0; n];
    drift.basis.values(t, &mut values);
    let creeps = drift.creeps.iter().map(|c| c.log_term(t));
    let free = DVector::from_iterator(
        n - 1 + drift.creeps.len(),
        values[1..].iter().copied().chain(creeps),
    );
    let sigma = |axis: usize| {
        (free.transpose() * &covariances[axis] * &free)[0]
            .max(0.0)
            .sqrt()
    };
    TrajectoryPoint {
        time_s: t,
        displacement_m: drift.displacement(t),
        sigma_m: [sigma(0), sigma(1)],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A smooth drift with a slow oscillation (metres over seconds).
    fn truth(t: f64) -> [f64; 2] {
        [
            3e-12 * t + 2e-10 * (t / 80.0).sin(),
            -2e-12 * t + 1e-10 * (t / 120.0).cos(),
        ]
    }

    /// Comparisons of 8 bands per consecutive pair of `frames` frames of `period` s, each
    /// band `(later, earlier)` one frame period apart plus a small skew, with noise.
    fn comparisons(frames: usize, period: f64, noise: f64) -> Vec<DriftDifference> {
        let mut out = Vec::new();
        let mut state = 7u64;
        let mut uniform = move || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        };
        for k in 1..frames {
            for band in 0..8 {
                let within = period * (band as f64 + 0.5) / 8.0;
                let later = k as f64 * period + within;
                let earlier = (k - 1) as f64 * period + within + 0.3 * period / 8.0;
                let (a, b) = (truth(later), truth(earlier));
                out.push(DriftDifference {
                    later_s: later,
                    earlier_s: earlier,
                    difference_m: [
                        a[0] - b[0] + noise * uniform(),
                        a[1] - b[1] + noise * uniform(),
                    ],
                });
            }
        }
        out
    }

    #[test]
    fn a_smooth_drift_is_recovered_from_its_differences_up_to_a_constant() {
        let (frames, period) = (12, 44.0);
        let differences = comparisons(frames, period, 2e-12);
        let basis = SplineBasis {
            start_s: 0.0,
            end_s: frames as f64 * period,
            interior_knots: frames - 1,
        };
        let first: Vec<f64> = (0..50).map(|i| period * i as f64 / 50.0).collect();
        let starts: Vec<f64> = (0..frames).map(|k| k as f64 * period).collect();
        let fit = fit_drift_differences(&differences, basis, &[], &first, &starts).expect("fit");
        // The truth, pinned the same way.
        let mean = first.iter().fold([0.0; 2], |a, &t| {
            let d = truth(t);
            [a[0] + d[0] / 50.0, a[1] + d[1] / 50.0]
        });
        for (k, s) in fit.frame_starts.iter().enumerate() {
            let t = truth(s.time_s);
            let error = [
                s.displacement_m[0] - (t[0] - mean[0]),
                s.displacement_m[1] - (t[1] - mean[1]),
            ];
            // The drift moves ~1.5 nm over the session; within 20 pm at every start.
            assert!(
                error[0].abs() < 20e-12 && error[1].abs() < 20e-12,
                "frame {k}: {error:?}"
            );
            if k > 0 {
                assert!(s.sigma_m[0] > 0.0 && s.sigma_m[0] < 20e-12, "{s:?}");
            }
        }
        assert!(fit.rms_residual_m[0] < 3e-12, "{:?}", fit.rms_residual_m);
    }

    #[test]
    fn a_wrong_comparison_is_outweighed() {
        let (frames, period) = (8, 44.0);
        let mut differences = comparisons(frames, period, 1e-12);
        differences[13].difference_m[0] += 500e-12;
        let basis = SplineBasis {
            start_s: 0.0,
            end_s: frames as f64 * period,
            interior_knots: frames - 1,
        };
        let first = [0.0, 10.0, 20.0, 30.0, 40.0];
        let fit = fit_drift_differences(&differences, basis, &[], &first, &[0.0]).expect("fit");
        assert!(fit.outliers >= 1, "{}", fit.outliers);
        assert!(fit.rms_residual_m[0] < 3e-12, "{:?}", fit.rms_residual_m);
    }

    #[test]
    fn too_few_comparisons_are_refused() {
        let differences = comparisons(2, 44.0, 0.0);
        let basis = SplineBasis {
            start_s: 0.0,
            end_s: 88.0,
            interior_knots: 20,
        };
        assert!(matches!(
            fit_drift_differences(&differences, basis, &[], &[0.0], &[0.0]),
            Err(DistortionError::TooFewFeatures { .. })
        ));
    }
}
