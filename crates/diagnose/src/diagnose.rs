//! The whole diagnosis: base stage, position-level base fit, noise floor, location of the
//! gap, greedy selection of effects, shrink.

use dhct_distortion::{DhctOptions, DistortionModel, PassInput, RoutePolicy};
use dhct_lattice::{Lattice, LatticeFitOptions};
use dhct_scan::{ScanGeometry, ScanPass};
use dhct_simulate::EffectConfig;
use dhct_simulate::effects::{FastScanHysteresis, LogCreep, ThermalDrift};
use serde::{Deserialize, Serialize};

use crate::evidence::heights::HeightView;
use crate::evidence::location::locate;
use crate::evidence::noise::{NoiseFloor, estimate, robust_sigma};
use crate::model::base::{
    BaseChoice, ChosenBase, DECISIVE_BIC, WholeModelScore, chi2_and_bic, choose_base,
};
use crate::model::data::{BaseSource, MIN_FEATURES, Observation, Prepared, prepare};
use crate::model::fit::{BASE_CREEP, Fitted, fit, fit_profiled};
use crate::model::global::{GlobalModel, LatticeParams, Term, sim_term};
use crate::model::terms::{PASS_OFFSET, PassOffset};
use crate::model::timing_gain::whitened;
use crate::report::diagnosis::{DiagnosisReport, GreedyRound, ModelSummary};
use crate::report::gap::{AddedEffect, FeatureResidual, GapSummary, NEAR_TIE_FRACTION, Shrink};
use crate::report::verdict::{VerdictKind, decide};
use crate::search::candidates::{Candidate, creep_t0_bounds};
use crate::search::select::{Current, CvScheme, Folds, Scored, SelectionOptions, round};
use crate::{DiagnoseError, PassOffsetReading};

/// Options of [`diagnose`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct DiagnoseOptions {
    /// Options of the base DHCT fit (neighbours, hysteresis law …).
    pub dhct: DhctOptions,
    /// Candidate effects to try.
    pub candidates: Vec<Candidate>,
    /// Acceptance thresholds and limits of the greedy selection.
    pub selection: SelectionOptions,
    /// How features are assigned to cross-validation folds.
    pub cv_scheme: CvScheme,
    /// Time blocks for [`CvScheme::TimeBlocks`] (folds hold out blocks `k`, `k + folds`, …).
    pub cv_blocks: usize,
    /// Cross-validation folds.
    pub cv_folds: usize,
    /// Features with a base residual above this many noise σ (both axes combined) are
    /// dropped as outliers (mis-indexed features, defects).
    pub outlier_sigma: f64,
    /// Features farther than this fraction of the NN distance from their lattice site
    /// (after the DHCT correction) are not used.
    pub max_deviation_fraction: f64,
    /// Fit the lattice scales too (degenerate with the slow drift and the hysteresis scale
    /// when the lattice constant is a known standard; off by default).
    pub fit_lattice_scale: bool,
    /// Compute the binned profiles, spectrum and change points.
    pub locate: bool,
    /// Lower the floor to the trace/retrace spread where the fits' uncertainty exceeds it
    /// 1.5 times ([`NoiseFloor`]); off only where that spread is not noise (positions
    /// simulated without noise).
    pub lower_floor_to_trace_retrace: bool,
}

impl Default for DiagnoseOptions {
    fn default() -> Self {
        DiagnoseOptions {
            // The base model is the paper's local route: a global registration can absorb
            // part of the very events the diagnosis looks for.
            dhct: DhctOptions {
                route: RoutePolicy::Local,
                ..DhctOptions::default()
            },
            candidates: Candidate::ALL.to_vec(),
            selection: SelectionOptions::default(),
            cv_scheme: CvScheme::PerCandidate,
            cv_blocks: 10,
            cv_folds: 5,
            outlier_sigma: 6.0,
            max_deviation_fraction: 0.3,
            fit_lattice_scale: false,
            locate: true,
            lower_floor_to_trace_retrace: true,
        }
    }
}

