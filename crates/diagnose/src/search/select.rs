//! Scoring and greedy selection of candidate effects.
//!
//! For the current model (fitted, weighted residual `r`, Jacobian `J`) each candidate's
//! proposals are screened by the exact linearised χ² reduction of adding their columns `B`
//! jointly with a re-adjustment of every current parameter (`B` projected off `J`). The best
//! shape of each candidate is then scored by
//!
//! * **cross-validation** ([`CvScheme`]): a persistent effect over 10 time blocks (fold `k`
//!   holds out blocks `k` and `k + 5`), a transient one over interleaved line pairs (fold
//!   `k` holds out every fifth line pair; time blocks cannot test an effect confined to one
//!   block); the model is re-fitted (one Gauss–Newton step from the full-data solution,
//!   exact for parameters that enter linearly) on the rest and predicts the held-out
//!   residuals. Score: held-out mean square with the effect ÷ without;
//! * **BIC/AIC** with the noise variance profiled out: `n·ln(χ²/n) + k·ln n` (`2k`),
//!   counting the grid-searched shape parameters in `k`, each at least at the
//!   look-elsewhere price `2 ln M` of the `M` shapes searched (a periodogram's frequencies).
//!
//! The best few by BIC are re-fitted in full (all parameters, shapes free where smooth) and
//! re-scored. An effect is accepted only if its CV ratio is below `1 − min_cv_gain`, the
//! held-out mean square drops by more than `min_cv_gain` of the floor's variance too (when
//! the residual is already below the floor, a relative gain measures the noise), and its
//! ΔBIC is below `−min_delta_bic`; the accepted best joins the model and the next round
//! starts. If none passes, the answer is "no further effect needed".

use dhct_scan::ScanGeometry;
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::model::data::Observation;
use crate::model::fit::{Fitted, fit_profiled, pinv_sym, weighted};
use crate::model::global::GlobalModel;
use crate::search::candidates::{
    Candidate, Context, Proposal, onset_proposal, onset_refinement, onset_step, proposals,
    tip_proposal, within_domain,
};
use dhct_numerics::linalg::pseudo_inverse_symmetric;

/// Score of one candidate in one greedy round.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CandidateScore {
    /// The candidate.
    pub candidate: Candidate,
    /// The chosen shape (grid point), human-readable.
    pub shape: String,
    /// Parameters added (including grid-searched shape parameters).
    pub added_parameters: usize,
    /// χ² (weighted by the noise floor) of the model with this effect.
    pub chi2: f64,
    /// χ² reduction relative to the current model.
    pub delta_chi2: f64,
    /// BIC change (negative = better).
    pub delta_bic: f64,
    /// AIC change (negative = better).
    pub delta_aic: f64,
    /// Held-out mean square with the effect ÷ without (< 1 = predicts unseen time blocks
    /// better).
    pub cv_ratio: f64,
    /// Held-out mean square without the effect minus with it, in units of the noise
    /// floor's variance.
    #[serde(default)]
    pub cv_drop: f64,
    /// Whether the scores come from a full non-linear refit (else linearised screening).
    pub refitted: bool,
    /// Whether it passes both acceptance tests.
    pub passes: bool,
}

/// Options of the selection.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct SelectionOptions {
    /// At most this many effects are added.
    pub max_effects: usize,
    /// Required relative drop of the held-out mean square.
    pub min_cv_gain: f64,
    /// Required BIC decrease.
    pub min_delta_bic: f64,
    /// Candidates re-fitted in full per round (best by linearised BIC).
    pub refit_top: usize,
    /// Levenberg–Marquardt iteration limit.
    pub max_iterations: usize,
}

impl Default for SelectionOptions {
    fn default() -> Self {
        SelectionOptions {
            max_effects: 3,
            min_cv_gain: 0.05,
            min_delta_bic: 20.0,
            refit_top: 3,
            max_iterations: 300,
        }
    }
}

