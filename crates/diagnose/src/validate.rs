//! Validation on withheld effects: simulated scans with base distortion + one effect (or
//! none, or two), diagnosed with the effect withheld from the base model; identification,
//! false alarms and shrink, tabulated for a tuned and a held-out set.

use std::fmt;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::synth::{ValidationCase, simulate_images, simulate_positions};
use crate::{Candidate, DiagnoseOptions, diagnose};

/// Options of [`validate`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ValidationOptions {
    /// Effects simulated one at a time.
    pub effects: Vec<Candidate>,
    /// Seeds of the tuned set (each effect, each seed).
    pub tuned_seeds: Vec<u64>,
    /// Seeds of the held-out set (other magnitudes, frequencies; never tuned on).
    pub held_out_seeds: Vec<u64>,
    /// Effect-free seeds, tuned set.
    pub tuned_null_seeds: Vec<u64>,
    /// Effect-free seeds, held-out set.
    pub held_out_null_seeds: Vec<u64>,
    /// Two-effect mixtures.
    pub mixtures: Vec<[Candidate; 2]>,
    /// Seeds of the mixtures (tuned); the held-out set uses `seed + 7000`.
    pub mixture_seeds: Vec<u64>,
    /// Also run the first tuned seed of every effect through rendered images and the
    /// feature finder (slower).
    pub image_path: bool,
    /// Localisation noise of the position-only path, metres per axis.
    pub noise_m: f64,
    /// Diagnosis options.
    pub diagnose: DiagnoseOptions,
}

/// The simulator effects the validation covers; scan coupling is included but scored as
/// *degenerate* (linear coupling equals lattice rotation + drift at the position level).
pub const VALIDATED_EFFECTS: [Candidate; 9] = [
    Candidate::LineDrift,
    Candidate::ExponentialCreep,
    Candidate::SecondCreep,
    Candidate::AsymmetricHysteresis,
    Candidate::SlowHysteresis,
    Candidate::Vibration,
    Candidate::TipChange,
    Candidate::HeightCoupling,
    Candidate::ScanCoupling,
];

impl Default for ValidationOptions {
    fn default() -> Self {
        ValidationOptions {
            effects: VALIDATED_EFFECTS.to_vec(),
            tuned_seeds: vec![1, 2, 3],
            held_out_seeds: vec![3001, 3002],
            tuned_null_seeds: (100..120).collect(),
            held_out_null_seeds: (4001..4021).collect(),
            mixtures: vec![
                [Candidate::TipChange, Candidate::Vibration],
                [Candidate::LineDrift, Candidate::SlowHysteresis],
                [Candidate::ExponentialCreep, Candidate::HeightCoupling],
            ],
            mixture_seeds: vec![11],
            image_path: false,
            noise_m: 2e-12,
            diagnose: DiagnoseOptions {
                locate: false,
                ..DiagnoseOptions::default()
            },
        }
    }
}

/// Kind of a validation case.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum CaseKind {
    /// One identifiable effect.
    Single,
    /// One effect that is degenerate with the base model + lattice (scan coupling).
    Degenerate,
    /// No effect.
    EffectFree,
    /// Two effects.
    Mixture,
}

/// One validation case's outcome.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CaseResult {
    /// Name.
    pub name: String,
    /// Kind.
    pub kind: CaseKind,
    /// Withheld effects.
    pub truth: Vec<Candidate>,
    /// Held-out set?
    pub held_out: bool,
    /// `"positions"` or `"images"`.
    pub path: String,
    /// Effects the diagnosis added, in order.
    pub identified: Vec<Candidate>,
    /// Single: top = truth; degenerate: none or the truth; effect-free: none; mixture: the
    /// first two added = the truth (any order).
    pub correct: bool,
    /// Gap/noise of the base model.
    pub gap_before: f64,
    /// Gap/noise after the top-ranked candidate.
    pub gap_after_top: Option<f64>,
    /// Gap/noise after the greedy set.
    pub gap_after: f64,
    /// Noise floor found, metres `[x, y]`.
    pub noise_floor_m: [f64; 2],
    /// Features used.
    pub features: usize,
    /// Error, if the diagnosis failed.
    pub error: Option<String>,
}

/// Summary of one set (tuned or held out).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SetSummary {
    /// Single-effect cases.
    pub effect_cases: usize,
    /// Of which top-1 correct.
    pub top1_correct: usize,
    /// Effect-free cases.
    pub null_cases: usize,
    /// Of which with any effect added.
    pub false_alarms: usize,
    /// Mixture cases.
    pub mixture_cases: usize,
    /// Of which both effects found.
    pub mixtures_correct: usize,
    /// Correct single cases with gap/noise after ≤ 1.2.
    pub gap_ok: usize,
    /// Largest gap/noise after the identified effect, over correct single cases.
    pub worst_gap_after: f64,
    /// Mean gap/noise before, over single cases.
    pub mean_gap_before: f64,
    /// Mean gap/noise after, over correct single cases.
    pub mean_gap_after: f64,
}

