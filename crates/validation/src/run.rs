//! The validation sweep: every case of every set simulated, diagnosed with its effect
//! withheld from the base model, and scored ([`validate`]).

use dhct_diagnose::{Candidate, DiagnoseOptions, VerdictKind};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::case::{ForeignEffect, ValidationCase};
use crate::set::{Catalogue, SetError, ValidationSet};
use crate::simulated::{PositionNoise, simulate_positions_with, simulate_rendered};
use crate::summary::{
    ABSORBED_VISIBILITY, CaseKind, CaseResult, SetReport, SetSummary, ValidationReport,
};

/// Options of [`validate`]; [`Default`] is the shipped sweep (`sets.toml`: its
/// `[sweep]` and every set with `sweep = true`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ValidationOptions {
    /// Effects simulated one at a time.
    pub effects: Vec<Candidate>,
    /// The sets, in report order.
    pub sets: Vec<ValidationSet>,
    /// Two-effect mixtures.
    pub mixtures: Vec<[Candidate; 2]>,
    /// Seeds of the mixtures (each set adds its `mixture_offset`).
    pub mixture_seeds: Vec<u64>,
    /// Also run the first tuned seed of every effect through rendered images and the
    /// feature finder (slower).
    pub image_path: bool,
    /// Localisation noise of the position-only path, metres per axis.
    pub noise_m: f64,
    /// Diagnosis options.
    pub diagnose: DiagnoseOptions,
}

impl ValidationOptions {
    /// At most `n` seeds per effect and mixture and `2n` effect-free seeds per set (quicker,
    /// less certain).
    pub fn truncate_seeds(&mut self, n: usize) {
        for set in &mut self.sets {
            set.seeds.truncate(n);
            set.null_seeds.truncate(2 * n);
            set.foreign_seeds.truncate(n);
        }
        self.mixture_seeds.truncate(n);
    }

    /// The sweep of `catalogue`: its plan and the sets named (every set with `sweep = true`
    /// when `names` is empty).
    pub fn of_catalogue(catalogue: &Catalogue, names: &[&str]) -> Result<Self, SetError> {
        let sets = if names.is_empty() {
            catalogue.sets.iter().filter(|s| s.sweep).cloned().collect()
        } else {
            names
                .iter()
                .map(|n| catalogue.named(n).cloned())
                .collect::<Result<_, _>>()?
        };
        let plan = &catalogue.sweep;
        Ok(ValidationOptions {
            effects: plan.effects.clone(),
            sets,
            mixtures: plan.mixtures.clone(),
            mixture_seeds: plan.mixture_seeds.clone(),
            image_path: false,
            noise_m: plan.noise_m,
            diagnose: DiagnoseOptions::default(),
        })
    }
}

impl Default for ValidationOptions {
    fn default() -> Self {
        ValidationOptions::of_catalogue(&Catalogue::shipped(), &[])
            .expect("the default sweep names no set")
    }
}

