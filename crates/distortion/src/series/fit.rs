//! The series fit: one drift (a spline in session time), a creep after every move and one
//! hysteresis law, fitted jointly to every indexed feature of every frame against one
//! lattice of the known constant; the number of spline knots chosen by cross-validation over
//! blocks of time.

use dhct_lattice::Lattice;
use dhct_numerics::envelope::solve_positive_definite;
use dhct_numerics::lm::{Bounds, LmOptions, ResidualFit, fit_residuals_within};
use dhct_numerics::robust::{finite_median, mad_sigma_about};
use dhct_numerics::sparse_rows::sparse_normal_equations;
use nalgebra::DMatrix;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::alignment::{frame_shifts, index_series, own_rms};
use super::frame::{SeriesFeature, SeriesFrame};
use super::problem::{GAIN_AT, NM, SPLINE_AT, SeriesProblem};
use super::session_drift::{MoveCreep, SessionDrift};
use super::spline::SplineBasis;
use crate::DistortionError;
use crate::fit::{
    FitOptions, LogisticLog, hysteresis_parameters, parameter, position_irls, sigmas,
};
use crate::model::{HysteresisLaw, Parameter};
use crate::thinning::thin;

/// Most features the joint fit uses (evenly thinned in time beyond; all are placed).
pub const MAX_SERIES_FITTED: usize = 24_000;

/// Creep time constants profiled before a fit (log-spaced from two lines to two frames).
const CREEP_T0_GRID: usize = 10;

/// Features each cross-validation fit is scored on (evenly thinned in time).
const CROSS_VALIDATION_FEATURES: usize = 4000;

/// How many interior knots the drift spline gets.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum KnotChoice {
    /// Chosen by cross-validation over blocks of time among 0, 1, 2, 4, 8, … up to four
    /// per frame.
    CrossValidated,
    /// This many.
    Fixed(usize),
}

/// Options of [`fit_series`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SeriesOptions {
    /// Hysteresis law and robust rounds (the secant option does not apply).
    pub fit: FitOptions,
    /// The drift spline's knots.
    pub knots: KnotChoice,
}

/// The cross-validated misfit of one knot count.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct KnotScore {
    /// Interior knots.
    pub interior_knots: usize,
    /// Robust RMS deviation (per axis the MAD scale) of the held-out features from their
    /// sites, metres.
    pub held_out_rms_m: f64,
}

/// One sample of the fitted drift trajectory.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TrajectoryPoint {
    /// Session time, seconds.
    pub time_s: f64,
    /// `D(T)`, metres, instrument frame.
    pub displacement_m: [f64; 2],
    /// Its 1σ per axis, metres (from the spline and creep amplitudes' covariance).
    pub sigma_m: [f64; 2],
}

/// The result of [`fit_series`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SeriesFit {
    /// The drift and creep over the session.
    pub drift: SessionDrift,
    /// The fast-scan hysteresis shared by every frame.
    pub hysteresis: HysteresisLaw,
    /// Lattice rotation θ in the instrument frame, radians.
    pub lattice_angle_rad: f64,
    /// Lattice origin in the instrument frame, metres.
    pub origin_m: [f64; 2],
    /// The scanner's gain along the instrument's y relative to its x (true over stated
    /// displacement; 1: the files' pixel aspect is right), with its 1σ. The x gain is taken
    /// as stated: a common factor of both is the fast-axis hysteresis scale's.
    pub gain_y: f64,
    /// 1σ of [`SeriesFit::gain_y`] (NaN: undetermined).
    pub gain_y_sigma: f64,
    /// The creeps' and the hysteresis law's parameters with 1σ.
    pub parameters: Vec<Parameter>,
    /// `D(T)` sampled over the session with its 1σ.
    pub trajectory: Vec<TrajectoryPoint>,
    /// `D` at each frame's start with its 1σ.
    pub frame_starts: Vec<TrajectoryPoint>,
    /// Line scan time the hysteresis law is in, seconds.
    pub line_time_s: f64,
    /// Robust RMS of the fitted features' deviations from their sites, metres.
    pub rms_deviation_m: f64,
    /// Features in the fit.
    pub features: usize,
    /// The knot counts tried and their held-out misfit (empty when fixed).
    pub knot_scores: Vec<KnotScore>,
    /// Per frame: the RMS deviation of its fitted features from their sites, metres. A frame
    /// far above the others was not explained by the session's model (misplaced by a
    /// lattice vector, or something happened during it).
    #[serde(default)]
    pub frame_rms_m: Vec<f64>,
    /// Per frame: the same under the frame's own single-frame model (one lattice fitted to
    /// that frame alone), metres: the yardstick of [`SeriesFit::frame_rms_m`].
    #[serde(default)]
    pub own_rms_m: Vec<f64>,
    /// Session times of the moves (0: the one before the session) whose creep the data did
    /// not resolve (its time constant ran to a bound): left out of the model, the drift
    /// spline takes what there is of it.
    #[serde(default)]
    pub unresolved_creeps_s: Vec<f64>,
}

impl SeriesFit {
    /// Moves the session frame so that `D` is zero on average at `times` (the first frame's
    /// features): the fit fixes `D(0) = 0` only at one instant, where a spline may take up
    /// the noise of a few lines; the first frame as its files place it, on average, is a
    /// steadier reference. The registered positions are unchanged but for that translation.
    fn recentre_on(&mut self, times: &[f64]) {
        if times.is_empty() {
            return;
        }
        let sum = times.iter().fold([0.0; 2], |a, &t| {
            let d = self.drift.displacement(t);
            [a[0] + d[0], a[1] + d[1]]
        });
        let shift = [sum[0] / times.len() as f64, sum[1] / times.len() as f64];
        // The clamped spline's basis sums to 1: one shift of every coefficient moves D.
        for c in &mut self.drift.coefficients_m {
            c[0] -= shift[0];
            c[1] -= shift[1];
        }
        self.origin_m = [self.origin_m[0] - shift[0], self.origin_m[1] - shift[1]];
        for p in self
            .trajectory
            .iter_mut()
            .chain(self.frame_starts.iter_mut())
        {
            p.displacement_m = [
                p.displacement_m[0] - shift[0],
                p.displacement_m[1] - shift[1],
            ];
        }
    }

