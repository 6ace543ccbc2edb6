//! The serialisable diagnosis report and its text form.

use std::fmt;

use serde::{Deserialize, Serialize};

use crate::evidence::location::GapLocation;
use crate::evidence::noise::NoiseFloor;
use crate::model::base::{BaseChoice, DECISIVE_BIC, LawScore};
use crate::model::fit::FittedParameter;
use crate::report::gap::{AddedEffect, FeatureResidual, GapSummary, NEAR_TIE_FRACTION, Shrink};
use crate::report::verdict::{Verdict, VerdictKind, names};
use crate::search::candidates::Candidate;
use crate::search::select::CandidateScore;
use dhct_scan::quantity::value_with_sigma;

/// A fitted position-level model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelSummary {
    /// Terms, in order (e.g. `thermal-drift`, `creep`, `fast-hysteresis`, `tip-change`).
    pub terms: Vec<String>,
    /// Every term parameter with its 1σ uncertainty (SI, the simulator's names).
    pub parameters: Vec<FittedParameter>,
    /// Lattice origin, metres (sample frame).
    pub lattice_origin_m: [f64; 2],
    /// Lattice rotation, radians.
    pub lattice_angle_rad: f64,
    /// Lattice scales `[s_x, s_y]` (1 = nominal; fixed unless `fit_lattice_scale`).
    pub lattice_scale: [f64; 2],
    /// Its gap.
    pub gap: GapSummary,
}

/// One greedy round.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GreedyRound {
    /// Every candidate's score, best first (passing ones first).
    pub scores: Vec<CandidateScore>,
    /// The effect added in this round, if any passed.
    pub accepted: Option<Candidate>,
}

/// Each alternative with its BIC against the chosen one, e.g. `power ΔBIC 0.0, cubic ΔBIC 6.2`.
fn bic_scores(scores: &[LawScore]) -> String {
    scores
        .iter()
        .map(|l| format!("{} ΔBIC {:.1}", l.law, l.delta_bic))
        .collect::<Vec<_>>()
        .join(", ")
}

/// Everything the diagnosis found.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DiagnosisReport {
    /// The verdict: `no_gap`, `explained`, `partly_explained` or `unexplained`.
    pub verdict: VerdictKind,
    /// The verdict's numbers (gap before/after in units of the floor, the named effects,
    /// where the remaining gap lies) and its plain-words summary.
    pub verdict_details: Verdict,
    /// The base model's hysteresis law as the data chose it, with every law's BIC.
    pub base_choice: BaseChoice,
    /// Features given.
    pub features_in: usize,
    /// Features indexed and used.
    pub features_used: usize,
    /// Features not indexed (or too far from any lattice site).
    pub unindexed: usize,
    /// Features whose fit residual is far above the others' (not used).
    #[serde(default)]
    pub poor_fits: usize,
    /// Features dropped as outliers of the base fit.
    pub outliers: usize,
    /// The noise floor.
    pub noise: NoiseFloor,
    /// Gap of the base DHCT sim (local-distortion fit, controller frame).
    pub dhct: GapSummary,
    /// The position-level base model (drift + creep + hysteresis + lattice).
    pub base: ModelSummary,
    /// The offset across the lines between the passes that the base model took, and
    /// whether it is larger than measuring the features makes it (then the verdict's
    /// summary says what to check). `None` with one pass.
    #[serde(default)]
    pub pass_offset: Option<crate::PassOffsetReading>,
    /// Where the base gap lies.
    pub location: Option<GapLocation>,
    /// The greedy rounds.
    pub rounds: Vec<GreedyRound>,
    /// Effects added, in order (none when the verdict is `no_gap`).
    pub added: Vec<AddedEffect>,
    /// With `no_gap`: effects the selection still found significant, below the floor (not
    /// findings), in order.
    #[serde(default)]
    pub below_floor: Vec<AddedEffect>,
    /// Gap before and after.
    pub shrink: Shrink,
    /// The final model.
    pub final_model: ModelSummary,
    /// Where the final gap lies.
    pub final_location: Option<GapLocation>,
    /// Per-feature residuals.
    pub residuals: Vec<FeatureResidual>,
    /// The image view below one feature (slice displacements), when the images were
    /// given ([`DiagnosisReport::with_sub_feature_view`]).
    #[serde(default)]
    pub sub_feature: Option<crate::SubFeatureView>,
    /// What only the height tells (terraces, feature heights and their changes): none of
    /// it moves a feature, so none of it is a scan distortion.
    #[serde(default)]
    pub heights: Option<crate::HeightView>,
    /// The final model rendered forward and compared with each image, pixel by pixel
    /// (empty when the images were not given; [`crate::pair_views`]).
    #[serde(default)]
    pub image_residual: Vec<crate::PassResidual>,
}

