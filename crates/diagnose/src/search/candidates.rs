//! The candidate effects and their proposals: each candidate, given the current model,
//! offers one or more starting models (one per point of its shape grid — a change time, a
//! relaxation time, a vibration frequency …) whose new parameters start at zero, together
//! with the weighted Jacobian columns of those new parameters, used for the linearised
//! screening (the shape with the largest χ² reduction wins, then a full refit follows).

use dhct_scan::ScanGeometry;
use dhct_simulate::EffectConfig;
use dhct_simulate::effects::{
    AsymmetricHysteresis, ExponentialCreep, FastScanHysteresis, HeightCoupling, HysteresisLaw,
    LineDrift, LogCreep, PiezoNonlinearity, ScanCoupling, SlowScanHysteresis, TipChange, Vibration,
};
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

use crate::evidence::spectrum::periodogram_peaks;
use crate::model::data::Observation;
use crate::model::global::{GlobalModel, ModelTerm, Term, Transform, sim_term, term_displacements};
use crate::model::terms::{CubicDrift, QuadraticField};

/// An unmodelled effect the diagnosis can add to the base model.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Candidate {
    /// Drift within each line only (simulator `line-drift`): `d = v·τ`.
    LineDrift,
    /// Creep relaxing exponentially after a start time (`exponential-creep`).
    ExponentialCreep,
    /// A second logarithmic creep impulse after a start time (`creep` with `start_s > 0`).
    SecondCreep,
    /// Different fast-scan hysteresis laws in trace and retrace (`asymmetric-hysteresis`).
    AsymmetricHysteresis,
    /// Slow-scan hysteresis after the frame start (`slow-hysteresis`, exponential law).
    SlowHysteresis,
    /// Sinusoidal vibration (`vibration`).
    Vibration,
    /// A sudden lateral tip jump (`tip-change`).
    TipChange,
    /// Lateral shift proportional to the terrace height (`height-coupling`, T_fz).
    HeightCoupling,
    /// Linear slow↔fast scanner coupling (`scan-coupling`; nearly degenerate with lattice
    /// rotation + drift, so rarely identifiable from positions).
    ScanCoupling,
    /// Drift with a constant jerk (`d = j·t³/6`), beyond the base velocity + acceleration.
    HigherOrderDrift,
    /// A smooth time-independent field quadratic in position (local strain / warped lattice).
    LocalStrain,
    /// The scanner's displacement not proportional to its drive (`piezo-nonlinearity`),
    /// the same in trace and retrace: of its curves in each axis's commanded position only
    /// the quadratic one along the fast axis is fitted (the cubic one along x is a
    /// symmetric hysteresis law's, and along y position is slow-scan time: drift).
    PiezoNonlinearity,
}

impl Candidate {
    /// Every candidate.
    pub const ALL: [Candidate; 12] = [
        Candidate::LineDrift,
        Candidate::ExponentialCreep,
        Candidate::SecondCreep,
        Candidate::AsymmetricHysteresis,
        Candidate::SlowHysteresis,
        Candidate::Vibration,
        Candidate::TipChange,
        Candidate::HeightCoupling,
        Candidate::ScanCoupling,
        Candidate::HigherOrderDrift,
        Candidate::LocalStrain,
        Candidate::PiezoNonlinearity,
    ];

    /// Whether the effect is confined to part of the frame (after an onset, decaying or
    /// stepping once) rather than acting throughout it; decides how it is cross-validated
    /// ([`crate::CvScheme`]).
    pub fn is_transient(self) -> bool {
        matches!(
            self,
            Candidate::ExponentialCreep
                | Candidate::SecondCreep
                | Candidate::SlowHysteresis
                | Candidate::TipChange
        )
    }

    /// Whether a scan can hold several of it, each with its own parameters: tip jumps,
    /// vibrations at different frequencies (e.g. harmonics), creep events. The greedy
    /// selection keeps such a candidate after adding it, so a second one can be added when
    /// it passes on its own; the others act on the whole frame once.
    pub fn is_repeatable(self) -> bool {
        matches!(
            self,
            Candidate::TipChange | Candidate::Vibration | Candidate::SecondCreep
        )
    }