fn run_case(
    case: &ValidationCase,
    images: bool,
    options: &ValidationOptions,
    seed: u64,
) -> CaseResult {
    // The image path also reads the images below one feature, as `dhct diagnose` does.
    let result = if images {
        simulate_rendered(&case.config).and_then(|r| r.diagnosed(&case.config, &options.diagnose))
    } else {
        let noise = PositionNoise::of_form(&case.scans, options.noise_m);
        simulate_positions_with(&case.config, &noise, seed)
            .and_then(|scan| scan.diagnosed(&case.config, &options.diagnose))
    };
    // The floor the effect's visibility is measured against: the localisation noise
    // simulated on the position path, the floor the diagnosis found on the image path.
    let floor_m = match (&result, images) {
        (_, false) => Some([options.noise_m; 2]),
        (Ok(report), true) => Some(report.noise.sigma_m),
        (Err(_), true) => None,
    };
    let visibility = match case.truth.as_slice() {
        [c] if case.foreign.is_empty() && *c != Candidate::ScanCoupling => {
            floor_m.and_then(|floor| noise_free_visibility(case, floor))
        }
        _ => None,
    };
    let kind = match case.truth.as_slice() {
        _ if !case.foreign.is_empty() => CaseKind::OutOfLibrary,
        [] => CaseKind::EffectFree,
        [Candidate::ScanCoupling] => CaseKind::Degenerate,
        [_] if visibility.is_some_and(|v| v <= ABSORBED_VISIBILITY) => CaseKind::Absorbed,
        [_] => CaseKind::Single,
        _ => CaseKind::Mixture,
    };
    let mut out = CaseResult {
        name: case.name.clone(),
        kind,
        truth: case.truth.clone(),
        foreign: case.foreign.clone(),
        verdict: None,
        remaining: Vec::new(),
        set: case.set.clone(),
        path: if images { "images" } else { "positions" }.into(),
        identified: Vec::new(),
        below_floor: false,
        correct: false,
        gap_before: f64::NAN,
        visibility,
        gap_after_top: None,
        gap_after: f64::NAN,
        noise_floor_m: [f64::NAN; 2],
        features: 0,
        error: None,
    };
    match result {
        Ok(report) => {
            let details = &report.verdict_details;
            out.below_floor = details.effects.is_empty() && !details.below_floor.is_empty();
            out.identified = if out.below_floor {
                details.below_floor.clone()
            } else {
                details.effects.clone()
            };
            out.verdict = Some(report.verdict);
            out.remaining = report
                .verdict_details
                .remaining
                .iter()
                .map(|p| p.label.clone())
                .collect();
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
            CaseKind::Degenerate | CaseKind::Absorbed => {
                out.identified.is_empty() || out.identified.first() == case.truth.first()
            }
            CaseKind::EffectFree => {
                out.identified.is_empty() && out.verdict == Some(VerdictKind::NoGap)
            }
            CaseKind::OutOfLibrary => match out.verdict {
                Some(VerdictKind::Unexplained) => true,
                Some(VerdictKind::PartlyExplained) => !out.remaining.is_empty(),
                _ => false,
            },
            CaseKind::Mixture => {
                // The first two distinct effects named (a candidate may be named more than
                // once: several tip jumps).
                let mut a: Vec<Candidate> = Vec::new();
                for c in &out.identified {
                    if !a.contains(c) && a.len() < 2 {
                        a.push(*c);
                    }
                }
                let mut b = case.truth.clone();
                a.sort();
                b.sort();
                a == b
            }
        };
    out
}

/// How visible `case`'s one effect is beyond what the base model absorbs: the base model's
/// gap (RMS residual over the floor) on the same scan without noise, every feature still
/// reporting an uncertainty of `floor_m` (metres per axis, so the floor is that), `None`
/// if it cannot be computed.
fn noise_free_visibility(case: &ValidationCase, floor_m: [f64; 2]) -> Option<f64> {
    let mut scan = simulate_positions_with(&case.config, &PositionNoise::white(0.0), 0).ok()?;
    let (px, py) = (scan.geometry.pitch_x(), scan.geometry.pitch_y());
    for f in scan.trace.iter_mut().chain(scan.retrace.iter_mut()) {
        f.x_sigma_px = floor_m[0] / px;
        f.y_sigma_px = floor_m[1] / py;
    }
    let options = DiagnoseOptions {
        candidates: Vec::new(),
        locate: false,
        // Without noise the trace/retrace spread is near zero: it is not the floor here.
        lower_floor_to_trace_retrace: false,
        ..DiagnoseOptions::default()
    };
    let report = scan.diagnosed(&case.config, &options).ok()?;
    Some(report.shrink.before)
}

/// Runs the validation sweep (cases in parallel).
pub fn validate(options: &ValidationOptions) -> ValidationReport {
    let mut jobs: Vec<(ValidationCase, bool, u64)> = Vec::new();
    for set in &options.sets {
        let added = set
            .added_effects
            .iter()
            .filter(|c| !options.effects.contains(c));
        for &c in options.effects.iter().chain(added) {
            for &s in &set.seeds {
                let images = set.scans.images;
                jobs.push((ValidationCase::single(c, s, set), images, s));
            }
        }
    }
    for set in &options.sets {
        for &s in &set.null_seeds {
            let images = set.scans.images;
            jobs.push((ValidationCase::effect_free(s, set), images, s));
        }
    }
    for &s in &options.mixture_seeds {
        for pair in &options.mixtures {
            for set in &options.sets {
                let seed = s + set.mixture_offset;
                jobs.push((
                    ValidationCase::with_effects(pair, seed, set),
                    set.scans.images,
                    seed,
                ));
            }
        }
    }
    for set in &options.sets {
        for &s in &set.foreign_seeds {
            for effect in ForeignEffect::ALL {
                let case = ValidationCase::out_of_library(effect, s, set);
                jobs.push((case, set.scans.images, s));
            }
        }
    }
    let tuned = options.sets.iter().find(|s| s.name == "tuned");
    if options.image_path
        && let Some(set) = tuned
        && let Some(&s) = set.seeds.first()
    {
        for &c in &options.effects {
            jobs.push((ValidationCase::single(c, s, set), true, s));
        }
        jobs.push((ValidationCase::effect_free(s + 500, set), true, s + 500));
    }
    let cases: Vec<CaseResult> = jobs
        .par_iter()
        .map(|(case, images, seed)| run_case(case, *images, options, *seed))
        .collect();
    let sets = options
        .sets
        .iter()
        .map(|set| SetReport {
            set: set.name.clone(),
            evidence: set.evidence,
            judged: set.judged,
            summary: SetSummary::of(
                &cases
                    .iter()
                    .filter(|c| c.set == set.name)
                    .collect::<Vec<_>>(),
            ),
        })
        .collect();
    ValidationReport { cases, sets }
}