impl SetSummary {
    fn of(cases: &[&CaseResult]) -> SetSummary {
        let single: Vec<&&CaseResult> = cases
            .iter()
            .filter(|c| c.kind == CaseKind::Single)
            .collect();
        let correct: Vec<&&&CaseResult> = single.iter().filter(|c| c.correct).collect();
        let null: Vec<&&CaseResult> = cases
            .iter()
            .filter(|c| c.kind == CaseKind::EffectFree)
            .collect();
        let mix: Vec<&&CaseResult> = cases
            .iter()
            .filter(|c| c.kind == CaseKind::Mixture)
            .collect();
        let mean = |v: Vec<f64>| {
            if v.is_empty() {
                f64::NAN
            } else {
                v.iter().sum::<f64>() / v.len() as f64
            }
        };
        SetSummary {
            effect_cases: single.len(),
            top1_correct: correct.len(),
            null_cases: null.len(),
            false_alarms: null.iter().filter(|c| !c.correct).count(),
            mixture_cases: mix.len(),
            mixtures_correct: mix.iter().filter(|c| c.correct).count(),
            gap_ok: correct.iter().filter(|c| c.gap_after <= 1.2).count(),
            worst_gap_after: correct.iter().map(|c| c.gap_after).fold(0.0, f64::max),
            mean_gap_before: mean(single.iter().map(|c| c.gap_before).collect()),
            mean_gap_after: mean(correct.iter().map(|c| c.gap_after).collect()),
        }
    }

    /// Top-1 rate over single-effect cases.
    pub fn top1_rate(&self) -> f64 {
        self.top1_correct as f64 / self.effect_cases.max(1) as f64
    }

    /// False-alarm rate over effect-free cases.
    pub fn false_alarm_rate(&self) -> f64 {
        self.false_alarms as f64 / self.null_cases.max(1) as f64
    }

    /// Whether the acceptance criteria hold.
    pub fn accepted(&self) -> bool {
        self.top1_rate() >= 0.9
            && self.false_alarm_rate() <= 0.05
            && self.gap_ok == self.top1_correct
    }
}

/// Everything [`validate`] measured.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ValidationReport {
    /// Every case.
    pub cases: Vec<CaseResult>,
    /// Tuned set.
    pub tuned: SetSummary,
    /// Held-out set.
    pub held_out: SetSummary,
}

fn run_case(
    case: &ValidationCase,
    images: bool,
    options: &ValidationOptions,
    seed: u64,
) -> CaseResult {
    let kind = match case.truth.as_slice() {
        [] => CaseKind::EffectFree,
        [Candidate::ScanCoupling] => CaseKind::Degenerate,
        [_] => CaseKind::Single,
        _ => CaseKind::Mixture,
    };
    let scan = if images {
        simulate_images(&case.config)
    } else {
        simulate_positions(&case.config, options.noise_m, seed)
    };
    let result = scan.and_then(|scan| {
        let lattice = case.config.surface.lattice.build()?;
        diagnose(
            &scan.inputs(),
            &scan.geometry,
            lattice.as_ref(),
            &options.diagnose,
        )
    });
    let mut out = CaseResult {
        name: case.name.clone(),
        kind,
        truth: case.truth.clone(),
        held_out: case.held_out,
        path: if images { "images" } else { "positions" }.into(),
        identified: Vec::new(),
        correct: false,
        gap_before: f64::NAN,
        gap_after_top: None,
        gap_after: f64::NAN,
        noise_floor_m: [f64::NAN; 2],
        features: 0,
        error: None,
    };
    match result {
        Ok(report) => {
            out.identified = report.identified();
            out.gap_before = report.shrink.before;
            out.gap_after_top = report.shrink.after_top;
            out.gap_after = report.shrink.after_greedy;
            out.noise_floor_m = report.noise.sigma_m;
            out.features = report.features_used;
        }
        Err(e) => out.error = Some(e.to_string()),
    }
    out.correct = out.error.is_none()
        && match kind {
            CaseKind::Single => out.identified.first() == case.truth.first(),
            CaseKind::Degenerate => {
                out.identified.is_empty() || out.identified.first() == case.truth.first()
            }
            CaseKind::EffectFree => out.identified.is_empty(),
            CaseKind::Mixture => {
                let mut a: Vec<Candidate> = out.identified.iter().take(2).copied().collect();
                let mut b = case.truth.clone();
                a.sort();
                b.sort();
                a == b
            }
        };
    out
}