impl DiagnoseOptions {
    fn validate(&self) -> Result<(), DiagnoseError> {
        let bad = |name, reason: &str| {
            Err(DiagnoseError::BadOption {
                name,
                reason: reason.to_string(),
            })
        };
        if self.cv_folds < 2 || self.cv_blocks < self.cv_folds {
            return bad("cv_folds/cv_blocks", "need folds ≥ 2 and blocks ≥ folds");
        }
        if self.outlier_sigma.is_nan() || self.outlier_sigma <= 1.0 {
            return bad("outlier_sigma", "must be > 1");
        }
        if !(self.max_deviation_fraction > 0.0 && self.max_deviation_fraction <= 0.5) {
            return bad("max_deviation_fraction", "must be in (0, 0.5]");
        }
        let s = &self.selection;
        if !(s.min_cv_gain.is_finite() && s.min_delta_bic.is_finite()) {
            return bad("selection", "thresholds must be finite");
        }
        Ok(())
    }
}

fn summary(f: &Fitted, sigma: [f64; 2]) -> ModelSummary {
    let l = &f.model.lattice;
    ModelSummary {
        terms: f
            .model
            .terms
            .iter()
            .map(|t| t.effect.name().to_string())
            .collect(),
        parameters: f.parameters(0),
        lattice_origin_m: l.origin_m,
        lattice_angle_rad: l.angle_rad,
        lattice_scale: l.scale,
        gap: GapSummary::of(&f.residuals, sigma, f.model.free_count()),
    }
}