    /// Kebab-case name.
    pub fn name(self) -> &'static str {
        match self {
            Candidate::LineDrift => "line-drift",
            Candidate::ExponentialCreep => "exponential-creep",
            Candidate::SecondCreep => "second-creep",
            Candidate::AsymmetricHysteresis => "asymmetric-hysteresis",
            Candidate::SlowHysteresis => "slow-hysteresis",
            Candidate::Vibration => "vibration",
            Candidate::TipChange => "tip-change",
            Candidate::HeightCoupling => "height-coupling",
            Candidate::ScanCoupling => "scan-coupling",
            Candidate::HigherOrderDrift => "higher-order-drift",
            Candidate::LocalStrain => "local-strain",
            Candidate::PiezoNonlinearity => "piezo-nonlinearity",
        }
    }

    /// The candidate that models a simulator effect entry (`None` for the base model's own
    /// effects: thermal drift, creep from the frame start, symmetric fast hysteresis).
    pub fn of_effect(effect: &EffectConfig) -> Option<Candidate> {
        Some(match effect {
            EffectConfig::LineDrift(_) => Candidate::LineDrift,
            EffectConfig::ExponentialCreep(_) => Candidate::ExponentialCreep,
            EffectConfig::Creep(c) if c.start_s > 0.0 => Candidate::SecondCreep,
            EffectConfig::AsymmetricHysteresis(_) => Candidate::AsymmetricHysteresis,
            EffectConfig::SlowHysteresis(_) => Candidate::SlowHysteresis,
            EffectConfig::Vibration(_) => Candidate::Vibration,
            EffectConfig::TipChange(_) => Candidate::TipChange,
            EffectConfig::HeightCoupling(_) => Candidate::HeightCoupling,
            EffectConfig::ScanCoupling(_) => Candidate::ScanCoupling,
            EffectConfig::PiezoNonlinearity(_) => Candidate::PiezoNonlinearity,
            _ => return None,
        })
    }
}

impl std::fmt::Display for Candidate {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Builds the refit's start model on top of a base (the current model, possibly with its
/// parameters re-adjusted for the new term) from the screened coefficients of the new
/// columns.
pub(crate) type Builder = Box<dyn Fn(&GlobalModel, &[f64]) -> Option<GlobalModel> + Send + Sync>;

/// One starting point of a candidate.
pub(crate) struct Proposal {
    pub candidate: Candidate,
    /// Human-readable shape (e.g. "t = 41.2 s").
    pub shape: String,
    /// Weighted columns of the new parameters (rows `[x0, y0, …]`).
    pub columns: DMatrix<f64>,
    pub build: Builder,
    /// Parameters chosen on a grid or free in the refit beyond the columns (for BIC).
    pub extra_parameters: usize,
    /// How many independent shapes the search behind this proposal compared, when that is
    /// more than the candidate's own proposals (a periodogram's frequencies); for the
    /// look-elsewhere penalty.
    pub searched: Option<usize>,
    /// `(time constant, onset)` of a creep candidate's grid point, seconds, for the
    /// refinement around the best one.
    pub onset: Option<(f64, f64)>,
}

/// What the proposals need to know.
pub(crate) struct Context<'a> {
    pub model: &'a GlobalModel,
    pub geometry: &'a ScanGeometry,
    pub observations: &'a [Observation],
    pub sigma: [f64; 2],
    /// Current weighted residuals, `[x0, y0, …]`.
    pub residuals: &'a [f64],
}