    /// Session position (instrument frame, metres) of `f` under the fit.
    pub fn position_of(&self, f: &SeriesFeature) -> [f64; 2] {
        self.position_with_lag(f, self.hysteresis_lag_s(f.pass, f.line_time_s))
    }

    /// How far the tip trails along the fast axis in `pass`, `line_time_s` seconds into
    /// the line: the hysteresis law's excess integral, seconds of fast-axis travel. The
    /// same on every line, so a caller placing many pixels computes it once per column.
    pub fn hysteresis_lag_s(&self, pass: dhct_scan::ScanPass, line_time_s: f64) -> f64 {
        match pass {
            dhct_scan::ScanPass::Trace => self.hysteresis.excess_integral(line_time_s),
            dhct_scan::ScanPass::Retrace => {
                self.hysteresis.excess_integral(self.line_time_s)
                    - self.hysteresis.excess_integral(line_time_s)
            }
        }
    }

    /// [`SeriesFit::position_of`] given `f`'s hysteresis lag
    /// ([`SeriesFit::hysteresis_lag_s`]).
    pub fn position_with_lag(&self, f: &SeriesFeature, lag: f64) -> [f64; 2] {
        let d = self.drift.displacement(f.time_s);
        let y = f.controller_m[1] + (self.gain_y - 1.0) * (f.controller_m[1] - f.centre_m[1]);
        [
            f.controller_m[0] + f.lag_direction_m_per_s[0] * lag + d[0],
            y + f.lag_direction_m_per_s[1] * lag + d[1],
        ]
    }
}

/// Fits one model to every frame of `frames` (at least two, in time order, with the same
/// size, pitch and timing) against `lattice`.
pub fn fit_series(
    frames: &[SeriesFrame],
    lattice: &dyn Lattice,
    options: &SeriesOptions,
) -> Result<SeriesFit, DistortionError> {
    check_frames(frames)?;
    let shifts = frame_shifts(frames, lattice)?;
    let placed = |f: &SeriesFeature| {
        let p = frames[f.frame].own_position(f.input, f.feature_index);
        let s = shifts[f.frame];
        [p[0] + s[0], p[1] + s[1]]
    };
    let mut features = index_series(frames, lattice, &placed)?;
    let mut setup = Setup::new(frames, options);
    let own = own_rms(frames, lattice);
    let knots = match options.knots {
        KnotChoice::Fixed(k) => (k, Vec::new()),
        KnotChoice::CrossValidated => {
            let noise = finite_median(own.iter().copied()).unwrap_or(f64::NAN);
            setup.cross_validate(&features, frames, &shifts, noise)?
        }
    };
    let mut fit = setup.fit(
        &features,
        &setup.start_drift(frames, &shifts, knots.0),
        None,
    )?;
    // A creep whose time constant ran to a bound, or whose amplitude the data do not fix
    // (1σ beyond its value on both axes), is not resolved (the spline took it, or it was not
    // there): fitted again without it, and said.
    let unresolved: Vec<f64> = fit
        .drift
        .creeps
        .iter()
        .enumerate()
        .filter(|(k, c)| {
            let amplitude_loose = (0..2).all(|axis| {
                let name = format!("creep{k}_C_{}", ["x", "y"][axis]);
                fit.parameters
                    .iter()
                    .find(|p| p.name == name)
                    .is_none_or(|p| !p.is_determined() || p.sigma >= p.value.abs())
            });
            setup.t0_map.at_bound(setup.t0_map.parameter(c.t0_s)) || amplitude_loose
        })
        .map(|(_, c)| c.start_s)
        .collect();
    if !unresolved.is_empty() {
        // Left out only when the fit without it is as good: a creep the spline trades
        // with may still be the one thing that follows a move's first seconds.
        let kept = setup.creep_starts.clone();
        setup.creep_starts.retain(|s| !unresolved.contains(s));
        let start = setup.start_drift(frames, &shifts, knots.0);
        let worst = |f: &SeriesFit| {
            frame_rms(f, &features, frames.len())
                .into_iter()
                .filter(|v| v.is_finite())
                .fold(0.0, f64::max)
        };
        match setup.fit(&features, &start, None) {
            Ok(without) if worst(&without) <= 1.05 * worst(&fit) => {
                fit = without;
                fit.unresolved_creeps_s = unresolved;
            }
            _ => setup.creep_starts = kept,
        }
    }
    // Index again in the fitted frame while that indexes markedly more features.
    for _ in 0..2 {
        let Ok(again) = index_series(frames, lattice, &|f| fit.position_of(f)) else {
            break;
        };
        if (again.len() as f64) < 1.02 * features.len() as f64 {
            break;
        }
        let Ok(better) = setup.fit(&again, &fit.drift, Some(&fit)) else {
            break;
        };
        features = again;
        fit = better;
    }
    fit.knot_scores = knots.1;
    let first: Vec<f64> = features
        .iter()
        .filter(|f| f.frame == 0)
        .map(|f| f.time_s)
        .collect();
    fit.recentre_on(&first);
    fit.frame_rms_m = frame_rms(&fit, &features, frames.len());
    fit.own_rms_m = own;
    check_explained(&fit)?;
    Ok(fit)
}

/// Largest ratio of a frame's RMS deviation under the series model to that under its own
/// model: noise alone gives about 1 (the series model has fewer parameters per frame, the
/// lattice fit of one frame more), a frame placed a lattice period off 5 or more.
pub const MAX_UNEXPLAINED_RATIO: f64 = 2.0;