/// The position-level base fit and what it decided.
struct BaseFit {
    /// The base model (hysteresis law chosen by BIC) fitted to every indexed feature.
    first: Fitted,
    /// The hysteresis law and creep form chosen, with every alternative's BIC.
    base_choice: BaseChoice,
    /// Per indexed feature, whether it was kept (not an outlier of `first`).
    keep: Vec<bool>,
    /// The features kept.
    observations: Vec<Observation>,
    /// The base model fitted in full to the features kept at the final noise floor.
    base: Fitted,
    /// The same with DHCT's log creep, when the data chose another creep form.
    log_base: Option<Fitted>,
    /// The base model with each other hysteresis law worth trying with effects
    /// ([`reconsidered`]; with DHCT's log creep), fitted in full to the same features at
    /// the same floor, by law name.
    law_bases: Vec<(&'static str, Fitted)>,
    /// The final noise floor.
    noise: NoiseFloor,
    /// Range of the base creep's `t0`, seconds.
    t0_bounds: (f64, f64),
}

/// What the greedy selection found (besides the final model).
#[derive(Clone)]
struct Greedy {
    rounds: Vec<GreedyRound>,
    added: Vec<AddedEffect>,
    /// The first round's best refitted candidate, and the gap/noise with it.
    top: Option<Candidate>,
    top_gap: Option<f64>,
}

impl Greedy {
    /// The selection as it stood after its first round.
    fn first_round(&self) -> Greedy {
        let mut first = self.clone();
        first.rounds.truncate(1);
        let accepted = first.rounds.iter().filter(|r| r.accepted.is_some()).count();
        first.added.truncate(accepted);
        first
    }
}

/// Diagnoses the sim-to-real gap of one scan.
///
/// `inputs` are the features of each image (each set of one pass, controller frame, with
/// acquisition times, e.g. from [`dhct_features::find_features_in_pair`]) with an optional
/// mask (`rows × columns`, true = use; features whose centre pixel is false are ignored);
/// `geometry` is their scan; `lattice` the known surface lattice (the internal standard).
pub fn diagnose(
    inputs: &[PassInput],
    geometry: &ScanGeometry,
    lattice: &dyn Lattice,
    options: &DiagnoseOptions,
) -> Result<DiagnosisReport, DiagnoseError> {
    diagnose_from(
        inputs,
        geometry,
        lattice,
        &BaseSource::Fit(&options.dhct),
        options,
    )
}

/// [`diagnose`] of a correction already made: `model` is the correction the features were
/// corrected with (e.g. the pipeline's drift model, or the affine map it chose instead) and
/// `lattice_fit` the options its lattice was fitted with. Nothing is refitted before the
/// position-level base fit starts from `model`; `options.dhct` is not used.
pub fn diagnose_with_model(
    inputs: &[PassInput],
    geometry: &ScanGeometry,
    lattice: &dyn Lattice,
    model: &DistortionModel,
    lattice_fit: &LatticeFitOptions,
    options: &DiagnoseOptions,
) -> Result<DiagnosisReport, DiagnoseError> {
    diagnose_from(
        inputs,
        geometry,
        lattice,
        &BaseSource::Given { model, lattice_fit },
        options,
    )
}

/// The diagnosis with the base correction from `source`.
fn diagnose_from(
    inputs: &[PassInput],
    geometry: &ScanGeometry,
    lattice: &dyn Lattice,
    source: &BaseSource,
    options: &DiagnoseOptions,
) -> Result<DiagnosisReport, DiagnoseError> {
    options.validate()?;
    let prepared = prepare(
        inputs,
        geometry,
        lattice,
        source,
        options.max_deviation_fraction,
    )?;
    let mut fitted = fit_base(&prepared, geometry, options)?;
    let (observations, sigma) = (&fitted.observations, fitted.noise.sigma_m);
    let folds = Folds::new(
        observations,
        geometry,
        options.cv_scheme,
        options.cv_blocks,
        options.cv_folds,
    );
    let context = |base| Current {
        fitted: base,
        geometry,
        observations,
        sigma,
        folds: &folds,
        nn_distance_m: lattice.nearest_neighbour_distance(),
        t0_bounds: fitted.t0_bounds,
    };
    let (mut current, mut greedy) = select_effects(&context(&fitted.base), options)?;
    let mut base = &fitted.base;
    if let Some(log_base) = &fitted.log_base {
        let (log_current, log_greedy) = select_effects(&context(log_base), options)?;
        let delta =
            whole_model_bic(base, &greedy, sigma) - whole_model_bic(log_base, &log_greedy, sigma);
        fitted.base_choice.creep_form_whole_model_delta_bic = Some(delta);
        if delta > -DECISIVE_BIC {
            fitted.base_choice.keep_log_creep();
            (base, current, greedy) = (log_base, log_current, log_greedy);
        }
    }
    let chosen = Selection {
        base,
        current,
        greedy,
    };
    let (chosen, other_law, scores) = reconsider_laws(
        chosen,
        &fitted.base_choice.hysteresis_law,
        &fitted.law_bases,
        &context,
        options,
    )?;
    if let Some(law) = other_law {
        fitted.base_choice.choose_law(law);
    }
    if scores.len() > 1 {
        fitted.base_choice.hysteresis_whole_model = scores;
    }
    let Selection {
        base,
        current,
        greedy,
    } = chosen;
    let base_summary = summary(base, sigma);
    let location = options
        .locate
        .then(|| locate(observations, &base.residuals, sigma, geometry));
    let final_summary = summary(&current, sigma);
    let final_location = options
        .locate
        .then(|| locate(observations, &current.residuals, sigma, geometry));
    let mut verdict = decide(
        base_summary.gap.gap_to_noise,
        final_summary.gap.gap_to_noise,
        greedy.added.iter().map(|a| a.candidate).collect(),
        final_location.as_ref(),
        observations.len(),
        fitted.noise.source,
    );
    if verdict.kind != VerdictKind::NoGap {
        verdict.note_near_ties(&greedy.added);
    }
    let (added, below_floor) = if verdict.kind == VerdictKind::NoGap {
        (Vec::new(), greedy.added)
    } else {
        (greedy.added, Vec::new())
    };
    let pass_offset = PassOffsetReading::of(&base_summary.parameters, sigma, geometry);
    if let Some(reading) = &pass_offset {
        reading.apply_to(&mut verdict);
    }
    let residuals = feature_residuals(&prepared, &fitted, base, &current);
    let all = &prepared.observations;
    Ok(DiagnosisReport {
        verdict: verdict.kind,
        verdict_details: verdict,
        base_choice: fitted.base_choice,
        features_in: prepared.input_features,
        features_used: observations.len(),
        unindexed: prepared.unindexed,
        poor_fits: prepared.poor_fits,
        outliers: all.len() - observations.len(),
        dhct: GapSummary::of(&prepared.dhct_gap, sigma, 0),
        base: base_summary.clone(),
        pass_offset,
        location,
        rounds: greedy.rounds,
        shrink: Shrink {
            before: base_summary.gap.gap_to_noise,
            top: greedy.top,
            after_top: greedy.top_gap,
            after_greedy: final_summary.gap.gap_to_noise,
        },
        added,
        below_floor,
        final_model: final_summary,
        final_location,
        sub_feature: None,
        heights: HeightView::of(&prepared.observations),
        image_residual: Vec::new(),
        noise: fitted.noise,
        residuals,
    })
}

/// The start model: the DHCT fit's drift, creep (its `t0` profiled, not fitted) and
/// fast-scan hysteresis (if any) as terms, and the lattice fit's origin and angle (and
/// scales, if they are fitted).
fn start_model(prepared: &Prepared, fit_lattice_scale: bool) -> GlobalModel {
    let d = &prepared.dhct_model;
    let mut terms = Vec::new();
    let drift = EffectConfig::ThermalDrift(ThermalDrift {
        velocity_m_per_s: d.drift.velocity_m_per_s,
        acceleration_m_per_s2: d.drift.acceleration_m_per_s2,
    });
    let creep = EffectConfig::Creep(LogCreep {
        coefficient_m: d.drift.creep_m,
        t0_s: d.drift.t0_s,
        start_s: 0.0,
    });
    if let Some(e) = sim_term(&drift) {
        terms.push(Term::all_free(e, "thermal-drift"));
    }
    if let Some(e) = sim_term(&creep) {
        // t0 is profiled ([`fit_profiled`]), not fitted.
        terms.push(Term::new(e, vec![true, true, false, false], BASE_CREEP));
    }
    if d.hysteresis != dhct_scan::HysteresisLaw::none()
        && let Some(e) = sim_term(&EffectConfig::FastHysteresis(FastScanHysteresis {
            law: d.hysteresis.clone(),
        }))
    {
        terms.push(Term::all_free(e, "fast-hysteresis"));
    }
    let has = |pass| prepared.observations.iter().any(|o| o.pass == pass);
    if has(ScanPass::Trace) && has(ScanPass::Retrace) {
        let offset = Box::new(PassOffset { across_m: 0.0 });
        terms.push(Term::all_free(offset, PASS_OFFSET));
    }
    let lf = &prepared.lattice_fit;
    GlobalModel {
        terms,
        lattice: LatticeParams {
            origin_m: lf.origin_m,
            angle_rad: lf.angle_rad,
            scale: if fit_lattice_scale {
                lf.scale
            } else {
                [1.0, 1.0]
            },
            fit_scale: fit_lattice_scale,
        },
    }
}

/// A base model and the greedy selection run from it.
struct Selection<'a> {
    base: &'a Fitted,
    current: Fitted,
    greedy: Greedy,
}