/// Weighted columns `∂(d/σ)/∂u_j` of a term's parameters in `mask` (fit space of its
/// transforms; a linear parameter is stepped by its typical size).
pub(crate) fn term_columns(
    term: &dyn ModelTerm,
    mask: &[bool],
    ctx: &Context,
) -> Option<DMatrix<f64>> {
    let n = ctx.observations.len();
    let p0 = term.parameters();
    let base = term_displacements(term, ctx.geometry, ctx.observations);
    let transforms = term.transforms();
    let selected: Vec<usize> = (0..p0.len()).filter(|&j| mask[j]).collect();
    let mut out = DMatrix::zeros(2 * n, selected.len());
    for (c, &j) in selected.iter().enumerate() {
        let t = transforms[j];
        let h = match t {
            Transform::Linear { typical } => typical,
            _ => t.step(p0[j]),
        };
        let mut p = p0.clone();
        p[j] = t.parameter_of(t.fit_value_of(p0[j]) + h);
        let moved = term.with_parameters(&p)?;
        let d = term_displacements(moved.as_ref(), ctx.geometry, ctx.observations);
        for i in 0..n {
            out[(2 * i, c)] = (d[i][0] - base[i][0]) / h / ctx.sigma[0];
            out[(2 * i + 1, c)] = (d[i][1] - base[i][1]) / h / ctx.sigma[1];
        }
    }
    Some(out)
}

/// A proposal that appends `term` (or replaces term `replace`), screening the parameters in
/// `new_mask`.
fn term_proposal(
    candidate: Candidate,
    shape: String,
    ctx: &Context,
    term: Term,
    new_mask: Vec<bool>,
    replace: Option<usize>,
    extra_parameters: usize,
) -> Option<Proposal> {
    let columns = term_columns(term.effect.as_ref(), &new_mask, ctx)?;
    let build: Builder = Box::new(move |base: &GlobalModel, coef: &[f64]| {
        let mut m = base.clone();
        let index = match replace {
            Some(k) => {
                m.terms[k] = term.clone();
                k
            }
            None => {
                m.terms.push(term.clone());
                m.terms.len() - 1
            }
        };
        let t = &mut m.terms[index];
        let mut p = t.effect.parameters();
        let transforms = t.effect.transforms();
        let mut k = 0;
        for j in 0..p.len() {
            if new_mask[j] {
                let tr = transforms[j];
                let step = match tr {
                    Transform::Linear { .. } => coef[k],
                    _ => coef[k].clamp(-5.0, 5.0),
                };
                p[j] = tr.parameter_of(tr.fit_value_of(p[j]) + step);
                k += 1;
            }
        }
        t.effect = t.effect.with_parameters(&p)?;
        Some(m)
    });
    Some(Proposal {
        candidate,
        shape,
        columns,
        build,
        extra_parameters,
        searched: None,
        onset: None,
    })
}

/// Log-spaced values from `lo` to `hi` (inclusive), `count ≥ 2`.
fn log_grid(lo: f64, hi: f64, count: usize) -> Vec<f64> {
    (0..count)
        .map(|k| lo * (hi / lo).powf(k as f64 / (count - 1) as f64))
        .collect()
}