/// The scanner y gains (relative to x) a series fit may end at: a scanner's calibration
/// is off by per cent, not by half.
pub const GAIN_RANGE: (f64, f64) = (0.67, 1.5);

/// Intervals per frame at whose ends a start's spline is fitted.
const START_SAMPLES: usize = 20;

/// Bounds of `n` series parameters: the scanner's y gain inside [`GAIN_RANGE`], the others
/// free. A mirrored slow axis (gain −1) with a drift near twice the slow-scan speed making
/// up for it within each frame is a false minimum that unbounded fits from a rough start
/// have ended in; no scanner is mirrored.
fn gain_bounds(n: usize) -> Bounds {
    let mut lower = vec![f64::NEG_INFINITY; n];
    let mut upper = vec![f64::INFINITY; n];
    lower[GAIN_AT] = GAIN_RANGE.0 - 1.0;
    upper[GAIN_AT] = GAIN_RANGE.1 - 1.0;
    Bounds { lower, upper }
}

/// An error naming the frame the series model explains worst, when it is past
/// [`MAX_UNEXPLAINED_RATIO`], or the gain, when it is outside [`GAIN_RANGE`].
fn check_explained(fit: &SeriesFit) -> Result<(), DistortionError> {
    let (low, high) = GAIN_RANGE;
    // The fit keeps the gain inside the range (gain_bounds): one that ends on a bound was
    // stopped there, not fixed by the data.
    if !(fit.gain_y > low && fit.gain_y < high) {
        return Err(DistortionError::ImplausibleGain {
            gain: fit.gain_y,
            low,
            high,
        });
    }
    let worst = fit
        .frame_rms_m
        .iter()
        .zip(&fit.own_rms_m)
        .enumerate()
        .filter(|(_, (s, o))| s.is_finite() && o.is_finite() && **o > 0.0)
        .max_by(|a, b| (a.1.0 / a.1.1).total_cmp(&(b.1.0 / b.1.1)));
    match worst {
        Some((frame, (series, own))) if series / own > MAX_UNEXPLAINED_RATIO => {
            Err(DistortionError::SeriesNotExplained {
                frame,
                series_pm: series * 1e12,
                own_pm: own * 1e12,
                limit: MAX_UNEXPLAINED_RATIO,
            })
        }
        _ => Ok(()),
    }
}

/// RMS deviation of each frame's features from their sites under `fit`, metres.
fn frame_rms(fit: &SeriesFit, features: &[SeriesFeature], frames: usize) -> Vec<f64> {
    let (s, c) = fit.lattice_angle_rad.sin_cos();
    let mut sums = vec![(0.0, 0usize); frames];
    for f in features {
        let q = fit.position_of(f);
        let [ux, uy] = f.site_m;
        let dx = q[0] - fit.origin_m[0] - (c * ux - s * uy);
        let dy = q[1] - fit.origin_m[1] - (s * ux + c * uy);
        sums[f.frame].0 += dx * dx + dy * dy;
        sums[f.frame].1 += 1;
    }
    sums.iter()
        .map(|(sum, n)| {
            if *n > 0 {
                (sum / *n as f64).sqrt()
            } else {
                f64::NAN
            }
        })
        .collect()
}

/// Frames a series can be fitted from: at least two, same size, pitch and line timing.
fn check_frames(frames: &[SeriesFrame]) -> Result<(), DistortionError> {
    let Some(first) = frames.first() else {
        return Err(DistortionError::BadParameter(
            "a series needs frames".into(),
        ));
    };
    if frames.len() < 2 {
        return Err(DistortionError::BadParameter(
            "a series needs at least two frames; one frame is fitted by itself".into(),
        ));
    }
    let g0 = first.geometry;
    for (k, frame) in frames.iter().enumerate() {
        let g = frame.geometry;
        let same = g.columns() == g0.columns()
            && g.rows() == g0.rows()
            && (g.pitch_x() / g0.pitch_x() - 1.0).abs() < 1e-6
            && (g.pitch_y() / g0.pitch_y() - 1.0).abs() < 1e-6
            && (g.line_scan_time() / g0.line_scan_time() - 1.0).abs() < 1e-6;
        if !same {
            return Err(DistortionError::BadParameter(format!(
                "frame {k} is {}x{} px of {:.4e} x {:.4e} m with {:.4e} s lines, frame 0 is \
                 {}x{} px of {:.4e} x {:.4e} m with {:.4e} s lines: a series fit needs \
                 frames of one size, pitch and timing",
                g.columns(),
                g.rows(),
                g.pitch_x(),
                g.pitch_y(),
                g.line_scan_time(),
                g0.columns(),
                g0.rows(),
                g0.pitch_x(),
                g0.pitch_y(),
                g0.line_scan_time()
            )));
        }
        if k > 0
            && frame.start_s
                < frames[k - 1].start_s + frames[k - 1].geometry.frame_duration() * 0.999
        {
            return Err(DistortionError::BadParameter(format!(
                "frame {k} starts {:.1} s into the session, before frame {} ended ({:.1} s): \
                 frames must be in time order and not overlap",
                frame.start_s,
                k - 1,
                frames[k - 1].start_s + frames[k - 1].geometry.frame_duration()
            )));
        }
    }
    Ok(())
}

/// What every fit of one series shares.
struct Setup {
    options: SeriesOptions,
    end_s: f64,
    line_time_s: f64,
    creep_starts: Vec<f64>,
    t0_map: LogisticLog,
    start_law: HysteresisLaw,
    frame_starts_s: Vec<f64>,
    frame_duration_s: f64,
}