/// How observations are assigned to cross-validation folds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum CvScheme {
    /// Each candidate on the data it has to predict: a persistent effect (vibration, line
    /// drift, couplings, higher-order drift, …) on [`CvScheme::TimeBlocks`], since it must
    /// carry over to parts of the frame it was not fitted on; a transient one (tip change,
    /// slow-scan hysteresis, a second or exponential creep from its onset) on
    /// [`CvScheme::InterleavedLines`], since a transient lives inside one time block, which
    /// time blocks could never test.
    #[default]
    PerCandidate,
    /// Line pairs (trace + retrace of one line) in turn: fold `k` holds out every
    /// `folds`-th line pair, so every held-out line has fitted lines on both sides.
    InterleavedLines,
    /// Contiguous time blocks: fold `k` holds out blocks `k`, `k + folds`, ….
    TimeBlocks,
}

impl CvScheme {
    /// The scheme `candidate` is tested with.
    pub fn for_candidate(self, candidate: Candidate) -> CvScheme {
        match self {
            CvScheme::PerCandidate if candidate.is_transient() => CvScheme::InterleavedLines,
            CvScheme::PerCandidate => CvScheme::TimeBlocks,
            fixed => fixed,
        }
    }
}

/// Fold assignments of every observation under both concrete schemes.
pub(crate) struct Folds {
    pub scheme: CvScheme,
    pub interleaved: Vec<usize>,
    pub blocks: Vec<usize>,
    pub count: usize,
}

impl Folds {
    pub(crate) fn new(
        observations: &[Observation],
        geometry: &ScanGeometry,
        scheme: CvScheme,
        blocks: usize,
        count: usize,
    ) -> Folds {
        Folds {
            scheme,
            interleaved: folds(
                observations,
                geometry,
                CvScheme::InterleavedLines,
                blocks,
                count,
            ),
            blocks: folds(observations, geometry, CvScheme::TimeBlocks, blocks, count),
            count,
        }
    }

    /// The folds `candidate` is tested with.
    pub(crate) fn of(&self, candidate: Candidate) -> &[usize] {
        match self.scheme.for_candidate(candidate) {
            CvScheme::InterleavedLines => &self.interleaved,
            _ => &self.blocks,
        }
    }
}

/// The fold of every observation under `scheme` (`PerCandidate` counts as time blocks).
pub(crate) fn folds(
    observations: &[Observation],
    geometry: &ScanGeometry,
    scheme: CvScheme,
    blocks: usize,
    folds: usize,
) -> Vec<usize> {
    match scheme {
        CvScheme::InterleavedLines => {
            let pair = 2.0 * geometry.line_period();
            observations
                .iter()
                .map(|o| ((o.time_s / pair).floor().max(0.0) as usize) % folds)
                .collect()
        }
        CvScheme::TimeBlocks | CvScheme::PerCandidate => {
            let (lo, hi) = observations
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), o| {
                    (a.min(o.time_s), b.max(o.time_s))
                });
            let span = (hi - lo).max(1e-12);
            observations
                .iter()
                .map(|o| {
                    let b = (((o.time_s - lo) / span * blocks as f64) as usize).min(blocks - 1);
                    b % folds
                })
                .collect()
        }
    }
}

/// Held-out mean square of the linearised refit of design `a` (rows `[x0, y0, …]`).
pub(crate) fn cv_mean_square(a: &DMatrix<f64>, r: &DVector<f64>, fold: &[usize], k: usize) -> f64 {
    let q = a.ncols();
    let mut g = vec![DMatrix::<f64>::zeros(q, q); k];
    let mut h = vec![DVector::<f64>::zeros(q); k];
    for row in 0..a.nrows() {
        let f = fold[row / 2];
        let ar = a.row(row);
        g[f] += ar.transpose() * ar;
        h[f] += ar.transpose() * r[row];
    }
    let gt: DMatrix<f64> = g.iter().fold(DMatrix::zeros(q, q), |acc, x| acc + x);
    let ht: DVector<f64> = h.iter().fold(DVector::zeros(q), |acc, x| acc + x);
    let deltas: Vec<DVector<f64>> = (0..k)
        .map(|f| -pseudo_inverse_symmetric(&(&gt - &g[f]), 1e-8) * (&ht - &h[f]))
        .collect();
    let mut sum = 0.0;
    for row in 0..a.nrows() {
        let f = fold[row / 2];
        let e = r[row] + (a.row(row) * &deltas[f])[0];
        sum += e * e;
    }
    sum / a.nrows() as f64
}