/// Every proposal of `candidate` on top of the current model (empty if not applicable).
pub(crate) fn proposals(candidate: Candidate, ctx: &Context) -> Vec<Proposal> {
    let t_max = frame_end(ctx);
    // A new term from the simulator's effect `config`, every parameter screened from zero.
    let fresh = |config: EffectConfig, mask: Vec<bool>| {
        sim_term(&config).and_then(|e| zero_term_proposal(candidate, ctx, e, mask))
    };
    let found: Vec<Option<Proposal>> = match candidate {
        Candidate::LineDrift => vec![fresh(
            EffectConfig::LineDrift(LineDrift {
                velocity_m_per_s: [0.0, 0.0],
            }),
            vec![true, true],
        )],
        Candidate::ExponentialCreep | Candidate::SecondCreep => onset_grid(candidate, ctx)
            .into_iter()
            .map(|(time_constant, start)| onset_proposal(candidate, time_constant, start, ctx))
            .collect(),
        Candidate::AsymmetricHysteresis => vec![asymmetric_hysteresis_proposal(ctx)],
        Candidate::SlowHysteresis => slow_hysteresis_proposals(ctx, t_max),
        Candidate::Vibration => {
            let (peaks, searched) = periodogram_peaks(
                ctx.observations,
                ctx.residuals,
                5,
                MIN_VIBRATION_CYCLES,
                crate::evidence::spectrum::SIGNIFICANT_FALSE_ALARM,
            );
            peaks
                .into_iter()
                .map(|f| vibration_proposal(ctx, f, searched))
                .collect()
        }
        Candidate::TipChange => tip_change_proposals(ctx, t_max),
        Candidate::HeightCoupling => vec![height_coupling_proposal(ctx)],
        Candidate::ScanCoupling => vec![fresh(
            EffectConfig::ScanCoupling(ScanCoupling {
                slow_to_fast: 0.0,
                fast_to_slow: 0.0,
            }),
            vec![true, true],
        )],
        Candidate::HigherOrderDrift => {
            let e = Box::new(CubicDrift {
                jerk_m_per_s3: [0.0, 0.0],
            });
            vec![zero_term_proposal(candidate, ctx, e, vec![true, true])]
        }
        Candidate::LocalStrain => {
            let e = Box::new(QuadraticField {
                coefficients_m: [0.0; 6],
            });
            vec![zero_term_proposal(candidate, ctx, e, vec![true; 6])]
        }
        Candidate::PiezoNonlinearity => vec![piezo_nonlinearity_proposal(ctx)],
    };
    found.into_iter().flatten().collect()
}

/// A proposal appending the term `effect` (parameters at zero), screening the parameters in
/// `mask`, with no shape searched.
fn zero_term_proposal(
    candidate: Candidate,
    ctx: &Context,
    effect: Box<dyn ModelTerm>,
    mask: Vec<bool>,
) -> Option<Proposal> {
    term_proposal(
        candidate,
        String::new(),
        ctx,
        Term::all_free(effect, candidate.name()),
        mask,
        None,
        0,
    )
}

/// A fast-axis piezo non-linearity: its quadratic part `q_x` free, and its cubic part
/// `c_x` too unless the model's fast-scan hysteresis law is a polynomial. The cubic part
/// along x is odd in position, which a symmetric fast-scan hysteresis law mirrors between
/// trace and retrace exactly as it is: a cubic or quartic law takes it whole (both free,
/// the fit wanders along the valley, e.g. to 2.5 mm for a true 33 pm), while a power or
/// exponential law cannot, and would leave it to an asymmetric law's extra freedom. Along
/// y the commanded position follows the slow-scan time, so that part is drift.
fn piezo_nonlinearity_proposal(ctx: &Context) -> Option<Proposal> {
    let candidate = Candidate::PiezoNonlinearity;
    let effect = sim_term(&EffectConfig::PiezoNonlinearity(PiezoNonlinearity {
        quadratic_m: [0.0; 2],
        cubic_m: [0.0; 2],
    }))?;
    let polynomial_law = ctx.model.terms.iter().any(|t| {
        matches!(
            t.effect.config(),
            Some(EffectConfig::FastHysteresis(FastScanHysteresis {
                law: HysteresisLaw::Quartic { .. }
            }))
        )
    });
    let free = vec![true, false, !polynomial_law, false];
    let term = Term::new(effect, free.clone(), candidate.name());
    term_proposal(candidate, String::new(), ctx, term, free, None, 0)
}

/// Trace and retrace each with their own copy of the current fast-scan hysteresis law
/// (replacing it; the retrace's parameters screened), if the model has one.
fn asymmetric_hysteresis_proposal(ctx: &Context) -> Option<Proposal> {
    let candidate = Candidate::AsymmetricHysteresis;
    let k = ctx
        .model
        .terms
        .iter()
        .position(|t| t.effect.name() == "fast-hysteresis")?;
    let Some(EffectConfig::FastHysteresis(h)) = ctx.model.terms[k].effect.config() else {
        return None;
    };
    let e = sim_term(&EffectConfig::AsymmetricHysteresis(AsymmetricHysteresis {
        trace: h.law.clone(),
        retrace: h.law.clone(),
    }))?;
    let n = h.law.parameter_count();
    let mut mask = vec![false; n];
    mask.extend(vec![true; n]);
    term_proposal(
        candidate,
        String::new(),
        ctx,
        Term::all_free(e, candidate.name()),
        mask,
        Some(k),
        0,
    )
}