impl Setup {
    fn new(frames: &[SeriesFrame], options: &SeriesOptions) -> Setup {
        let g0 = frames[0].geometry;
        let last = frames.last().unwrap_or(&frames[0]);
        let end_s = last.start_s + last.geometry.frame_duration();
        // A creep after every move of the frame centre. The creep left from before the
        // session is the drift spline's: a logarithm starting at the session's start trades
        // with the spline without limit (nanometres of each) and sends the fit astray.
        let mut creep_starts = Vec::new();
        for pair in frames.windows(2) {
            let (a, b) = (pair[0].geometry.offset(), pair[1].geometry.offset());
            if (a.0 - b.0).hypot(a.1 - b.1) > 0.5 * g0.pitch_x().min(g0.pitch_y()) {
                creep_starts.push(pair[1].start_s);
            }
        }
        Setup {
            options: *options,
            end_s,
            line_time_s: g0.line_scan_time(),
            creep_starts,
            t0_map: LogisticLog::for_frame(g0.line_scan_time(), g0.frame_duration()),
            start_law: frames[0].model.hysteresis.clone(),
            frame_starts_s: frames.iter().map(|f| f.start_s).collect(),
            frame_duration_s: g0.frame_duration(),
        }
    }

    /// The start: each frame's own creep for the creeps (where plausible), the spline
    /// fitted to what the creeps leave of each frame's whole displacement (its shift plus
    /// its own drift and creep since its start).
    fn start_drift(
        &self,
        frames: &[SeriesFrame],
        shifts: &[[f64; 2]],
        knots: usize,
    ) -> SessionDrift {
        let basis = SplineBasis {
            start_s: 0.0,
            end_s: self.end_s,
            interior_knots: knots,
        };
        let creeps: Vec<MoveCreep> = self
            .creep_starts
            .iter()
            .map(|&start_s| {
                let frame = frames
                    .iter()
                    .find(|f| f.start_s >= start_s)
                    .unwrap_or(&frames[0]);
                let own = &frame.model.drift;
                let g = frame.geometry;
                // A frame alone often cannot separate its creep from its drift (C of
                // micrometres traded against v): such a start is taken as no creep.
                let plausible = own.creep_m[0].hypot(own.creep_m[1])
                    <= 0.1 * g.width().hypot(g.height())
                    && !self.t0_map.at_bound(self.t0_map.parameter(own.t0_s));
                if plausible {
                    MoveCreep {
                        start_s,
                        coefficient_m: g.vector_to_instrument(own.creep_m),
                        t0_s: own.t0_s,
                    }
                } else {
                    MoveCreep {
                        start_s,
                        coefficient_m: [0.0; 2],
                        t0_s: 0.05 * g.frame_duration(),
                    }
                }
            })
            .collect();
        let with_creeps = SessionDrift {
            coefficients_m: vec![[0.0; 2]; basis.len()],
            basis: basis.clone(),
            creeps,
        };
        // Frames placed from their images: each frame's own drift may hold a slow-axis
        // gain error as a fake drift (the images' steps do not), so the start is the drift
        // between the frames' starts, linear over each frame, and the fit finds the gain.
        let placed_by_images = frames.iter().any(|f| f.observed_step.is_some());
        let between = |k: usize| -> [f64; 2] {
            let (a, b) = match k + 1 < frames.len() {
                true => (k, k + 1),
                false if k > 0 => (k - 1, k),
                false => return [0.0; 2],
            };
            let dt = (frames[b].start_s - frames[a].start_s).max(f64::MIN_POSITIVE);
            [
                (shifts[b][0] - shifts[a][0]) / dt,
                (shifts[b][1] - shifts[a][1]) / dt,
            ]
        };
        // The displacement within frame `k`, `t` seconds after its start: the frame's own
        // drift and creep together (a frame alone fixes their sum, not the parts: its creep
        // and drift may trade micrometres, as above).
        let within = |k: usize, t: f64| -> [f64; 2] {
            if placed_by_images {
                let v = between(k);
                return [v[0] * t, v[1] * t];
            }
            frames[k].own_drift(t)
        };
        let samples: Vec<(f64, [f64; 2])> = self
            .start_samples()
            .map(|(k, t)| {
                let (at, shift, drift) = (frames[k].start_s + t, shifts[k], within(k, t));
                let creep = with_creeps.displacement(at);
                (
                    at,
                    [
                        shift[0] + drift[0] - creep[0],
                        shift[1] + drift[1] - creep[1],
                    ],
                )
            })
            .collect();
        let coefficients_m = fit_spline(&basis, &samples);
        SessionDrift {
            coefficients_m,
            ..with_creeps
        }
    }