/// The selection `chosen` (from the base with the law `chosen_law`) against the same from
/// each base of `law_bases` (the laws [`reconsidered`]), as whole models: the better one
/// (the chosen stays unless another is lower by more than [`DECISIVE_BIC`]), the other
/// law's name if that one won, and every whole model's score. A law is tried only where
/// it falls short of the chosen base by less than that base's own excess over the floor
/// (what effects are there to explain: beyond, its effects would have to explain more than
/// the chosen law leaves), and followed past its first effect only where that puts it
/// ahead of the chosen law's first effect (later rounds add less than the first).
fn reconsider_laws<'a>(
    chosen: Selection<'a>,
    chosen_law: &str,
    law_bases: &'a [(&'static str, Fitted)],
    context: &dyn Fn(&'a Fitted) -> Current<'a>,
    options: &DiagnoseOptions,
) -> Result<(Selection<'a>, Option<&'static str>, Vec<WholeModelScore>), DiagnoseError> {
    let sigma = context(chosen.base).sigma;
    let n = 2.0 * context(chosen.base).observations.len() as f64;
    let chi2 = |f: &Fitted| chi2_and_bic(f, sigma).0;
    let excess = chi2(chosen.base) - n;
    let worth_trying = |f: &Fitted| excess > 0.0 && chi2(f) - chi2(chosen.base) < excess;
    let whole = |s: &Selection| whole_model_bic(s.base, &s.greedy, sigma);
    let first_round = whole_model_bic(chosen.base, &chosen.greedy.first_round(), sigma);
    let mut others: Vec<(&'static str, Selection<'a>)> = Vec::new();
    for (law, law_base) in law_bases.iter().filter(|(_, f)| worth_trying(f)) {
        let law_context = context(law_base);
        let start = Progress::start(&law_context, options);
        let first = advance(&law_context, options, start, 1)?;
        if whole_model_bic(law_base, &first.greedy, sigma) >= first_round {
            continue;
        }
        let done = advance(&law_context, options, first, usize::MAX)?;
        others.push((
            law,
            Selection {
                base: law_base,
                current: done.current,
                greedy: done.greedy,
            },
        ));
    }
    let chosen_bic = whole(&chosen);
    let winner = (0..others.len())
        .filter(|&k| whole(&others[k].1) < chosen_bic - DECISIVE_BIC)
        .min_by(|&a, &b| whole(&others[a].1).total_cmp(&whole(&others[b].1)));
    let best_bic = winner.map_or(chosen_bic, |k| whole(&others[k].1));
    let score = |law: &str, s: &Selection| WholeModelScore {
        law: law.to_string(),
        delta_bic: whole(s) - best_bic,
        effects: s
            .greedy
            .added
            .iter()
            .map(|a| a.candidate.name().into())
            .collect(),
    };
    let mut scores = vec![score(chosen_law, &chosen)];
    scores.extend(others.iter().map(|(law, s)| score(law, s)));
    Ok(match winner {
        Some(k) => {
            let (law, selection) = others.swap_remove(k);
            (selection, Some(law), scores)
        }
        None => (chosen, None, scores),
    })
}