/// Slow-scan hysteresis with an exponential law, one proposal per time constant of a log
/// grid from two line periods to 0.3 × `t_max` (s); the amplitude is screened.
fn slow_hysteresis_proposals(ctx: &Context, t_max: f64) -> Vec<Option<Proposal>> {
    let candidate = Candidate::SlowHysteresis;
    log_grid(2.0 * ctx.geometry.line_period(), 0.3 * t_max, 16)
        .into_iter()
        .map(|tau| {
            let e = sim_term(&EffectConfig::SlowHysteresis(SlowScanHysteresis {
                law: HysteresisLaw::Exponential {
                    amplitude: 0.0,
                    time_constant_s: tau,
                },
            }))?;
            term_proposal(
                candidate,
                format!("τ = {tau:.3} s"),
                ctx,
                Term::all_free(e, candidate.name()),
                vec![true, false],
                None,
                1,
            )
        })
        .collect()
}

/// A tip change at every line start up to `t_max` (s); the round refines the best to
/// the feature times around it.
fn tip_change_proposals(ctx: &Context, t_max: f64) -> Vec<Option<Proposal>> {
    // Every half-line start, then refined to the feature times around the best.
    let step = ctx.geometry.line_period();
    let mut out = Vec::new();
    let mut t = step;
    while t < t_max {
        out.push(tip_proposal(ctx, t));
        t += step;
    }
    out
}

/// Lateral shift proportional to the terrace height, if the terrace height varies.
fn height_coupling_proposal(ctx: &Context) -> Option<Proposal> {
    let spread = ctx
        .observations
        .iter()
        .map(|o| o.terrace_height_m)
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), z| {
            (lo.min(z), hi.max(z))
        });
    if spread.1 - spread.0 > 0.0 {
        let e = sim_term(&EffectConfig::HeightCoupling(HeightCoupling {
            lateral_per_height: [0.0, 0.0],
        }))?;
        zero_term_proposal(Candidate::HeightCoupling, ctx, e, vec![true, true])
    } else {
        None
    }
}

/// The range the base creep's `t0` is profiled over ([`crate::model::fit::fit_profiled`]): from one
/// line period (a faster creep is not sampled by the slow axis) to ten frame durations (a
/// slower one is a polynomial over the frame: the drift's velocity and acceleration, then
/// the higher-order drift candidate), seconds.
pub(crate) fn creep_t0_bounds(geometry: &ScanGeometry, observations: &[Observation]) -> (f64, f64) {
    let span = observations
        .iter()
        .map(|o| o.time_s)
        .fold(geometry.frame_duration(), f64::max);
    let lo = geometry.line_period();
    (lo, (10.0 * span).max(10.0 * lo))
}

/// The shortest time constant a fitted exponential creep may keep: a relaxation faster
/// than the slow scan takes to cross half an atom (`½·NN / v_slow`, at least four line
/// pairs) cannot be told from a jump (a tip change), since every feature is fitted over
/// about one NN distance of lines: on rendered images the features cut by a jump look like
/// such a fast relaxation. (The search grid starts lower, at two line periods, so that a
/// refit can move up from there.)
pub(crate) fn min_creep_time_constant(geometry: &ScanGeometry, nn_distance_m: f64) -> f64 {
    (0.5 * nn_distance_m / geometry.slow_speed()).max(8.0 * geometry.line_period())
}