    fn problem<'a>(&self, features: &'a [SeriesFeature], basis: SplineBasis) -> SeriesProblem<'a> {
        let choice = self.options.fit.hysteresis.resolved(&self.start_law);
        SeriesProblem::new(
            features,
            basis,
            self.creep_starts.clone(),
            choice,
            self.line_time_s,
            self.t0_map,
        )
    }

    /// The robust fit from `start` (θ and the origin placed in closed form unless `previous`
    /// gives them).
    fn fit(
        &self,
        features: &[SeriesFeature],
        start: &SessionDrift,
        previous: Option<&SeriesFit>,
    ) -> Result<SeriesFit, DistortionError> {
        let start = match previous {
            Some(_) => start.clone(),
            None => self.best_creep_start(features, start),
        };
        self.fit_rounds(features, &start, previous, self.options.fit.robust_rounds)
    }

    /// `start` with the creeps' time constants profiled: `t0` is the one strongly
    /// non-linear parameter (from a creep of amplitude 0 the fit cannot move it, and a free
    /// `t0` trades with the spline towards a bound), so the plain fit is made with every
    /// creep's `t0` held at each of [`CREEP_T0_GRID`] values (log-spaced from two lines to
    /// two frames) and the lowest cost's fitted drift is the start. Each trial keeps the
    /// start's creep amplitudes and refits the spline under them ([`Setup::with_creeps`]).
    /// The gain stays inside [`GAIN_RANGE`].
    fn best_creep_start(&self, features: &[SeriesFeature], start: &SessionDrift) -> SessionDrift {
        if start.creeps.is_empty() {
            return start.clone();
        }
        let features = thin(features, CROSS_VALIDATION_FEATURES);
        let problem = self.problem(&features, start.basis.clone());
        let law = self.start_law.clone();
        let (low, high) = (2.0 * self.line_time_s, 2.0 * self.frame_duration_s);
        // The trials run side by side; the lowest cost is then taken in grid order, so the
        // choice does not depend on the threads.
        let trials: Vec<Option<(f64, SessionDrift)>> = (0..CREEP_T0_GRID)
            .into_par_iter()
            .map(|j| {
                let t0 = low * (high / low).powf(j as f64 / (CREEP_T0_GRID - 1) as f64);
                let mut creeps = start.creeps.clone();
                for creep in &mut creeps {
                    creep.t0_s = t0;
                }
                let candidate = self.with_creeps(start, creeps);
                let (theta, origin) = place(&features, &candidate, &law, self.line_time_s);
                let p0 = problem.start((theta, origin, 1.0), &candidate, &law);
                let at = problem.creep_at();
                let Bounds {
                    mut lower,
                    mut upper,
                } = gain_bounds(p0.len());
                for k in 0..candidate.creeps.len() {
                    lower[at + 3 * k + 2] = p0[at + 3 * k + 2];
                    upper[at + 3 * k + 2] = p0[at + 3 * k + 2];
                }
                let lm = LmOptions {
                    max_iterations: 30,
                    ..LmOptions::default()
                };
                let bounds = Some(Bounds { lower, upper });
                let weights = problem.plain_weights();
                let fit =
                    fit_residuals_within(&problem, problem.rows(), &p0, &weights, bounds, &lm)?;
                let cost: f64 = fit
                    .residuals
                    .iter()
                    .zip(&weights)
                    .map(|(r, w)| w * r * r)
                    .sum();
                cost.is_finite().then(|| (cost, problem.drift(&fit.params)))
            })
            .collect();
        trials
            .into_iter()
            .flatten()
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .map_or_else(|| start.clone(), |(_, drift)| drift)
    }

    /// Where a start's spline is fitted: [`START_SAMPLES`] + 1 times evenly over every
    /// frame (the frames share one duration), each as (frame, seconds since its start).
    fn start_samples(&self) -> impl Iterator<Item = (usize, f64)> + '_ {
        let step = self.frame_duration_s / START_SAMPLES as f64;
        (0..self.frame_starts_s.len())
            .flat_map(move |k| (0..=START_SAMPLES).map(move |j| (k, step * j as f64)))
    }

    /// `drift` with `creeps` in place of its own and the spline fitted again to what they
    /// leave of its displacement within every frame: the same whole displacement, so a
    /// creep profiled at another time constant starts from the session's displacement, not
    /// from what the creep it replaces left over (which, carried over a long session, is
    /// nanometres off).
    fn with_creeps(&self, drift: &SessionDrift, creeps: Vec<MoveCreep>) -> SessionDrift {
        let creeps_alone = SessionDrift {
            coefficients_m: vec![[0.0; 2]; drift.basis.len()],
            basis: drift.basis.clone(),
            creeps,
        };
        let samples: Vec<(f64, [f64; 2])> = self
            .start_samples()
            .map(|(k, t)| {
                let at = self.frame_starts_s[k] + t;
                let (whole, creep) = (drift.displacement(at), creeps_alone.displacement(at));
                (at, [whole[0] - creep[0], whole[1] - creep[1]])
            })
            .collect();
        SessionDrift {
            coefficients_m: fit_spline(&drift.basis, &samples),
            ..creeps_alone
        }
    }

    /// [`Setup::fit`] with `robust_rounds` Huber rounds.
    fn fit_rounds(
        &self,
        features: &[SeriesFeature],
        start: &SessionDrift,
        previous: Option<&SeriesFit>,
        robust_rounds: usize,
    ) -> Result<SeriesFit, DistortionError> {
        if features.len() < 24 {
            return Err(DistortionError::TooFewFeatures {
                what: "series fit",
                found: features.len(),
                needed: 24,
            });
        }
        let features = thin(features, MAX_SERIES_FITTED);
        let problem = self.problem(&features, start.basis.clone());
        let law = previous.map_or_else(|| self.start_law.clone(), |p| p.hysteresis.clone());
        let placed = match previous {
            Some(p) => (p.lattice_angle_rad, p.origin_m, p.gain_y),
            None => {
                let (theta, origin) = place(&features, start, &law, self.line_time_s);
                (theta, origin, 1.0)
            }
        };
        let p0 = problem.start(placed, start, &law);
        let bounds = gain_bounds(p0.len());
        let (fit, weights) = position_irls(
            &problem,
            (problem.rows(), problem.features.len()),
            problem.plain_weights(),
            p0,
            robust_rounds,
            "series",
            Some(&bounds),
        )?;
        if !fit.params.iter().all(|v| v.is_finite()) {
            return Err(DistortionError::FitFailed("series"));
        }
        Ok(self.result(&problem, &fit, &weights))
    }

    fn result(&self, problem: &SeriesProblem, fit: &ResidualFit, weights: &[f64]) -> SeriesFit {
        let p = &fit.params;
        let n = p.len();
        let covariance = scaled_covariance(fit, weights);
        let sigma = sigmas(&covariance, 1.0, n);
        let drift = problem.drift(p);
        let mut parameters = vec![parameter("gain_y", 1.0 + p[GAIN_AT], sigma[GAIN_AT], "1")];
        let at = problem.creep_at();
        for (k, creep) in drift.creeps.iter().enumerate() {
            let q = p[at + 3 * k + 2];
            let s = &sigma[at + 3 * k..at + 3 * k + 3];
            parameters.push(parameter(
                &format!("creep{k}_C_x"),
                creep.coefficient_m[0],
                s[0] / NM,
                "m",
            ));
            parameters.push(parameter(
                &format!("creep{k}_C_y"),
                creep.coefficient_m[1],
                s[1] / NM,
                "m",
            ));
            parameters.push(parameter(
                &format!("creep{k}_t0"),
                creep.t0_s,
                self.t0_map.derivative(q) * s[2],
                "s",
            ));
        }
        let h_at = problem.hysteresis_at();
        parameters.extend(hysteresis_parameters(
            problem.choice,
            &p[h_at..],
            &sigma[h_at..],
        ));
        let sample = |t: f64| trajectory_point(problem, &drift, covariance.as_ref(), t);
        let trajectory = (0..=200)
            .map(|j| sample(self.end_s * j as f64 / 200.0))
            .collect();
        let frame_starts = self.frame_starts_s.iter().map(|&t| sample(t)).collect();
        let m = problem.features.len();
        let robust = mad_sigma_about(&fit.residuals[..2 * m], 0.0).unwrap_or(f64::NAN);
        SeriesFit {
            hysteresis: problem.law(p),
            drift,
            lattice_angle_rad: p[0],
            origin_m: [p[1] / NM, p[2] / NM],
            gain_y: 1.0 + p[GAIN_AT],
            gain_y_sigma: sigma[GAIN_AT],
            parameters,
            trajectory,
            frame_starts,
            line_time_s: self.line_time_s,
            rms_deviation_m: robust * std::f64::consts::SQRT_2 / NM,
            features: m,
            knot_scores: Vec::new(),
            unresolved_creeps_s: Vec::new(),
            frame_rms_m: Vec::new(),
            own_rms_m: Vec::new(),
        }
    }

    /// The knot count with the lowest held-out misfit: 5 folds of blocks of time (an
    /// eighth of a frame each), each fitted without its features and scored on them. The
    /// knot counts double from 0 until two in a row score worse once the misfit is near
    /// `noise_m` (a frame's misfit under its own model): far above it, the spline is still
    /// too stiff for the drift (an oscillation over a long session needs knots near its
    /// period before any count helps), and a flat score says nothing yet.
    fn cross_validate(
        &self,
        features: &[SeriesFeature],
        frames: &[SeriesFrame],
        shifts: &[[f64; 2]],
        noise_m: f64,
    ) -> Result<(usize, Vec<KnotScore>), DistortionError> {
        let block = frames[0].geometry.frame_duration() / 8.0;
        let most = 4 * frames.len();
        let candidates: Vec<usize> = std::iter::once(0)
            .chain((0..).map(|e| 1usize << e).take_while(|k| *k <= most))
            .collect();
        let features = thin(features, CROSS_VALIDATION_FEATURES);
        let fold = |f: &SeriesFeature| ((f.time_s / block) as usize) % 5;
        let mut scores = Vec::new();
        for &knots in &candidates {
            let start = self.start_drift(frames, shifts, knots);
            // The folds are fitted side by side; their held-out deviations are joined in
            // fold order.
            let held: Vec<Vec<[f64; 2]>> = (0..5)
                .into_par_iter()
                .map(|k| {
                    let train: Vec<SeriesFeature> =
                        features.iter().filter(|f| fold(f) != k).copied().collect();
                    let Ok(fit) = self.fit_rounds(&train, &start, None, 0) else {
                        return Vec::new();
                    };
                    let (s, c) = fit.lattice_angle_rad.sin_cos();
                    features
                        .iter()
                        .filter(|f| fold(f) == k)
                        .map(|f| {
                            let q = fit.position_of(f);
                            let [ux, uy] = f.site_m;
                            [
                                q[0] - fit.origin_m[0] - (c * ux - s * uy),
                                q[1] - fit.origin_m[1] - (s * ux + c * uy),
                            ]
                        })
                        .collect()
                })
                .collect();
            let held_x: Vec<f64> = held.iter().flatten().map(|d| d[0]).collect();
            let held_y: Vec<f64> = held.iter().flatten().map(|d| d[1]).collect();
            // Robust: a block the training left out entirely (the first seconds of a
            // creep) may be extrapolated far off; the score is the typical held-out feature.
            if let (Some(sx), Some(sy)) =
                (mad_sigma_about(&held_x, 0.0), mad_sigma_about(&held_y, 0.0))
            {
                scores.push(KnotScore {
                    interior_knots: knots,
                    held_out_rms_m: sx.hypot(sy),
                });
            }
            if enough_knots(&scores, noise_m) {
                break;
            }
        }
        let best = scores
            .iter()
            .min_by(|a, b| a.held_out_rms_m.total_cmp(&b.held_out_rms_m))
            .map(|s| s.interior_knots)
            .ok_or(DistortionError::FitFailed("series knot cross-validation"))?;
        Ok((best, scores))
    }
}