impl DiagnosisReport {
    /// The effects added, in order.
    pub fn identified(&self) -> Vec<Candidate> {
        self.added.iter().map(|a| a.candidate).collect()
    }

    /// The top-ranked candidate of the first round, if it passed.
    pub fn top(&self) -> Option<Candidate> {
        self.added.first().map(|a| a.candidate)
    }

    /// JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).unwrap_or_else(|e| format!("{{\"error\": \"{e}\"}}"))
    }
}

fn pm(v: f64) -> String {
    format!("{:.2}", v * 1e12)
}

/// `rms x × y pm, gap/noise, χ²/dof` of a gap.
fn gap_line(s: &GapSummary) -> String {
    format!(
        "rms {} × {} pm, gap/noise {:.2}, χ²/dof {:.2}",
        pm(s.rms_m[0]),
        pm(s.rms_m[1]),
        s.gap_to_noise,
        s.chi2_per_dof
    )
}

impl fmt::Display for DiagnosisReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.write_overview(f)?;
        self.write_base(f)?;
        if let Some(loc) = &self.location {
            write_location(f, loc)?;
        }
        self.write_rounds(f)?;
        self.write_added(f)?;
        if !self.below_floor.is_empty() {
            let listed: Vec<Candidate> = self.below_floor.iter().map(|a| a.candidate).collect();
            writeln!(
                f,
                "below the floor (significant, not findings): {}",
                names(&listed)
            )?;
        }
        self.write_shrink(f)
    }
}

