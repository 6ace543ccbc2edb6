//! The whole diagnosis: base stage, position-level base fit, noise floor, location of the
//! gap, greedy selection of effects, shrink.

use dhct_distortion::{DhctOptions, PassInput};
use dhct_lattice::Lattice;
use dhct_scan::ScanGeometry;
use dhct_simulate::EffectConfig;
use dhct_simulate::effects::{FastScanHysteresis, LogCreep, ThermalDrift};
use serde::{Deserialize, Serialize};

use crate::DiagnoseError;
use crate::base::choose_hysteresis;
use crate::candidates::{Candidate, creep_t0_bounds};
use crate::data::{MIN_FEATURES, Observation, prepare};
use crate::fit::{BASE_CREEP, Fitted, fit, fit_profiled};
use crate::location::locate;
use crate::model::{GlobalModel, LatticeParams, Term, sim_term};
use crate::noise::{estimate, robust_sigma};
use crate::report::{
    AddedEffect, DiagnosisReport, FeatureResidual, GapSummary, GreedyRound, ModelSummary, Shrink,
};
use crate::select::{Current, CvScheme, Folds, SelectionOptions, round};
use crate::verdict::decide;

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
}

impl Default for DiagnoseOptions {
    fn default() -> Self {
        DiagnoseOptions {
            dhct: DhctOptions::default(),
            candidates: Candidate::ALL.to_vec(),
            selection: SelectionOptions::default(),
            cv_scheme: CvScheme::PerCandidate,
            cv_blocks: 10,
            cv_folds: 5,
            outlier_sigma: 6.0,
            max_deviation_fraction: 0.3,
            fit_lattice_scale: false,
            locate: true,
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
    options.validate()?;
    let prepared = prepare(
        inputs,
        geometry,
        lattice,
        &options.dhct,
        options.max_deviation_fraction,
    )?;
    let all = prepared.observations.clone();
    // Start model: the DHCT fit and the lattice fit.
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
    let lf = &prepared.lattice_fit;
    let start = GlobalModel {
        terms,
        lattice: LatticeParams {
            origin_m: lf.origin_m,
            angle_rad: lf.angle_rad,
            scale: if options.fit_lattice_scale {
                lf.scale
            } else {
                [1.0, 1.0]
            },
            fit_scale: options.fit_lattice_scale,
        },
    };
    let iterations = options.selection.max_iterations;
    // Noise floor: first from the DHCT gap, then from the base fit's residuals.
    let mut sigma = estimate(&all, &prepared.dhct_gap, geometry).sigma_m;
    let t0_bounds = creep_t0_bounds(geometry, &all);
    // The hysteresis law chosen by the data (BIC), part of the base model from here on.
    let (first, base_choice) = choose_hysteresis(
        &start,
        &d.hysteresis,
        geometry,
        &all,
        sigma,
        iterations,
        t0_bounds,
    )?;
    sigma = estimate(&all, &first.residuals, geometry).sigma_m;
    // Outliers relative to the residuals' own robust spread (not the noise floor), so that
    // a large unmodelled effect is not thrown away as outliers.
    let spread = [0, 1].map(|a| {
        let v: Vec<f64> = first.residuals.iter().map(|r| r[a]).collect();
        robust_sigma(&v).max(sigma[a])
    });
    let keep: Vec<bool> = first
        .residuals
        .iter()
        .map(|r| {
            ((r[0] / spread[0]).powi(2) + (r[1] / spread[1]).powi(2)).sqrt()
                <= options.outlier_sigma
        })
        .collect();
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
    let mut base = fit(
        first.model.clone(),
        geometry,
        &observations,
        sigma,
        iterations,
    )?;
    let noise = estimate(&observations, &base.residuals, geometry);
    sigma = noise.sigma_m;
    // The base model and every accepted extension, fitted in full at the final noise floor.
    let refit = |model: GlobalModel| {
        fit_profiled(
            model,
            geometry,
            &observations,
            sigma,
            2 * iterations,
            t0_bounds,
        )
    };
    base = refit(base.model)?;
    let base_summary = summary(&base, sigma);
    let location = options
        .locate
        .then(|| locate(&observations, &base.residuals, sigma, geometry));
    let folds = Folds::new(
        &observations,
        geometry,
        options.cv_scheme,
        options.cv_blocks,
        options.cv_folds,
    );

    // Greedy selection.
    let mut current = base.clone();
    let mut remaining = options.candidates.clone();
    let mut rounds = Vec::new();
    let mut added = Vec::new();
    let mut top_gap = None;
    let mut top = None;
    for k in 0..options.selection.max_effects {
        if remaining.is_empty() {
            break;
        }
        let scored = round(
            &Current {
                fitted: &current,
                geometry,
                observations: &observations,
                sigma,
                folds: &folds,
                nn_distance_m: lattice.nearest_neighbour_distance(),
                t0_bounds,
            },
            &remaining,
            &options.selection,
        );
        if k == 0
            && let Some(s) = scored.iter().find(|s| s.fitted.is_some())
        {
            top = Some(s.score.candidate);
            top_gap = s
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
            let from = current.model.terms.len();
            // A replaced term (asymmetric hysteresis) sits at its old index.
            let index = f
                .model
                .terms
                .iter()
                .position(|t| t.label == w.score.candidate.name())
                .unwrap_or(from);
            let parameters = f
                .parameters(0)
                .into_iter()
                .filter(|p| f.model.terms[index].effect.name() == p.effect)
                .collect();
            added.push(AddedEffect {
                candidate: w.score.candidate,
                shape: w.score.shape.clone(),
                parameters,
                gap_after: GapSummary::of(&f.residuals, sigma, f.model.free_count()),
            });
            current = refit(f.model)?;
            remaining.retain(|c| *c != w.score.candidate);
        }
        rounds.push(GreedyRound {
            scores: scored.into_iter().map(|s| s.score).collect(),
            accepted,
        });
        if accepted.is_none() {
            break;
        }
    }
    let final_summary = summary(&current, sigma);
    let final_location = options
        .locate
        .then(|| locate(&observations, &current.residuals, sigma, geometry));
    let verdict = decide(
        base_summary.gap.gap_to_noise,
        final_summary.gap.gap_to_noise,
        added.iter().map(|a| a.candidate).collect(),
        final_location.as_ref(),
        observations.len(),
        noise.source,
    );
    // Per-feature residuals (outliers carry the base fit's prediction).
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
    Ok(DiagnosisReport {
        verdict: verdict.kind,
        verdict_details: verdict,
        base_choice,
        features_in: prepared.input_features,
        features_used: observations.len(),
        unindexed: prepared.unindexed,
        outliers: all.len() - observations.len(),
        dhct: GapSummary::of(&prepared.dhct_gap, sigma, 0),
        base: base_summary.clone(),
        location,
        rounds,
        shrink: Shrink {
            before: base_summary.gap.gap_to_noise,
            top,
            after_top: top_gap,
            after_greedy: final_summary.gap.gap_to_noise,
        },
        added,
        final_model: final_summary,
        final_location,
        sub_feature: None,
        noise,
        residuals,
    })
}