/// Whether the effect `candidate` added as the last term of `model` is still within the
/// candidate's domain after a free refit: an exponential creep may not relax faster than
/// [`min_creep_time_constant`], and a second creep's `t0` may not be shorter than one line
/// period (the grid's floor and the base creep's: a faster creep is not sampled by the
/// slow axis, and such a `t0` makes `C·ln(1 + t/t0)` a step with a tail — on rendered
/// images the smeared jump of a tip change).
pub(crate) fn within_domain(
    candidate: Candidate,
    model: &GlobalModel,
    geometry: &ScanGeometry,
    nn_distance_m: f64,
) -> bool {
    let (parameter, minimum) = match candidate {
        Candidate::ExponentialCreep => (
            "time_constant_s",
            min_creep_time_constant(geometry, nn_distance_m),
        ),
        Candidate::SecondCreep => ("t0_s", geometry.line_period()),
        _ => return true,
    };
    model
        .terms
        .iter()
        .rev()
        .find(|t| t.label == candidate.name())
        .is_none_or(|t| {
            t.effect
                .parameter_names()
                .iter()
                .zip(t.effect.parameters())
                .filter(|(name, _)| name.ends_with(parameter))
                .all(|(_, value)| value >= 0.999 * minimum)
        })
}

/// Onsets searched per frame by the creep candidates' coarse grid.
const ONSET_GRID: usize = 24;

/// The coarse grid's step between creep onsets, seconds.
pub(crate) fn onset_step(ctx: &Context) -> f64 {
    frame_end(ctx) / ONSET_GRID as f64
}

/// The largest observation time (at least one line period), seconds.
fn frame_end(ctx: &Context) -> f64 {
    ctx.observations
        .iter()
        .map(|o| o.time_s)
        .fold(0.0, f64::max)
        .max(ctx.geometry.line_period())
}

/// The time constants of a creep candidate's coarse grid: an exponential creep's `τ` from
/// two line periods to half the frame (10 values), a second creep's `t0` from one line
/// period to a fifth of it (8 values; log-spaced).
fn time_constant_grid(candidate: Candidate, ctx: &Context) -> Vec<f64> {
    let (lp, t_max) = (ctx.geometry.line_period(), frame_end(ctx));
    match candidate {
        Candidate::ExponentialCreep => log_grid(2.0 * lp, 0.5 * t_max, 10),
        _ => log_grid(lp, 0.2 * t_max, 8),
    }
}

/// The coarse `(time constant, onset)` grid of a creep candidate (an exponential creep may
/// start with the frame, a second creep not: that is the base creep).
fn onset_grid(candidate: Candidate, ctx: &Context) -> Vec<(f64, f64)> {
    let t_max = frame_end(ctx);
    let first = usize::from(candidate == Candidate::SecondCreep);
    let mut out = Vec::new();
    for tau in time_constant_grid(candidate, ctx) {
        for k in first..ONSET_GRID {
            let start = t_max * k as f64 / ONSET_GRID as f64;
            // An exponential creep must relax within the frame to be told from a drift.
            if candidate == Candidate::ExponentialCreep && start + tau > t_max {
                continue;
            }
            out.push((tau, start));
        }
    }
    out
}

/// Finer `(time constant, onset)` points around a coarse grid point: onsets within one
/// coarse step at an eighth of it, time constants at the grid point and half a grid step
/// either side. The coarse onset step (a 24th of the frame) is comparable to the time
/// constants themselves, and a refit started more than a few time constants from the true
/// onset stays in a neighbouring minimum.
pub(crate) fn onset_refinement(
    candidate: Candidate,
    time_constant: f64,
    start: f64,
    ctx: &Context,
) -> Vec<(f64, f64)> {
    let t_max = frame_end(ctx);
    let step = t_max / ONSET_GRID as f64;
    let grid = time_constant_grid(candidate, ctx);
    let ratio = (grid[1] / grid[0]).sqrt().max(1.0);
    let mut out = Vec::new();
    for tau in [time_constant / ratio, time_constant, time_constant * ratio] {
        for k in -8..=8 {
            let s = start + step * k as f64 / 8.0;
            if k == 0 && tau == time_constant || s < 0.0 || s >= t_max {
                continue;
            }
            out.push((tau, s));
        }
    }
    out
}