/// The held-out misfit (over a frame's own model's) below which more knots only fit
/// noise once they stop helping; above it the drift is not followed yet.
const SETTLED_MISFIT: f64 = 2.0;

/// Whether more knots only fit noise from here on: the last two knot counts both scored
/// worse than the one before each, and the best score is within [`SETTLED_MISFIT`] of
/// `noise_m` (NaN: not known, and the scores alone decide).
fn enough_knots(scores: &[KnotScore], noise_m: f64) -> bool {
    let best = scores
        .iter()
        .map(|s| s.held_out_rms_m)
        .fold(f64::INFINITY, f64::min);
    let settled = noise_m.is_nan() || best <= SETTLED_MISFIT * noise_m;
    settled && worse_twice(scores)
}

/// Whether the last two knot counts both scored worse than the one before each.
fn worse_twice(scores: &[KnotScore]) -> bool {
    let n = scores.len();
    n >= 3
        && scores[n - 1].held_out_rms_m > scores[n - 2].held_out_rms_m
        && scores[n - 2].held_out_rms_m > scores[n - 3].held_out_rms_m
}

/// Least-squares spline coefficients (the first fixed at 0) through `samples` of
/// `(time, displacement)`. Each sample touches four basis functions, so the normal
/// equations are banded and solved in their envelope. A ridge of 1e-12 of their largest
/// diagonal leaves a coefficient no sample reaches (a knot span inside a pause between
/// frames) at 0, as the minimum-norm solution does; the others move by less than 1e-5 of
/// the largest (those only partly reached, at a pause's edges; a start value either way).
fn fit_spline(basis: &SplineBasis, samples: &[(f64, [f64; 2])]) -> Vec<[f64; 2]> {
    let free = basis.len() - 1;
    let weights = vec![1.0; samples.len()];
    // Column j − 1 holds basis function j (function 0 is fixed).
    let row = |i: usize, entries: &mut Vec<(usize, f64)>| {
        let (first, values) = basis.nonzero(samples[i].0);
        entries.extend(
            values
                .iter()
                .enumerate()
                .filter_map(|(k, v)| (first + k).checked_sub(1).map(|j| (j, *v))),
        );
    };
    let solve_axis = |axis: usize| {
        let along: Vec<f64> = samples.iter().map(|(_, d)| d[axis]).collect();
        let mut normal = sparse_normal_equations(free, &along, &weights, row);
        let ridge = 1e-12 * normal.jtwj.diagonal().max().max(f64::MIN_POSITIVE);
        normal
            .jtwj
            .set_diagonal(&normal.jtwj.diagonal().add_scalar(ridge));
        solve_positive_definite(&normal.jtwj, &normal.jtwr)
    };
    let (x, y) = (solve_axis(0), solve_axis(1));
    (0..=free)
        .map(|j| match (&x, &y) {
            (Some(x), Some(y)) if j > 0 => [x[j - 1], y[j - 1]],
            _ => [0.0; 2],
        })
        .collect()
}