fn hcat(a: &DMatrix<f64>, b: &DMatrix<f64>) -> DMatrix<f64> {
    let mut out = DMatrix::zeros(a.nrows(), a.ncols() + b.ncols());
    out.columns_mut(0, a.ncols()).copy_from(a);
    out.columns_mut(a.ncols(), b.ncols()).copy_from(b);
    out
}

/// Linearised χ² reduction and coefficients of adding `b` to the fit with Jacobian basis `q`.
fn screen(q: &DMatrix<f64>, r: &DVector<f64>, b: &DMatrix<f64>) -> (f64, Vec<f64>) {
    let bp = b - q * (q.transpose() * b);
    let rp = r - q * (q.transpose() * r);
    let g = bp.transpose() * &bp;
    let h = bp.transpose() * &rp;
    let beta = -pinv_sym(&g) * &h;
    let gain = -(h.transpose() * &beta)[0];
    (gain.max(0.0), beta.iter().copied().collect())
}

/// The state of the model at the start of a round.
pub(crate) struct Current<'a> {
    pub fitted: &'a Fitted,
    pub geometry: &'a ScanGeometry,
    pub observations: &'a [Observation],
    pub sigma: [f64; 2],
    pub folds: &'a Folds,
    /// The lattice's nearest-neighbour distance, metres.
    pub nn_distance_m: f64,
    /// Range of the base creep's `t0`, seconds (profiled in every refit).
    pub t0_bounds: (f64, f64),
}

/// A scored candidate with its refitted model, if refitted.
pub(crate) struct Scored {
    pub score: CandidateScore,
    pub fitted: Option<Fitted>,
}

/// The parameter count of a proposal for the information criteria.
#[derive(Debug, Clone, Copy)]
struct Complexity {
    /// Parameters entering through the screening columns.
    columns: usize,
    /// Shape parameters chosen by a search (grid or periodogram).
    shape: usize,
    /// Independent shapes that search compared.
    searched: usize,
}

impl Complexity {
    fn parameters(self) -> usize {
        self.columns + self.shape
    }

    /// `(ΔBIC, ΔAIC)` penalties. A searched shape costs what a fitted parameter costs, or
    /// `2 ln M` for a search over `M` independent shapes if that is more (look-elsewhere:
    /// under noise alone the best of `M` shapes gains about `2 ln M` in χ²). Only the
    /// periodogram's thousands of frequencies exceed the BIC price of its one parameter.
    fn penalties(self, n: f64) -> (f64, f64) {
        let search = 2.0 * (self.searched.max(1) as f64).ln();
        let shape_bic = if self.shape == 0 {
            0.0
        } else {
            (self.shape as f64 * n.ln()).max(search)
        };
        let shape_aic = if self.shape == 0 {
            0.0
        } else {
            (2.0 * self.shape as f64).max(search)
        };
        (
            self.columns as f64 * n.ln() + shape_bic,
            2.0 * self.columns as f64 + shape_aic,
        )
    }
}

fn criteria(n: f64, chi2_0: f64, chi2_1: f64, complexity: Complexity) -> (f64, f64) {
    let d = n * (chi2_1.max(1e-300) / chi2_0.max(1e-300)).ln();
    let (bic, aic) = complexity.penalties(n);
    (d + bic, d + aic)
}