/// The BIC of the greedy selection's whole model: `base`'s at the floor `sigma`, plus
/// each added effect's ΔBIC as scored when it was accepted (with the price of its shape
/// search).
fn whole_model_bic(base: &Fitted, greedy: &Greedy, sigma: [f64; 2]) -> f64 {
    let added: f64 = greedy
        .rounds
        .iter()
        .filter_map(|r| {
            let accepted = r.accepted?;
            r.scores
                .iter()
                .find(|s| s.candidate == accepted && s.passes)
                .map(|s| s.delta_bic)
        })
        .sum();
    chi2_and_bic(base, sigma).1 + added
}

/// The position-level base fit: the hysteresis law chosen by BIC (at the noise floor of
/// the DHCT gap), outliers of that fit dropped, then the base model fitted again to the
/// rest and refitted in full at the noise floor of its residuals.
fn fit_base(
    prepared: &Prepared,
    geometry: &ScanGeometry,
    options: &DiagnoseOptions,
) -> Result<BaseFit, DiagnoseError> {
    let all = &prepared.observations;
    // Start model: the DHCT fit and the lattice fit.
    let start = start_model(prepared, options.fit_lattice_scale);
    let iterations = options.selection.max_iterations;
    // Noise floor: first from the DHCT gap, then from the base fit's residuals.
    let lower = options.lower_floor_to_trace_retrace;
    let mut sigma = estimate(all, &prepared.dhct_gap, geometry, lower).sigma_m;
    let t0_bounds = creep_t0_bounds(geometry, all);
    // The hysteresis law and creep form chosen by the data (BIC), part of the base model
    // from here on.
    let ChosenBase {
        best: first,
        choice: base_choice,
        log_form,
        other_laws,
    } = choose_base(
        &start,
        &prepared.dhct_model.hysteresis,
        geometry,
        all,
        sigma,
        iterations,
        t0_bounds,
    )?;
    // From here on, residuals are compared with the fits' 1σ through the first model's
    // timing gain (held fixed).
    let all = &whitened(&first.model, geometry, all);
    let first = Fitted {
        residuals: first.model.residuals(geometry, all),
        ..first
    };
    sigma = estimate(all, &first.residuals, geometry, lower).sigma_m;
    let keep = inliers(&first.residuals, sigma, options.outlier_sigma);
    let observations: Vec<Observation> = all
        .iter()
        .zip(&keep)
        .filter(|(_, k)| **k)
        .map(|(o, _)| *o)
        .collect();
    if observations.len() < MIN_FEATURES {
        return Err(DiagnoseError::TooFewFeatures {
            what: "diagnosis (after outlier rejection)",
            found: observations.len(),
            needed: MIN_FEATURES,
        });
    }
    let base = fit(
        first.model.clone(),
        geometry,
        &observations,
        sigma,
        iterations,
    )?;
    let noise = estimate(&observations, &base.residuals, geometry, lower);
    let base = refit(
        base.model,
        geometry,
        &observations,
        noise.sigma_m,
        iterations,
        t0_bounds,
    )?;
    // A failed fit of the log form (or of another law) leaves the choice unchallenged.
    let refit_kept = |model: GlobalModel| {
        refit(
            model,
            geometry,
            &observations,
            noise.sigma_m,
            iterations,
            t0_bounds,
        )
        .ok()
    };
    let log_base = log_form.and_then(|log| refit_kept(log.model));
    let law_bases = other_laws
        .into_iter()
        .filter(|(name, _)| reconsidered(&base_choice.hysteresis_law, name))
        .filter_map(|(name, f)| Some((name, refit_kept(f.model)?)))
        .collect();
    Ok(BaseFit {
        first,
        base_choice,
        keep,
        observations,
        base,
        log_base,
        law_bases,
        noise,
        t0_bounds,
    })
}