/// Closed-form θ and origin placing the lattice on `features` under `drift` and `law`.
fn place(
    features: &[SeriesFeature],
    drift: &SessionDrift,
    law: &HysteresisLaw,
    line_time_s: f64,
) -> (f64, [f64; 2]) {
    let probe = SeriesFit {
        drift: drift.clone(),
        hysteresis: law.clone(),
        lattice_angle_rad: 0.0,
        origin_m: [0.0; 2],
        gain_y: 1.0,
        gain_y_sigma: f64::NAN,
        parameters: Vec::new(),
        trajectory: Vec::new(),
        frame_starts: Vec::new(),
        line_time_s,
        rms_deviation_m: 0.0,
        features: 0,
        knot_scores: Vec::new(),
        unresolved_creeps_s: Vec::new(),
        frame_rms_m: Vec::new(),
        own_rms_m: Vec::new(),
    };
    let positions: Vec<[f64; 2]> = features.iter().map(|f| probe.position_of(f)).collect();
    let count = features.len().max(1) as f64;
    let mean = |get: &dyn Fn(usize) -> [f64; 2]| {
        let s = (0..features.len()).fold([0.0; 2], |a, i| {
            let v = get(i);
            [a[0] + v[0], a[1] + v[1]]
        });
        [s[0] / count, s[1] / count]
    };
    let mp = mean(&|i| positions[i]);
    let mu = mean(&|i| features[i].site_m);
    let (mut cross, mut dot) = (0.0, 0.0);
    for (f, p) in features.iter().zip(&positions) {
        let (px, py) = (p[0] - mp[0], p[1] - mp[1]);
        let (ux, uy) = (f.site_m[0] - mu[0], f.site_m[1] - mu[1]);
        dot += ux * px + uy * py;
        cross += ux * py - uy * px;
    }
    let theta = cross.atan2(dot);
    let (s, c) = theta.sin_cos();
    (
        theta,
        [
            mp[0] - (c * mu[0] - s * mu[1]),
            mp[1] - (s * mu[0] + c * mu[1]),
        ],
    )
}

/// `σ̂²·(JᵀWJ)⁻¹`, nm units.
fn scaled_covariance(fit: &ResidualFit, weights: &[f64]) -> Option<DMatrix<f64>> {
    let chi2: f64 = fit
        .residuals
        .iter()
        .zip(weights)
        .map(|(r, w)| w * r * r)
        .sum();
    let dof = fit.residuals.len().saturating_sub(fit.params.len()).max(1) as f64;
    fit.inverse_normal().map(|c| c * (chi2 / dof))
}