/// The start model of a candidate's full refit: the new term at a fraction `α` of its
/// screened coefficients `beta`, on the current model either as it is or moved by the same
/// fraction of the linearised re-adjustment the screening assumed (`δu = −(JᵀJ)⁺Jᵀ·Bβ`);
/// of `α ∈ {0, …, 1}` on both paths, the start with the lowest χ². A term correlated with
/// the current ones (an exponential creep with drift and creep) makes both full steps land
/// far above the screened χ² (the re-adjustment moves the base's non-linear parameters far
/// beyond where it is linear), and a refit from there can stall above the base model
/// itself; `α = 0` (the new term at zero, the base's χ²) bounds the start.
fn refit_start(
    current: &Current,
    proposal: &Proposal,
    beta: &[f64],
    j: &DMatrix<f64>,
    jtj_pinv: &DMatrix<f64>,
) -> Option<GlobalModel> {
    let base = &current.fitted.model;
    let added = &proposal.columns * DVector::from_column_slice(beta);
    let shift = -(jtj_pinv * (j.transpose() * &added));
    let u0 = base.free_vector();
    let chi2 = |m: &GlobalModel| {
        weighted(
            &m.residuals(current.geometry, current.observations),
            current.sigma,
        )
        .norm_squared()
    };
    let mut best: Option<(f64, GlobalModel)> = None;
    for alpha in [0.0, 0.01, 0.03, 0.1, 0.3, 1.0] {
        let coef: Vec<f64> = beta.iter().map(|b| alpha * b).collect();
        let moved: Vec<f64> = u0
            .iter()
            .zip(shift.iter())
            .map(|(u, d)| u + alpha * d)
            .collect();
        let starts = [
            (proposal.build)(base, &coef),
            base.with_free_vector(&moved)
                .and_then(|b| (proposal.build)(&b, &coef)),
        ];
        for m in starts.into_iter().flatten() {
            let c = chi2(&m);
            if c.is_finite() && best.as_ref().is_none_or(|(b, _)| c < *b) {
                best = Some((c, m));
            }
        }
    }
    best.map(|(_, m)| m)
}

/// What every candidate of a round is measured against: the current model's weighted
/// residuals `r` (`[x0, y0, …]`, in noise σ), its Jacobian `J` and an orthonormal basis `Q`
/// of it, `χ²₀` and the held-out mean squares under both fold schemes.
struct Baseline<'a> {
    current: &'a Current<'a>,
    r: DVector<f64>,
    j: &'a DMatrix<f64>,
    q: DMatrix<f64>,
    /// Number of residuals.
    n: f64,
    chi2_0: f64,
    cv0_interleaved: f64,
    cv0_blocks: f64,
}

impl<'a> Baseline<'a> {
    fn new(current: &'a Current<'a>) -> Baseline<'a> {
        let fitted = current.fitted;
        let r = weighted(&fitted.residuals, current.sigma);
        let j = &fitted.jacobian;
        let q = j.clone().qr().q();
        let n = r.len() as f64;
        let chi2_0 = r.norm_squared();
        let cv0_interleaved =
            cv_mean_square(j, &r, &current.folds.interleaved, current.folds.count);
        let cv0_blocks = cv_mean_square(j, &r, &current.folds.blocks, current.folds.count);
        Baseline {
            current,
            r,
            j,
            q,
            n,
            chi2_0,
            cv0_interleaved,
            cv0_blocks,
        }
    }

    /// The current model's held-out mean square on the folds `c` is tested with.
    fn cv0(&self, c: Candidate) -> f64 {
        let folds = self.current.folds;
        if std::ptr::eq(folds.of(c), folds.interleaved.as_slice()) {
            self.cv0_interleaved
        } else {
            self.cv0_blocks
        }
    }
}

/// A candidate's best proposal by linearised χ² reduction: the proposal, its gain, its
/// screened coefficients and the number of shapes searched.
type Screened = (Proposal, f64, Vec<f64>, usize);

/// A proposal and its screened coefficients: where a full refit starts.
type Start = (Proposal, Vec<f64>);

/// A candidate's score, with what its full refit starts from: the best proposal, its
/// screened coefficients and its complexity, and for a creep the best start in another
/// basin of its onset ([`other_onset`]), refitted as well.
struct Entry {
    scored: Scored,
    proposal: Option<Proposal>,
    beta: Vec<f64>,
    complexity: Complexity,
    alternative: Option<Start>,
}