/// Whether the law `other` is tried again with effects when the base chose `chosen`: a
/// polynomial law (quartic, cubic) is flexible enough to take part of an effect the base
/// leaves out (a piezo non-linearity's odd part, a turnaround transient) and win the
/// base's comparison for it; the rigid laws (power, exponential) cannot, so they are
/// tried again when a polynomial was chosen.
fn reconsidered(chosen: &str, other: &str) -> bool {
    matches!(chosen, "quartic" | "cubic") && matches!(other, "power" | "exponential")
}

/// Which residuals (metres) are not outliers: within `outlier_sigma` (both axes combined)
/// of the residuals' own robust spread, at least the noise floor `sigma` — not of the
/// floor itself, so that a large unmodelled effect is not thrown away as outliers.
fn inliers(residuals: &[[f64; 2]], sigma: [f64; 2], outlier_sigma: f64) -> Vec<bool> {
    let spread = [0, 1].map(|a| {
        let v: Vec<f64> = residuals.iter().map(|r| r[a]).collect();
        robust_sigma(&v).max(sigma[a])
    });
    residuals
        .iter()
        .map(|r| ((r[0] / spread[0]).powi(2) + (r[1] / spread[1]).powi(2)).sqrt() <= outlier_sigma)
        .collect()
}

/// The base model and every accepted extension, fitted in full at the final noise floor
/// (twice the iterations, the base creep's `t0` profiled within `t0_bounds`).
fn refit(
    model: GlobalModel,
    geometry: &ScanGeometry,
    observations: &[Observation],
    sigma: [f64; 2],
    iterations: usize,
    t0_bounds: (f64, f64),
) -> Result<Fitted, DiagnoseError> {
    fit_profiled(
        model,
        geometry,
        observations,
        sigma,
        2 * iterations,
        t0_bounds,
    )
}

/// The greedy selection: each round scores the remaining candidates on top of the current
/// model (`context.fitted` at first) and adds the best that passes, refitted in full,
/// until none passes, none is left or `max_effects` were added (a repeatable candidate,
/// [`Candidate::is_repeatable`], stays in the running). Returns the final model.
fn select_effects(
    context: &Current,
    options: &DiagnoseOptions,
) -> Result<(Fitted, Greedy), DiagnoseError> {
    let done = advance(
        context,
        options,
        Progress::start(context, options),
        usize::MAX,
    )?;
    Ok((done.current, done.greedy))
}

/// A greedy selection under way: the model so far, what it found, the candidates still in
/// the running, and whether it has ended (a round passed nothing).
struct Progress {
    current: Fitted,
    greedy: Greedy,
    remaining: Vec<Candidate>,
    ended: bool,
}

impl Progress {
    /// Before the first round: `context.fitted` and every candidate of `options`.
    fn start(context: &Current, options: &DiagnoseOptions) -> Progress {
        Progress {
            current: context.fitted.clone(),
            greedy: Greedy {
                rounds: Vec::new(),
                added: Vec::new(),
                top: None,
                top_gap: None,
            },
            remaining: options.candidates.clone(),
            ended: false,
        }
    }
}