/// Runs the validation sweep (cases in parallel).
pub fn validate(options: &ValidationOptions) -> ValidationReport {
    let mut jobs: Vec<(ValidationCase, bool, u64)> = Vec::new();
    for (seeds, held_out) in [
        (&options.tuned_seeds, false),
        (&options.held_out_seeds, true),
    ] {
        for &c in &options.effects {
            for &s in seeds.iter() {
                jobs.push((ValidationCase::single(c, s, held_out), false, s));
            }
        }
    }
    for (seeds, held_out) in [
        (&options.tuned_null_seeds, false),
        (&options.held_out_null_seeds, true),
    ] {
        for &s in seeds.iter() {
            jobs.push((ValidationCase::effect_free(s, held_out), false, s));
        }
    }
    for &s in &options.mixture_seeds {
        for pair in &options.mixtures {
            jobs.push((ValidationCase::with_effects(pair, s, false), false, s));
            jobs.push((
                ValidationCase::with_effects(pair, s + 7000, true),
                false,
                s + 7000,
            ));
        }
    }
    if options.image_path
        && let Some(&s) = options.tuned_seeds.first()
    {
        for &c in &options.effects {
            jobs.push((ValidationCase::single(c, s, false), true, s));
        }
        jobs.push((ValidationCase::effect_free(s + 500, false), true, s + 500));
    }
    let cases: Vec<CaseResult> = jobs
        .par_iter()
        .map(|(case, images, seed)| run_case(case, *images, options, *seed))
        .collect();
    let pick = |held: bool| {
        cases
            .iter()
            .filter(|c| c.held_out == held)
            .collect::<Vec<_>>()
    };
    ValidationReport {
        tuned: SetSummary::of(&pick(false)),
        held_out: SetSummary::of(&pick(true)),
        cases,
    }
}

fn label(c: Option<&Candidate>) -> &'static str {
    c.map_or("none", |c| c.name())
}

impl ValidationReport {
    /// Confusion matrix (rows: withheld effect of single/degenerate/effect-free cases;
    /// columns: top identified) of one set, as text.
    pub fn confusion_matrix(&self, held_out: bool) -> String {
        let cases: Vec<&CaseResult> = self
            .cases
            .iter()
            .filter(|c| c.held_out == held_out && c.kind != CaseKind::Mixture)
            .collect();
        let mut names: Vec<&'static str> = Vec::new();
        for c in &cases {
            for n in [label(c.truth.first()), label(c.identified.first())] {
                if !names.contains(&n) {
                    names.push(n);
                }
            }
        }
        let mut s = format!("{:<22}", "withheld \\ top");
        for n in &names {
            s += &format!(" {:>5}", &n[..n.len().min(5)]);
        }
        s.push('\n');
        for row in &names {
            let members: Vec<&&CaseResult> = cases
                .iter()
                .filter(|c| label(c.truth.first()) == *row)
                .collect();
            if members.is_empty() {
                continue;
            }
            s += &format!("{row:<22}");
            for col in &names {
                let k = members
                    .iter()
                    .filter(|c| label(c.identified.first()) == *col)
                    .count();
                s += &format!(
                    " {:>5}",
                    if k == 0 {
                        ".".to_string()
                    } else {
                        k.to_string()
                    }
                );
            }
            s.push('\n');
        }
        s
    }
}

impl fmt::Display for SetSummary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "top-1 {}/{} ({:.0} %), false alarms {}/{} ({:.0} %), mixtures {}/{}, gap/noise before {:.2} → after {:.2} (worst {:.2}; ≤ 1.2 in {}/{}) — {}",
            self.top1_correct,
            self.effect_cases,
            100.0 * self.top1_rate(),
            self.false_alarms,
            self.null_cases,
            100.0 * self.false_alarm_rate(),
            self.mixtures_correct,
            self.mixture_cases,
            self.mean_gap_before,
            self.mean_gap_after,
            self.worst_gap_after,
            self.gap_ok,
            self.top1_correct,
            if self.accepted() {
                "ACCEPTED"
            } else {
                "NOT accepted"
            }
        )
    }
}

impl fmt::Display for ValidationReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "{:<44} {:<9} {:<6} {:<34} {:>6} {:>6} {:>6} ok",
            "case", "set", "path", "identified", "before", "top", "after"
        )?;
        for c in &self.cases {
            let ids = if let Some(e) = &c.error {
                format!("error: {}", &e[..e.len().min(30)])
            } else if c.identified.is_empty() {
                "none".to_string()
            } else {
                c.identified
                    .iter()
                    .map(|c| c.name())
                    .collect::<Vec<_>>()
                    .join("+")
            };
            writeln!(
                f,
                "{:<44} {:<9} {:<6} {:<34} {:>6.2} {:>6} {:>6.2} {}",
                c.name,
                if c.held_out { "held-out" } else { "tuned" },
                c.path,
                ids,
                c.gap_before,
                c.gap_after_top.map_or("—".into(), |v| format!("{v:.2}")),
                c.gap_after,
                if c.correct { "yes" } else { "NO" }
            )?;
        }
        writeln!(
            f,
            "\nconfusion matrix, tuned set:\n{}",
            self.confusion_matrix(false)
        )?;
        writeln!(
            f,
            "confusion matrix, held-out set:\n{}",
            self.confusion_matrix(true)
        )?;
        writeln!(f, "tuned:    {}", self.tuned)?;
        writeln!(f, "held-out: {}", self.held_out)
    }
}