/// Scores every candidate in `candidates` on top of `current`; sorted best first.
pub(crate) fn round(
    current: &Current,
    candidates: &[Candidate],
    options: &SelectionOptions,
) -> Vec<Scored> {
    let base = Baseline::new(current);
    let r_slice: Vec<f64> = base.r.iter().copied().collect();
    let ctx = Context {
        model: &current.fitted.model,
        geometry: current.geometry,
        observations: current.observations,
        sigma: current.sigma,
        residuals: &r_slice,
    };
    let screened: Vec<(Screened, Option<Start>)> = candidates
        .par_iter()
        .filter_map(|&c| screen_candidate(c, &ctx, &base))
        .collect();
    let mut scored: Vec<Entry> = screened
        .into_iter()
        .map(|(s, alternative)| Entry {
            alternative,
            ..screened_entry(s, &base)
        })
        .collect();
    scored.sort_by(|a, b| {
        a.scored
            .score
            .delta_bic
            .total_cmp(&b.scored.score.delta_bic)
    });
    // Full refits of the best few.
    let top = options.refit_top.min(scored.len());
    let jtj_pinv = pinv_sym(&(base.j.transpose() * base.j));
    let refits: Vec<Option<(Fitted, String)>> = scored[..top]
        .par_iter()
        .map(|entry| refit_candidate(&base, entry, &jtj_pinv, options))
        .collect();
    for (entry, refit) in scored.iter_mut().zip(refits) {
        let Some((f, shape)) = refit else { continue };
        entry.scored.score.shape = shape;
        rescore(&mut entry.scored, f, entry.complexity, &base);
    }
    rank(scored, options)
}

/// Screens every proposal of candidate `c` and keeps the one that gains the most; a tip
/// change's best is then refined to the feature times near it, a creep onset around the
/// best coarse grid point, and a creep also gets its best start in another basin of the
/// onset ([`other_onset`]). `None` when the candidate has no proposal.
fn screen_candidate(
    c: Candidate,
    ctx: &Context,
    base: &Baseline,
) -> Option<(Screened, Option<Start>)> {
    let current = base.current;
    let mut best: Option<(Proposal, f64, Vec<f64>)> = None;
    let all = proposals(c, ctx);
    let mut searched = all.len();
    let mut onsets: Vec<(f64, (f64, f64))> = Vec::new();
    for p in all {
        let (gain, beta) = screen(&base.q, &base.r, &p.columns);
        if let Some(onset) = p.onset {
            onsets.push((gain, onset));
        }
        keep_if_best(&mut best, p, gain, beta);
    }
    // A tip change is refined to the feature times near the best line start.
    if c == Candidate::TipChange
        && let Some((p, _, _)) = &best
        && let Some(t) = p
            .shape
            .strip_prefix("t = ")
            .and_then(|s| s.trim_end_matches(" s").parse::<f64>().ok())
    {
        let times = times_near(current.observations, t, current.geometry.line_period());
        searched += times.len();
        for tt in times {
            if let Some(p) = tip_proposal(ctx, tt + 1e-9) {
                let (gain, beta) = screen(&base.q, &base.r, &p.columns);
                keep_if_best(&mut best, p, gain, beta);
            }
        }
    }
    // A creep onset is refined around the best coarse grid point.
    let mut alternative = None;
    if let Some((p, _, _)) = &best
        && let Some(first) = p.onset
    {
        searched += refine_onset(c, first, ctx, base, &mut best);
        if let Some(other) = other_onset(first, &onsets, ctx) {
            let mut second = None;
            searched += 1 + refine_onset(c, other, ctx, base, &mut second);
            if let Some(p) = onset_proposal(c, other.0, other.1, ctx) {
                let (gain, beta) = screen(&base.q, &base.r, &p.columns);
                keep_if_best(&mut second, p, gain, beta);
            }
            alternative = second.map(|(p, _, beta)| (p, beta));
        }
    }
    best.map(|(p, gain, beta)| ((p, gain, beta, searched), alternative))
}