/// A creep candidate with time constant `time_constant` (exponential `τ` or logarithmic
/// `t0`) from `start` (s since frame start): amplitudes screened, both shapes free in the
/// refit.
pub(crate) fn onset_proposal(
    candidate: Candidate,
    time_constant: f64,
    start: f64,
    ctx: &Context,
) -> Option<Proposal> {
    let config = match candidate {
        Candidate::ExponentialCreep => EffectConfig::ExponentialCreep(ExponentialCreep {
            amplitude_m: [0.0, 0.0],
            time_constant_s: time_constant,
            start_s: start,
        }),
        Candidate::SecondCreep => EffectConfig::Creep(LogCreep {
            coefficient_m: [0.0, 0.0],
            t0_s: time_constant,
            start_s: start,
        }),
        _ => return None,
    };
    let shape = match candidate {
        Candidate::ExponentialCreep => format!("τ = {time_constant:.3} s, start = {start:.2} s"),
        _ => format!("t0 = {time_constant:.3} s, start = {start:.2} s"),
    };
    term_proposal(
        candidate,
        shape,
        ctx,
        Term::new(sim_term(&config)?, vec![true; 4], candidate.name()),
        vec![true, true, false, false],
        None,
        2,
    )
    .map(|p| Proposal {
        onset: Some((time_constant, start)),
        ..p
    })
}

/// A tip change at `t` (s since frame start): jump free, time fixed.
pub(crate) fn tip_proposal(ctx: &Context, t: f64) -> Option<Proposal> {
    let e = sim_term(&EffectConfig::TipChange(TipChange {
        time_s: t,
        jump_m: [0.0, 0.0],
        height_offset_m: 0.0,
        contrast: 1.0,
    }))?;
    let mask = vec![false, true, true, false, false];
    term_proposal(
        Candidate::TipChange,
        format!("t = {t:.3} s"),
        ctx,
        Term::new(e, mask.clone(), Candidate::TipChange.name()),
        mask,
        None,
        1,
    )
}

/// A "vibration" with fewer periods than this in the frame is a smooth drift residue, which
/// the drift and creep terms and the other candidates describe: it is not searched for.
pub(crate) const MIN_VIBRATION_CYCLES: f64 = 4.0;

/// Vibration at `f` Hz, found among `searched` independent periodogram frequencies: the
/// screening columns are `sin`, `cos` per axis; the refit frees the frequency, amplitudes
/// and phases.
fn vibration_proposal(ctx: &Context, f: f64, searched: usize) -> Option<Proposal> {
    let n = ctx.observations.len();
    let mut columns = DMatrix::zeros(2 * n, 4);
    let w = std::f64::consts::TAU * f;
    for (i, o) in ctx.observations.iter().enumerate() {
        let (s, c) = (w * o.time_s).sin_cos();
        columns[(2 * i, 0)] = s * 1e-11 / ctx.sigma[0];
        columns[(2 * i, 1)] = c * 1e-11 / ctx.sigma[0];
        columns[(2 * i + 1, 2)] = s * 1e-11 / ctx.sigma[1];
        columns[(2 * i + 1, 3)] = c * 1e-11 / ctx.sigma[1];
    }
    let build: Builder = Box::new(move |base: &GlobalModel, coef: &[f64]| {
        let amp = |a: f64, b: f64| (1e-11 * a.hypot(b), b.atan2(a));
        let (ax, px) = amp(coef[0], coef[1]);
        let (ay, py) = amp(coef[2], coef[3]);
        let e = sim_term(&EffectConfig::Vibration(Vibration {
            frequency_hz: f,
            amplitude_m: [ax, ay],
            phase_rad: [px, py],
        }))?;
        let mut m = base.clone();
        m.terms.push(Term::all_free(e, Candidate::Vibration.name()));
        Some(m)
    });
    Some(Proposal {
        candidate: Candidate::Vibration,
        shape: format!("f = {f:.4} Hz"),
        columns,
        build,
        extra_parameters: 1,
        searched: Some(searched),
        onset: None,
    })
}