/// [`select_effects`]'s rounds, at most `rounds` more of them, from `progress`.
fn advance(
    context: &Current,
    options: &DiagnoseOptions,
    mut progress: Progress,
    rounds: usize,
) -> Result<Progress, DiagnoseError> {
    let sigma = context.sigma;
    for _ in 0..rounds {
        let Progress {
            current,
            greedy,
            remaining,
            ended,
        } = &mut progress;
        if *ended || greedy.rounds.len() >= options.selection.max_effects || remaining.is_empty() {
            break;
        }
        let state = Current {
            fitted: current,
            ..*context
        };
        let scored = round(&state, remaining, &options.selection);
        if greedy.rounds.is_empty()
            && let Some(s) = scored.iter().find(|s| s.fitted.is_some())
        {
            greedy.top = Some(s.score.candidate);
            greedy.top_gap = s
                .fitted
                .as_ref()
                .map(|f| GapSummary::of(&f.residuals, sigma, f.model.free_count()).gap_to_noise);
        }
        let winner = scored.iter().find(|s| s.score.passes && s.fitted.is_some());
        let accepted = winner.map(|w| w.score.candidate);
        if let Some(w) = winner {
            let f = w
                .fitted
                .clone()
                .unwrap_or_else(|| unreachable!("filtered on Some"));
            let mut added = added_effect(w, &f, current, sigma);
            added.about_as_good = about_as_good(w, &scored);
            greedy.added.push(added);
            *current = refit(
                f.model,
                context.geometry,
                context.observations,
                sigma,
                options.selection.max_iterations,
                context.t0_bounds,
            )?;
            if !w.score.candidate.is_repeatable() {
                remaining.retain(|c| *c != w.score.candidate);
            }
        }
        greedy.rounds.push(GreedyRound {
            scores: scored.into_iter().map(|s| s.score).collect(),
            accepted,
        });
        *ended = accepted.is_none();
    }
    Ok(progress)
}

/// The other refitted, passing candidates of `scored` whose χ² reduction comes within
/// [`NEAR_TIE_FRACTION`] of the accepted `w`'s.
fn about_as_good(w: &Scored, scored: &[Scored]) -> Vec<Candidate> {
    let mut out: Vec<Candidate> = scored
        .iter()
        .filter(|s| s.score.passes && s.fitted.is_some())
        .filter(|s| s.score.candidate != w.score.candidate)
        .filter(|s| s.score.delta_chi2 >= (1.0 - NEAR_TIE_FRACTION) * w.score.delta_chi2)
        .map(|s| s.score.candidate)
        .collect();
    out.dedup();
    out
}

/// The effect `w` added to `current`, as fitted in `f` (its parameters, and the gap after
/// it at the noise floor `sigma`).
fn added_effect(w: &Scored, f: &Fitted, current: &Fitted, sigma: [f64; 2]) -> AddedEffect {
    let from = current.model.terms.len();
    // A new term is appended; a replaced term (asymmetric hysteresis) sits at its old index.
    // (A repeated candidate's earlier terms carry the same label: never look them up.)
    let index = if f.model.terms.len() > from {
        from
    } else {
        f.model
            .terms
            .iter()
            .position(|t| t.label == w.score.candidate.name())
            .unwrap_or(from)
    };
    let count = f
        .model
        .terms
        .get(index)
        .map_or(0, |t| t.effect.parameter_names().len());
    // `parameters(index)` lists the terms from `index` on: the first `count` are its own.
    let parameters = f.parameters(index).into_iter().take(count).collect();
    AddedEffect {
        candidate: w.score.candidate,
        shape: w.score.shape.clone(),
        parameters,
        gap_after: GapSummary::of(&f.residuals, sigma, f.model.free_count()),
        about_as_good: Vec::new(),
    }
}

/// Per-feature residuals of the DHCT sim, the base fit and the final model (outliers carry
/// the first base fit's residual for both).
fn feature_residuals(
    prepared: &Prepared,
    fitted: &BaseFit,
    base: &Fitted,
    current: &Fitted,
) -> Vec<FeatureResidual> {
    let all = &prepared.observations;
    let (keep, first) = (&fitted.keep, &fitted.first);
    let mut residuals = Vec::with_capacity(all.len());
    let mut used = 0;
    for (i, o) in all.iter().enumerate() {
        let (base_m, final_m, outlier) = if keep[i] {
            let r = (base.residuals[used], current.residuals[used], false);
            used += 1;
            r
        } else {
            (first.residuals[i], first.residuals[i], true)
        };
        residuals.push(FeatureResidual {
            set: o.set,
            index: o.index,
            pass: o.pass,
            time_s: o.time_s,
            line_time_s: o.line_time_s,
            controller_m: o.controller_m,
            dhct_gap_m: prepared.dhct_gap[i],
            base_m,
            final_m,
            outlier,
        });
    }
    residuals
}