/// Keeps `p` (screened `gain`, coefficients `beta`) in `best` if it gains the most so far.
fn keep_if_best(
    best: &mut Option<(Proposal, f64, Vec<f64>)>,
    p: Proposal,
    gain: f64,
    beta: Vec<f64>,
) {
    if best.as_ref().is_none_or(|b| gain > b.1) {
        *best = Some((p, gain, beta));
    }
}

/// Screens the finer onsets around `onset` (`(time constant, start)`, seconds) of creep
/// candidate `c` into `best`; returns how many were searched.
fn refine_onset(
    c: Candidate,
    onset: (f64, f64),
    ctx: &Context,
    base: &Baseline,
    best: &mut Option<(Proposal, f64, Vec<f64>)>,
) -> usize {
    let finer = onset_refinement(c, onset.0, onset.1, ctx);
    let searched = finer.len();
    for (tau, start) in finer {
        if let Some(p) = onset_proposal(c, tau, start, ctx) {
            let (gain, beta) = screen(&base.q, &base.r, &p.columns);
            keep_if_best(best, p, gain, beta);
        }
    }
    searched
}

/// Coarse onset steps by which a second start must differ from the first.
const OTHER_ONSET_STEPS: f64 = 2.0;

/// The coarse grid point (of `onsets`: screened gain, `(time constant, start)`) that gains
/// the most with a start more than [`OTHER_ONSET_STEPS`] coarse steps from `first`'s. The
/// linearised screening is taken about a base model that has already absorbed part of
/// the creep, so its best start can lie in the wrong basin (measured: an exponential
/// creep's screening best 25 s before its true onset, whose refit stayed there with half
/// the χ² reduction a refit from near the true onset reached); refitting from the best
/// start elsewhere too leaves the choice to the full fit.
fn other_onset(
    first: (f64, f64),
    onsets: &[(f64, (f64, f64))],
    ctx: &Context,
) -> Option<(f64, f64)> {
    let step = onset_step(ctx);
    onsets
        .iter()
        .filter(|(_, (_, start))| (start - first.1).abs() > OTHER_ONSET_STEPS * step)
        .max_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, onset)| *onset)
}

/// The distinct feature times (s) within `line_period` of `t`, in increasing order.
fn times_near(observations: &[Observation], t: f64, line_period: f64) -> Vec<f64> {
    let mut times: Vec<f64> = observations
        .iter()
        .map(|o| o.time_s)
        .filter(|x| (x - t).abs() < line_period)
        .collect();
    times.sort_by(f64::total_cmp);
    times.dedup();
    times
}

/// The linearised score of a screened proposal: χ², ΔBIC/ΔAIC with its complexity, and
/// the CV ratio of the current Jacobian extended by the proposal's columns.
fn screened_entry((p, gain, beta, searched): Screened, base: &Baseline) -> Entry {
    let current = base.current;
    let complexity = Complexity {
        columns: p.columns.ncols(),
        shape: p.extra_parameters,
        searched: p.searched.unwrap_or(searched),
    };
    let k = complexity.parameters();
    let chi2 = base.chi2_0 - gain;
    let (delta_bic, delta_aic) = criteria(base.n, base.chi2_0, chi2, complexity);
    let cv = cv_mean_square(
        &hcat(base.j, &p.columns),
        &base.r,
        current.folds.of(p.candidate),
        current.folds.count,
    );
    let score = CandidateScore {
        candidate: p.candidate,
        shape: p.shape.clone(),
        added_parameters: k,
        chi2,
        delta_chi2: gain,
        delta_bic,
        delta_aic,
        cv_ratio: cv / base.cv0(p.candidate),
        cv_drop: base.cv0(p.candidate) - cv,
        refitted: false,
        passes: false,
    };
    Entry {
        scored: Scored {
            score,
            fitted: None,
        },
        proposal: Some(p),
        beta,
        complexity,
        alternative: None,
    }
}