/// `D(t)` with its 1σ from the covariance of the spline coefficients and creep amplitudes.
fn trajectory_point(
    problem: &SeriesProblem,
    drift: &SessionDrift,
    covariance: Option<&DMatrix<f64>>,
    t: f64,
) -> TrajectoryPoint {
    let n_basis = drift.basis.len();
    let free = n_basis - 1;
    let mut values = vec![0.0; n_basis];
    drift.basis.values(t, &mut values);
    let at = problem.creep_at();
    let sigma_m = std::array::from_fn(|axis| {
        let Some(c) = covariance else {
            return f64::NAN;
        };
        // Gradient of D_axis(t) in the parameters.
        let mut g: Vec<(usize, f64)> = values
            .iter()
            .enumerate()
            .skip(1)
            .map(|(j, v)| (SPLINE_AT + axis * free + j - 1, *v))
            .collect();
        for (k, creep) in drift.creeps.iter().enumerate() {
            g.push((at + 3 * k + axis, creep.log_term(t)));
        }
        let mut variance = 0.0;
        for &(i, gi) in &g {
            for &(j, gj) in &g {
                variance += gi * gj * c[(i, j)];
            }
        }
        variance.max(0.0).sqrt() / NM
    });
    TrajectoryPoint {
        time_s: t,
        displacement_m: drift.displacement(t),
        sigma_m,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{DistortionModel, DriftCreep, FitOptions};
    use dhct_scan::ScanGeometry;
    use nalgebra::DVector;

    fn scores(pm: &[f64]) -> Vec<KnotScore> {
        pm.iter()
            .enumerate()
            .map(|(k, v)| KnotScore {
                interior_knots: k,
                held_out_rms_m: v * 1e-12,
            })
            .collect()
    }

    /// The banded normal equations give the minimum-norm least-squares spline a dense SVD
    /// gives, also with a pause between the frames that leaves knot spans without samples.
    #[test]
    fn the_start_spline_is_the_minimum_norm_least_squares_fit() {
        let basis = SplineBasis {
            start_s: 0.0,
            end_s: 100.0,
            interior_knots: 24,
        };
        // Two "frames" of samples, 0–30 s and 70–100 s: the spans between hold none.
        let samples: Vec<(f64, [f64; 2])> = (0..=60)
            .map(|k| {
                let t = if k <= 30 { k as f64 } else { 40.0 + k as f64 };
                (t, [1e-9 * (0.05 * t).sin(), 2e-10 * t - 1e-12 * t * t])
            })
            .collect();
        let n = basis.len();
        let mut a = DMatrix::<f64>::zeros(samples.len(), n - 1);
        let mut values = vec![0.0; n];
        for (row, (t, _)) in samples.iter().enumerate() {
            basis.values(*t, &mut values);
            for j in 1..n {
                a[(row, j - 1)] = values[j];
            }
        }
        let svd = a.svd(true, true);
        let fitted = fit_spline(&basis, &samples);
        assert_eq!(fitted.len(), n);
        assert_eq!(fitted[0], [0.0; 2]);
        for axis in [0, 1] {
            let b = DVector::from_iterator(samples.len(), samples.iter().map(|s| s.1[axis]));
            let reference = svd.solve(&b, 1e-12).expect("solved");
            let scale = reference.amax();
            for j in 1..n {
                let error = (fitted[j][axis] - reference[j - 1]).abs();
                assert!(
                    error <= 1e-5 * scale,
                    "axis {axis}, coefficient {j}: {error:e}"
                );
            }
        }
    }

    /// The start drift follows each frame's whole displacement (its drift and creep as its
    /// own model gives them), placed at its shift: a frame alone fixes their sum, not the
    /// parts. (It once took each frame's drift without its creep, so a session whose frames'
    /// own creeps traded with their drifts started tens of nanometres off, and 20- and
    /// 30-frame sessions ended on a mirrored slow axis.)
    #[test]
    fn the_start_drift_follows_each_frames_own_drift_and_creep_together() {
        use dhct_scan::ScanDirection;
        let geometry = ScanGeometry::new(
            64,
            64,
            1e-10,
            1e-10,
            2e-3,
            ScanDirection::Right,
            ScanDirection::Down,
        )
        .unwrap();
        let duration = geometry.frame_duration();
        // Each frame's own model: a creep of 50 nm traded against a drift that undoes most
        // of it over the frame (the whole displacement stays a few nanometres).
        let models: Vec<DistortionModel> = (0..4)
            .map(|k| {
                let creep = 5e-8 * (1.0 + 0.2 * k as f64);
                let t0_s = 0.5 * duration;
                let undo = -creep * (duration / t0_s).ln_1p() / duration;
                let drift = DriftCreep {
                    velocity_m_per_s: [undo + 1e-11, -undo],
                    acceleration_m_per_s2: [0.0; 2],
                    creep_m: [creep, -creep],
                    t0_s,
                };
                DistortionModel::new(drift, HysteresisLaw::none())
            })
            .collect();
        // Three frames of pause between them: room for the session's drift to turn.
        let frames: Vec<SeriesFrame> = models
            .iter()
            .enumerate()
            .map(|(k, model)| SeriesFrame {
                geometry: &geometry,
                inputs: Vec::new(),
                model,
                start_s: k as f64 * 4.0 * duration,
                observed_step: None,
            })
            .collect();
        let shifts: Vec<[f64; 2]> = (0..4)
            .map(|k| [1e-9 * k as f64, -5e-10 * k as f64])
            .collect();
        let options = SeriesOptions {
            fit: FitOptions::default(),
            knots: KnotChoice::Fixed(128),
        };
        let setup = Setup::new(&frames, &options);
        let start = setup.start_drift(&frames, &shifts, 128);
        let mut worst: f64 = 0.0;
        for (frame, shift) in frames.iter().zip(&shifts) {
            for j in 0..=10 {
                let t = duration * j as f64 / 10.0;
                let expected = frame.own_drift(t);
                let got = start.displacement(frame.start_s + t);
                for axis in 0..2 {
                    worst = worst.max((got[axis] - shift[axis] - expected[axis]).abs());
                }
            }
        }
        assert!(worst < 2e-11, "start drift off by {:.3} nm", worst * 1e9);
    }

    /// A flat score far above the noise (a spline still too stiff for an oscillating
    /// drift) asks for more knots; the same rise at the noise level stops.
    #[test]
    fn knots_stop_being_added_only_once_the_misfit_is_near_the_noise() {
        let noise = 1.1e-12;
        assert!(!enough_knots(&scores(&[232.7, 231.9, 232.3, 232.8]), noise));
        assert!(enough_knots(&scores(&[3.0, 1.2, 1.3, 1.4]), noise));
        assert!(!enough_knots(&scores(&[3.0, 1.2, 1.3]), noise));
        assert!(!enough_knots(&scores(&[3.0, 1.2, 1.1, 1.4]), noise));
        assert!(enough_knots(
            &scores(&[232.7, 231.9, 232.3, 232.8]),
            f64::NAN
        ));
    }
}