impl DiagnosisReport {
    /// The verdict, the feature counts and the noise floor (pm).
    fn write_overview(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "verdict: {} — {}",
            self.verdict.name(),
            self.verdict_details.summary
        )?;
        if let Some(view) = &self.sub_feature {
            writeln!(f, "{}", view.describe())?;
        }
        writeln!(
            f,
            "features: {} in, {} used, {} not indexed, {} poorly fitted, {} outliers",
            self.features_in, self.features_used, self.unindexed, self.poor_fits, self.outliers
        )?;
        let n = &self.noise;
        writeln!(
            f,
            "noise floor: {} × {} pm ({}); localisation {}; successive differences {}; \
             trace/retrace {} (an upper bound only)",
            pm(n.sigma_m[0]),
            pm(n.sigma_m[1]),
            n.source.describe(),
            n.localisation.describe(),
            n.successive_differences.describe(),
            n.trace_retrace.describe(),
        )?;
        if let Some(h) = &self.heights {
            writeln!(
                f,
                "heights (z only: they move no feature, so they are no scan distortion): {}",
                h.describe()
            )?;
        }
        for p in &self.image_residual {
            writeln!(
                f,
                "image minus the final model rendered with the measured atom, {}",
                p.describe()
            )?;
        }
        Ok(())
    }

    /// The DHCT sim's gap, the base hysteresis law and creep form chosen, each image's line
    /// levelling and the base fit's gap.
    fn write_base(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "DHCT sim gap (controller frame): {}",
            gap_line(&self.dhct)
        )?;
        writeln!(
            f,
            "base hysteresis law (BIC): {} ({})",
            self.base_choice.hysteresis_law,
            bic_scores(&self.base_choice.hysteresis)
        )?;
        writeln!(
            f,
            "base creep form (BIC):     {} ({})",
            self.base_choice.creep_form,
            bic_scores(&self.base_choice.creep)
        )?;
        if let Some(d) = self.base_choice.creep_form_whole_model_delta_bic {
            let other = self
                .base_choice
                .creep
                .iter()
                .filter(|c| c.law != "log")
                .min_by(|a, b| a.bic.total_cmp(&b.bic))
                .map_or("other", |c| c.law.as_str());
            writeln!(
                f,
                "  with the effects each form's selection named, the whole model with the {other} \
                 form has ΔBIC {d:.1} against the log form's ({})",
                if d >= 0.0 {
                    "the log form's is better: it is kept"
                } else if d > -DECISIVE_BIC {
                    "not decisive: the log form is kept"
                } else {
                    "decisive: it is kept"
                }
            )?;
        }
        if !self.base_choice.hysteresis_whole_model.is_empty() {
            let wholes: Vec<String> = self
                .base_choice
                .hysteresis_whole_model
                .iter()
                .map(|w| {
                    let effects = match w.effects.as_slice() {
                        [] => "no effect".to_string(),
                        e => e.join(" + "),
                    };
                    format!("{} ΔBIC {:.1} with {effects}", w.law, w.delta_bic)
                })
                .collect();
            writeln!(
                f,
                "  whole models, each law with the effects its own selection named: {}",
                wholes.join("; ")
            )?;
        }
        for p in &self.base_choice.line_levelling {
            writeln!(f, "line levelling, {}: {}", p.pass, p.levelling)?;
        }
        writeln!(
            f,
            "base position-level fit:        {}",
            gap_line(&self.base.gap)
        )
    }

    /// One table per greedy round: every candidate's scores.
    fn write_rounds(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (k, r) in self.rounds.iter().enumerate() {
            writeln!(
                f,
                "round {}: {:<22} {:>9} {:>9} {:>8} {:>6} pass",
                k + 1,
                "candidate",
                "Δχ²",
                "ΔBIC",
                "CV ratio",
                "refit"
            )?;
            for s in &r.scores {
                writeln!(
                    f,
                    "         {:<22} {:>9.1} {:>9.1} {:>8.4} {:>6} {}",
                    s.candidate.name(),
                    s.delta_chi2,
                    s.delta_bic,
                    s.cv_ratio,
                    if s.refitted { "yes" } else { "no" },
                    if s.passes { "yes" } else { "no" }
                )?;
            }
        }
        Ok(())
    }

    /// Each effect added, with the gap after it and its parameters.
    fn write_added(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for a in &self.added {
            writeln!(
                f,
                "added {} ({}): {}",
                a.candidate,
                a.shape,
                gap_line(&a.gap_after)
            )?;
            if !a.about_as_good.is_empty() {
                writeln!(
                    f,
                    "    about as good (χ² reduction within {:.0} %, not told apart): {}",
                    100.0 * NEAR_TIE_FRACTION,
                    names(&a.about_as_good)
                )?;
            }
            for p in &a.parameters {
                let shown = value_with_sigma(p.value, p.sigma.unwrap_or(0.0), p.unit());
                writeln!(f, "    {} = {shown}", p.name)?;
            }
        }
        Ok(())
    }

    /// Gap/noise before, after the top candidate and after the greedy set (last line, no
    /// newline).
    fn write_shrink(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let s = &self.shrink;
        writeln!(
            f,
            "gap/noise: before {:.2}, after top ({}) {}, after greedy set {:.2}",
            s.before,
            s.top.map_or("—".to_string(), |c| c.to_string()),
            s.after_top.map_or("—".to_string(), |v| format!("{v:.2}")),
            s.after_greedy
        )
    }
}

/// Where the base gap concentrates: the hottest bins, the strongest spectral peak, the
/// jumps (pm, Hz, s).
fn write_location(f: &mut fmt::Formatter<'_>, loc: &GapLocation) -> fmt::Result {
    writeln!(f, "where the base gap concentrates:")?;
    for b in loc.hot_spots.iter().take(6) {
        writeln!(
            f,
            "  {:<28} n={:<5} χ²/dof {:.2} (z {:.1}), mean ({}, {}) pm",
            b.label,
            b.count,
            b.chi2_per_dof,
            b.excess_z,
            pm(b.mean_m[0]),
            pm(b.mean_m[1])
        )?;
    }
    if let Some(p) = loc.spectrum.peaks.first() {
        writeln!(
            f,
            "  strongest spectral peak {:.4} Hz, power {:.1}, false-alarm p {:.2e}",
            p.frequency_hz, p.power, p.false_alarm_probability
        )?;
    }
    for c in &loc.change_points {
        writeln!(
            f,
            "  jump at {:.2} s: ({}, {}) pm, statistic {:.0}",
            c.time_s,
            pm(c.jump_m[0]),
            pm(c.jump_m[1]),
            c.statistic
        )?;
    }
    Ok(())
}