/// The full refit of an entry's proposal, and of its alternative start if it has one:
/// the better of the two, with the shape of the proposal it started from. `None` when
/// both fail or leave the candidate's domain.
fn refit_candidate(
    base: &Baseline,
    entry: &Entry,
    jtj_pinv: &DMatrix<f64>,
    options: &SelectionOptions,
) -> Option<(Fitted, String)> {
    let starts = entry
        .proposal
        .as_ref()
        .map(|p| (p, entry.beta.as_slice()))
        .into_iter()
        .chain(
            entry
                .alternative
                .as_ref()
                .map(|(p, beta)| (p, beta.as_slice())),
        );
    let chi2 = |f: &Fitted| weighted(&f.residuals, base.current.sigma).norm_squared();
    starts
        .filter_map(|(p, beta)| {
            refit_from(base, p, beta, jtj_pinv, options).map(|f| (f, p.shape.clone()))
        })
        .min_by(|a, b| chi2(&a.0).total_cmp(&chi2(&b.0)))
}

/// The full refit of proposal `p` (screened coefficients `beta`) from [`refit_start`]
/// (base `t0` profiled); `None` when it fails or leaves the candidate's domain (it then
/// describes another effect).
fn refit_from(
    base: &Baseline,
    p: &Proposal,
    beta: &[f64],
    jtj_pinv: &DMatrix<f64>,
    options: &SelectionOptions,
) -> Option<Fitted> {
    let current = base.current;
    let model = refit_start(current, p, beta, base.j, jtj_pinv)?;
    let r = fit_profiled(
        model,
        current.geometry,
        current.observations,
        current.sigma,
        options.max_iterations,
        current.t0_bounds,
    );
    if let Err(e) = &r
        && std::env::var_os("DHCT_DEBUG").is_some()
    {
        eprintln!("refit failed: {e}");
    }
    // A refit that left the candidate's domain describes another effect.
    r.ok().filter(|f| {
        within_domain(
            p.candidate,
            &f.model,
            current.geometry,
            current.nn_distance_m,
        )
    })
}

/// Replaces the screened scores of `s` by those of its full refit `f`.
fn rescore(s: &mut Scored, f: Fitted, complexity: Complexity, base: &Baseline) {
    let current = base.current;
    let rf = weighted(&f.residuals, current.sigma);
    let chi2 = rf.norm_squared();
    if std::env::var_os("DHCT_DEBUG").is_some() {
        eprintln!(
            "{}: refit χ² {chi2} vs screened {}",
            s.score.candidate, s.score.chi2
        );
    }
    let (delta_bic, delta_aic) = criteria(base.n, base.chi2_0, chi2, complexity);
    let cv = cv_mean_square(
        &f.jacobian,
        &rf,
        current.folds.of(s.score.candidate),
        current.folds.count,
    );
    s.score.chi2 = chi2;
    s.score.delta_chi2 = base.chi2_0 - chi2;
    s.score.delta_bic = delta_bic;
    s.score.delta_aic = delta_aic;
    s.score.cv_ratio = cv / base.cv0(s.score.candidate);
    s.score.cv_drop = base.cv0(s.score.candidate) - cv;
    s.score.refitted = true;
    s.fitted = Some(f);
}

/// Marks the entries that pass both acceptance tests and ranks them: passing first, then
/// by ΔBIC.
fn rank(scored: Vec<Entry>, options: &SelectionOptions) -> Vec<Scored> {
    let mut out: Vec<Scored> = scored
        .into_iter()
        .map(|entry| {
            let mut s = entry.scored;
            // The held-out error must drop by `min_cv_gain` of what remains and of the
            // floor's variance: below the floor a relative gain measures noise.
            s.score.passes = s.score.cv_ratio < 1.0 - options.min_cv_gain
                && s.score.cv_drop > options.min_cv_gain
                && s.score.delta_bic < -options.min_delta_bic;
            s
        })
        .collect();
    // Rank: passing first, then by BIC.
    out.sort_by(|a, b| {
        b.score
            .passes
            .cmp(&a.score.passes)
            .then(a.score.delta_bic.total_cmp(&b.score.delta_bic))
    });
    out
}
