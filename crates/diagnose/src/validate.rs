//! Validation on withheld effects: simulated scans with base distortion + one effect (or
//! none, or two), diagnosed with the effect withheld from the base model; identification,
//! false alarms and shrink, tabulated per [`ValidationSet`].
//!
//! # Protocol
//! * **Tuned** (seeds 1–3, effect-free 100–119): the method was developed on these.
//! * **Development** (seeds 3001–3002, effect-free 4001–4020, other magnitudes and a
//!   higher vibration band): the first held-out set. The method missed its targets there
//!   (top-1 14/16, false alarms 2/20: slow-scan hysteresis taken for a second creep, a
//!   small "vibration" in effect-free scans), and its cases were then looked at to
//!   understand why; what changed was argued from principle, not fitted to them (time-block
//!   cross-validation cannot test a transient, so transients are cross-validated over
//!   interleaved lines; a periodogram search pays its look-elsewhere price; an effect must
//!   cut the out-of-sample error by 5 %; the slow-hysteresis time-constant grid is twice as
//!   fine). These cases are reported but are no longer evidence.
//! * **Second development** (seeds 5001–5003, effect-free 6001–6040): the second held-out
//!   set, run once (top-1 19/24: all three exponential creeps and two of three slow-scan
//!   hystereses taken for a second creep; false alarms 0/40). Looking at those cases
//!   showed numerical faults, not a weak criterion: the base creep's `t0` did not converge
//!   (a valley towards large `t0` along which the fit crawled and stopped anywhere, so the
//!   candidates were compared on a base model that was not at its optimum), a refit could
//!   start from a point worse than the base model itself, and the creep candidates' onset
//!   grid (a 24th of the frame) was coarser than their time constants. Since then `t0` is
//!   profiled, refits start from the best point along the screened step, and the best
//!   creep onset is refined. Reported, no longer evidence.
//! * **Third development** (seeds 8001–8004, effect-free 8101–8140, mixtures seed +
//!   11000): the third held-out set, run once with the method above: top-1 29/32 (91 %),
//!   false alarms 1/40, mixtures 3/3, gap/noise 1.64 → 0.87 (≤ 1.2 in 29/29), i.e. the
//!   targets held. Then the rendered-image path (a tuned case) showed a tip change taken
//!   for a second creep whose `t0` had gone below one line period, and a second creep's
//!   `t0` is now kept at one line period or more (as the base creep's and the grid's);
//!   after that change this set is development data.
//! * **Held-out** (seeds 12001–12004, effect-free 12101–12140, mixtures seed + 13000;
//!   magnitudes 0.7–0.8 or 1.2–1.35 ×, vibration 0.07–0.1 Hz, a band no other set has):
//!   fixed in this file before it was first run, and run once with the method final. Its
//!   numbers are the evidence for the acceptance targets. Measured (2026-11-22): top-1
//!   29/32 (91 %), false alarms 0/40, gap/noise 1.76 → 0.85 (≤ 1.2 in 29/29) — accepted;
//!   mixtures 1/3. The misses: two exponential creeps taken for a second creep (the two
//!   creep shapes are close: 31/32 with them as one family), and one slow-scan hysteresis
//!   with no gap to explain (0.97 × noise: a converged base creep with a short `t0` absorbs
//!   most of a slow-scan hysteresis at the frame start, as in the tuned set's two misses).
//!   The method was not changed after this run.
//! * **Foreign** (seeds 21001–21004, effect-free 22001–22040, out of library 23001–23005):
//!   issue 17's first held-out set, base fast-scan law cubic, quartic, exponential or
//!   power by seed, effects outside the library. Its one run (2026-11-25): top-1 27/32,
//!   false alarms 0/40, out of library 8/10 — top-1 missed: the four slow-scan hystereses
//!   left no gap (0.99–1.05 × floor). Looked at since, so no longer untouched.
//! * **Absorbed effects** (from 2026-11-27, every set): a single effect's *visibility* is
//!   the base model's gap on the same scan without noise ([`CaseResult::visibility`]).
//!   Measured on the sets above, slow-scan hysteresis that relaxes within the first rows of
//!   features has 0.04–0.69 (the base creep along the slow axis takes the rest: both are
//!   functions of time along the slow axis in one frame), every other effect 0.89 or more.
//!   At ≤ [`ABSORBED_VISIBILITY`] the base model alone would be `no_gap` even with the
//!   noise known exactly, so no diagnosis can demand the effect: such a case is
//!   [`CaseKind::Absorbed`], right if nothing or the truth is named, and not in top-1.
//!   This is a property of the scan, computed from the truth, never from the diagnosis.
//! * **Foreign development** (seeds 31001–31004, effect-free 32001–32020, out of library
//!   33001–33005): the second foreign set's forms — localisation noise correlated in time
//!   ([`crate::synth::PositionNoise::of_set`]) and slow-scan hysteresis over 3–10 % of the
//!   frame — tried before that set was fixed. They showed two vibrations named in
//!   effect-free scans (correlated noise raises the lowest octaves of the residual
//!   spectrum), so a vibration is now proposed only where its peak stands out of the
//!   spectrum within half an octave ([`crate::spectrum`]'s local level, as the slices'
//!   view already did). Development data.
//! * **Second foreign** (seeds 41001–41004, effect-free 42001–42040, out of library
//!   43001–43005, mixtures seed + 44000): issue 17's second held-out set, fixed in this
//!   file before it was first run and run once with the method above (2026-11-27): top-1
//!   25/27 (93 %; the two misses an exponential creep and a second creep taken for each
//!   other), 5 absorbed (four slow-scan hystereses, visibility 0.04–0.41, and one
//!   asymmetric hysteresis, 0.24; nothing or the truth named in 2 of them), false alarms
//!   0/40, out of library 10/10, gap ≤ 1.2 × floor in 25/25 — accepted. Scored with every
//!   in-library case as identifiable, top-1 would be 26/32 (81 %).
//! * **Rendered development** (seeds 61001–61002, effect-free 62001–62020, out of library
//!   63001–63003, mixtures seed + 64000): the second foreign set's base and effects
//!   rendered as images that differ from what dhct's fits assume — white, 1/f and
//!   line-offset noise, atoms with a wide halo and unequal widths
//!   ([`crate::synth::rendered_look`]) — and found by the feature finder with the default
//!   options; the floor a single effect's visibility is measured against is the floor
//!   the diagnosis found. Run while the image path was checked: development data.
//! * **Rendered** (seeds 71001–71004, effect-free 72001–72040, out of library
//!   73001–73005, mixtures seed + 74000): issue 17's held-out set on the image path, as
//!   the rendered development set with its own seeds, magnitudes 0.75–0.85 or 1.15–1.25 ×
//!   and vibration 0.3–0.45 Hz; fixed in this file ([`rendered_held_out`]) before it was
//!   first run, and run once (2026-11-27, at 57d99cd, after the timing gain and the
//!   settled lattice levelling had brought its development set to 0/20 false alarms):
//!   false alarms 0/40 (gaps 0.99–1.13), top-1 28/28, 4 absorbed (2 right), out of
//!   library 8/10 (two weak strain bubbles, 1.12 and 1.24 × floor), gap ≤ 1.2 × floor in
//!   25/28 — the last target (90 %) missed by one case: the three height couplings were
//!   named but left at 2.0–2.5 × the floor; mixtures 1/3. Not in the default sweep
//!   (`validate_set rendered` reproduces it); no longer untouched.
//! * **Second rendered** (seeds 81001–81004, effect-free 82001–82040, out of library
//!   83001–83005, mixtures seed + 84000): issue 17's second held-out set on the image
//!   path, magnitudes 0.7–0.8 or 1.2–1.3 ×, vibration 0.8–1.0 Hz; fixed in this file
//!   ([`second_rendered_held_out`]) right after the first one's run, before anything was
//!   changed for what that run showed; run once (2026-11-27 at e6772c7): false alarms 1/40,
//!   top-1 22/28 (the four 0.8–1.0 Hz vibrations unseen: the validation did not yet read
//!   the images below one feature, as `dhct diagnose` does), out of library 9/10, gap ≤ 1.2
//!   × floor in 22/22. Development data since (re-run at aa8f590: top-1 27/28).
//! * **Third rendered** (seeds 91001–91004, effect-free 92001–92040, out of library
//!   93001–93005, mixtures seed + 94000): issue 17's third held-out set on the image path,
//!   magnitudes 0.75–0.85 or 1.15–1.3 ×, vibration 1.0–1.6 Hz; fixed in this file
//!   ([`third_rendered_held_out`]) at 1251780, after the image-path cases began to read the
//!   images below one feature ([`crate::synth::simulate_rendered`]) and before its first
//!   run; run once (2026-11-27 at aa8f590): false alarms 0/40 (gaps 1.00–1.10), top-1 27/28
//!   (96 %), 4 absorbed (2 right), out of library 9/10, gap ≤ 1.2 × floor in 27/27 (worst
//!   1.14), mixtures 3/3 — every target met. One absorbed height coupling had a slice
//!   "vibration" from its step edges named first; the rule that a vibration must explain
//!   the slices' scatter was added for it after the run (0eab146; a rerun, not evidence,
//!   gives the same figures).

use std::fmt;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::synth::{
    ForeignEffect, PositionNoise, ValidationCase, ValidationSet, simulate_positions_with,
    simulate_rendered,
};
use crate::verdict::VerdictKind;
use crate::{Candidate, DiagnoseOptions};

/// The seeds of one validation set.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SetSeeds {
    /// The set (it decides the magnitudes and the vibration band drawn).
    pub set: ValidationSet,
    /// Seeds of the single-effect cases (each effect, each seed).
    pub seeds: Vec<u64>,
    /// Seeds of the effect-free cases.
    pub null_seeds: Vec<u64>,
    /// Added to every mixture seed, so that each set's mixtures are its own scans.
    pub mixture_offset: u64,
    /// Seeds of the out-of-library cases (each foreign effect, each seed).
    #[serde(default)]
    pub foreign_seeds: Vec<u64>,
}

/// Options of [`validate`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ValidationOptions {
    /// Effects simulated one at a time.
    pub effects: Vec<Candidate>,
    /// The sets, in report order (see [`ValidationSet`] and the module docs).
    pub sets: Vec<SetSeeds>,
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

/// Issue 17's held-out set on the image path ([`ValidationSet::Rendered`]), fixed here
/// before its first run and run once (2026-11-27; the module documentation has the
/// result). Not in [`ValidationOptions::default`]: `validate_set rendered` reproduces it.
pub fn rendered_held_out() -> SetSeeds {
    SetSeeds {
        set: ValidationSet::Rendered,
        seeds: vec![71001, 71002, 71003, 71004],
        null_seeds: (72001..72041).collect(),
        mixture_offset: 74000,
        foreign_seeds: (73001..73006).collect(),
    }
}

/// Issue 17's second held-out set on the image path ([`ValidationSet::SecondRendered`]),
/// fixed here (2026-11-27) after [`rendered_held_out`] was run and before any change made
/// after that run; run once (2026-11-27 at e6772c7, with the step-edge levelling): false
/// alarms 1/40, top-1 22/28 (the 0.8–1.0 Hz vibrations unseen), out of library 9/10, gap
/// ≤ 1.2 × floor in 22/22 (the README has the table). `validate_set rendered-2`
/// reproduces it.
pub fn second_rendered_held_out() -> SetSeeds {
    SetSeeds {
        set: ValidationSet::SecondRendered,
        seeds: vec![81001, 81002, 81003, 81004],
        null_seeds: (82001..82041).collect(),
        mixture_offset: 84000,
        foreign_seeds: (83001..83006).collect(),
    }
}

/// Issue 17's third held-out set on the image path ([`ValidationSet::ThirdRendered`]),
/// fixed here (2026-11-27) after [`second_rendered_held_out`] was run and the images below
/// one feature joined the image-path validation, before its first run; run once at
/// aa8f590: false alarms 0/40, top-1 27/28, out of library 9/10, gap ≤ 1.2 × floor in
/// 27/27. `validate_set rendered-3` reproduces it.
pub fn third_rendered_held_out() -> SetSeeds {
    SetSeeds {
        set: ValidationSet::ThirdRendered,
        seeds: vec![91001, 91002, 91003, 91004],
        null_seeds: (92001..92041).collect(),
        mixture_offset: 94000,
        foreign_seeds: (93001..93006).collect(),
    }
}

impl Default for ValidationOptions {
    fn default() -> Self {
        ValidationOptions {
            effects: VALIDATED_EFFECTS.to_vec(),
            sets: vec![
                SetSeeds {
                    set: ValidationSet::Tuned,
                    seeds: vec![1, 2, 3],
                    null_seeds: (100..120).collect(),
                    mixture_offset: 0,
                    foreign_seeds: Vec::new(),
                },
                SetSeeds {
                    set: ValidationSet::Development,
                    seeds: vec![3001, 3002],
                    null_seeds: (4001..4021).collect(),
                    mixture_offset: 7000,
                    foreign_seeds: Vec::new(),
                },
                SetSeeds {
                    set: ValidationSet::SecondDevelopment,
                    seeds: vec![5001, 5002, 5003],
                    null_seeds: (6001..6041).collect(),
                    mixture_offset: 9000,
                    foreign_seeds: Vec::new(),
                },
                SetSeeds {
                    set: ValidationSet::ThirdDevelopment,
                    seeds: vec![8001, 8002, 8003, 8004],
                    null_seeds: (8101..8141).collect(),
                    mixture_offset: 11000,
                    foreign_seeds: Vec::new(),
                },
                SetSeeds {
                    set: ValidationSet::HeldOut,
                    seeds: vec![12001, 12002, 12003, 12004],
                    null_seeds: (12101..12141).collect(),
                    mixture_offset: 13000,
                    foreign_seeds: Vec::new(),
                },
                // Issue 17's held-out set: fixed here before its first run.
                SetSeeds {
                    set: ValidationSet::Foreign,
                    seeds: vec![21001, 21002, 21003, 21004],
                    null_seeds: (22001..22041).collect(),
                    mixture_offset: 24000,
                    foreign_seeds: (23001..23006).collect(),
                },
                // Development cases of the second foreign set's forms.
                SetSeeds {
                    set: ValidationSet::ForeignDevelopment,
                    seeds: vec![31001, 31002, 31003, 31004],
                    null_seeds: (32001..32021).collect(),
                    mixture_offset: 34000,
                    foreign_seeds: (33001..33006).collect(),
                },
                // Issue 17's second held-out set: fixed here before its first run.
                SetSeeds {
                    set: ValidationSet::SecondForeign,
                    seeds: vec![41001, 41002, 41003, 41004],
                    null_seeds: (42001..42041).collect(),
                    mixture_offset: 44000,
                    foreign_seeds: (43001..43006).collect(),
                },
                // Development cases of the image-path set's forms.
                SetSeeds {
                    set: ValidationSet::RenderedDevelopment,
                    seeds: vec![61001, 61002],
                    null_seeds: (62001..62021).collect(),
                    mixture_offset: 64000,
                    foreign_seeds: (63001..63004).collect(),
                },
            ],
            mixtures: vec![
                [Candidate::TipChange, Candidate::Vibration],
                [Candidate::LineDrift, Candidate::SlowHysteresis],
                [Candidate::ExponentialCreep, Candidate::HeightCoupling],
            ],
            mixture_seeds: vec![11],
            image_path: false,
            noise_m: 2e-12,
            diagnose: DiagnoseOptions::default(),
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
    /// An effect outside the library: right if the verdict is `unexplained`, or
    /// `partly_explained` with the remaining gap located.
    OutOfLibrary,
    /// One effect that the base model absorbs: without any noise, the base model alone
    /// leaves a gap of at most the verdict's 1.2 × floor ([`ABSORBED_VISIBILITY`]), so
    /// no data of this noise can demand it. Right if nothing is named or the truth is.
    Absorbed,
}

/// An effect whose noise-free base residual is at most this many floors is absorbed by
/// the base model: `√(1 + v²) ≤ 1.2`, the verdict's `no_gap` bound, even with the noise
/// known exactly.
pub const ABSORBED_VISIBILITY: f64 = 0.663;

/// One validation case's outcome.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CaseResult {
    /// Name.
    pub name: String,
    /// Kind.
    pub kind: CaseKind,
    /// Withheld effects.
    pub truth: Vec<Candidate>,
    /// Its set.
    pub set: ValidationSet,
    /// `"positions"` or `"images"`.
    pub path: String,
    /// Effects outside the library in the scan.
    #[serde(default)]
    pub foreign: Vec<ForeignEffect>,
    /// Effects the diagnosis named, in order: its findings, or, with a `no_gap` verdict,
    /// the effects it still found significant below the floor (`below_floor`). Scored as
    /// before the two were kept apart in the report: a sub-floor effect on an effect-free
    /// scan is a false alarm here, and a single effect named only below the floor counts
    /// as named.
    pub identified: Vec<Candidate>,
    /// Whether [`CaseResult::identified`] are below the floor (`no_gap`).
    #[serde(default)]
    pub below_floor: bool,
    /// The diagnosis's verdict.
    pub verdict: Option<VerdictKind>,
    /// Places where the remaining gap lies, as the verdict names them.
    pub remaining: Vec<String>,
    /// Single: top = truth; degenerate: none or the truth; effect-free: none added and
    /// verdict `no_gap`; mixture: the first two added = the truth (any order); out of
    /// library: `unexplained`, or `partly_explained` with the remainder located.
    pub correct: bool,
    /// Gap/noise of the base model.
    pub gap_before: f64,
    /// Single effects: the base model's RMS residual on the same scan without noise, in
    /// units of the floor (how visible the effect is beyond what the base absorbs).
    #[serde(default)]
    pub visibility: Option<f64>,
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
    /// Of which top-1 correct when a second creep and an exponential creep count as one
    /// family (the issue lists them as one item: both model a creep event after an onset).
    pub top1_family_correct: usize,
    /// Effect-free cases.
    pub null_cases: usize,
    /// Of which with any effect added.
    pub false_alarms: usize,
    /// Mixture cases.
    pub mixture_cases: usize,
    /// Of which both effects found.
    pub mixtures_correct: usize,
    /// Out-of-library cases.
    #[serde(default)]
    pub foreign_cases: usize,
    /// Of which `unexplained`, or `partly_explained` with the remainder located.
    #[serde(default)]
    pub foreign_correct: usize,
    /// Single-effect cases the base model absorbs ([`CaseKind::Absorbed`]): not in top-1.
    #[serde(default)]
    pub absorbed_cases: usize,
    /// Of which nothing or the truth named.
    #[serde(default)]
    pub absorbed_correct: usize,
    /// Correct single cases with gap/noise after ≤ 1.2.
    pub gap_ok: usize,
    /// Largest gap/noise after the identified effect, over correct single cases.
    pub worst_gap_after: f64,
    /// Mean gap/noise before, over single cases.
    pub mean_gap_before: f64,
    /// Mean gap/noise after, over correct single cases.
    pub mean_gap_after: f64,
}

/// `candidate`, with a second creep counted as an exponential creep.
fn creep_family(candidate: Candidate) -> Candidate {
    match candidate {
        Candidate::SecondCreep => Candidate::ExponentialCreep,
        other => other,
    }
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
        let foreign: Vec<&&CaseResult> = cases
            .iter()
            .filter(|c| c.kind == CaseKind::OutOfLibrary)
            .collect();
        let absorbed: Vec<&&CaseResult> = cases
            .iter()
            .filter(|c| c.kind == CaseKind::Absorbed)
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
            top1_family_correct: single
                .iter()
                .filter(|c| {
                    c.error.is_none()
                        && c.identified.first().map(|&i| creep_family(i))
                            == c.truth.first().map(|&t| creep_family(t))
                })
                .count(),
            null_cases: null.len(),
            false_alarms: null.iter().filter(|c| !c.correct).count(),
            mixture_cases: mix.len(),
            mixtures_correct: mix.iter().filter(|c| c.correct).count(),
            foreign_cases: foreign.len(),
            foreign_correct: foreign.iter().filter(|c| c.correct).count(),
            absorbed_cases: absorbed.len(),
            absorbed_correct: absorbed.iter().filter(|c| c.correct).count(),
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

    /// Share of out-of-library cases answered `unexplained` (or `partly_explained`,
    /// located); 1 when there are none.
    pub fn foreign_rate(&self) -> f64 {
        if self.foreign_cases == 0 {
            1.0
        } else {
            self.foreign_correct as f64 / self.foreign_cases as f64
        }
    }

    /// Whether the acceptance criteria hold: top-1 ≥ 90 %, false alarms ≤ 5 %
    /// (≤ 2.5 %, 1 in 40, with 40 or more effect-free cases), gap ≤ 1.2 × floor in ≥ 90 %
    /// of correct single cases, ≥ 80 % of out-of-library cases unexplained.
    pub fn accepted(&self) -> bool {
        let alarms = if self.null_cases >= 40 {
            self.false_alarms * 40 <= self.null_cases
        } else {
            self.false_alarm_rate() <= 0.05
        };
        self.top1_rate() >= 0.9
            && alarms
            && self.gap_ok as f64 >= 0.9 * self.top1_correct as f64
            && self.foreign_rate() >= 0.8
    }
}

/// The summary of one set.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SetReport {
    /// The set.
    pub set: ValidationSet,
    /// Its summary.
    pub summary: SetSummary,
}

/// Everything [`validate`] measured.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ValidationReport {
    /// Every case.
    pub cases: Vec<CaseResult>,
    /// Per set, in the options' order.
    pub sets: Vec<SetReport>,
}

impl ValidationReport {
    /// The summary of `set`, if it was run.
    pub fn summary(&self, set: ValidationSet) -> Option<&SetSummary> {
        self.sets.iter().find(|s| s.set == set).map(|s| &s.summary)
    }

    /// The summary of the cases of `sets` taken together (small subsets of several sets
    /// are judged pooled: one miss in a set of seven is not a rate).
    pub fn pooled(&self, sets: &[ValidationSet]) -> SetSummary {
        let cases: Vec<&CaseResult> = self
            .cases
            .iter()
            .filter(|c| sets.contains(&c.set))
            .collect();
        SetSummary::of(&cases)
    }

    /// Whether the acceptance criteria hold on the tuned set and on every evidence set run.
    pub fn accepted(&self) -> bool {
        self.sets
            .iter()
            .filter(|s| s.set == ValidationSet::Tuned || s.set.is_evidence())
            .all(|s| s.summary.accepted())
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
        let noise = PositionNoise::of_set(case.set, options.noise_m);
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
        set: case.set,
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
        for &c in &options.effects {
            for &s in &set.seeds {
                let images = set.set.renders_images();
                jobs.push((ValidationCase::single(c, s, set.set), images, s));
            }
        }
    }
    for set in &options.sets {
        for &s in &set.null_seeds {
            let images = set.set.renders_images();
            jobs.push((ValidationCase::effect_free(s, set.set), images, s));
        }
    }
    for &s in &options.mixture_seeds {
        for pair in &options.mixtures {
            for set in &options.sets {
                let seed = s + set.mixture_offset;
                jobs.push((
                    ValidationCase::with_effects(pair, seed, set.set),
                    set.set.renders_images(),
                    seed,
                ));
            }
        }
    }
    for set in &options.sets {
        for &s in &set.foreign_seeds {
            for effect in ForeignEffect::ALL {
                let case = ValidationCase::out_of_library(effect, s, set.set);
                jobs.push((case, set.set.renders_images(), s));
            }
        }
    }
    let first_tuned = options
        .sets
        .iter()
        .find(|s| s.set == ValidationSet::Tuned)
        .and_then(|s| s.seeds.first());
    if options.image_path
        && let Some(&s) = first_tuned
    {
        for &c in &options.effects {
            jobs.push((ValidationCase::single(c, s, ValidationSet::Tuned), true, s));
        }
        jobs.push((
            ValidationCase::effect_free(s + 500, ValidationSet::Tuned),
            true,
            s + 500,
        ));
    }
    let cases: Vec<CaseResult> = jobs
        .par_iter()
        .map(|(case, images, seed)| run_case(case, *images, options, *seed))
        .collect();
    let sets = options
        .sets
        .iter()
        .map(|set| SetReport {
            set: set.set,
            summary: SetSummary::of(
                &cases
                    .iter()
                    .filter(|c| c.set == set.set)
                    .collect::<Vec<_>>(),
            ),
        })
        .collect();
    ValidationReport { cases, sets }
}

fn label(c: Option<&Candidate>) -> &'static str {
    c.map_or("none", |c| c.name())
}

fn truth_label(c: &CaseResult) -> &'static str {
    c.foreign
        .first()
        .map_or_else(|| label(c.truth.first()), |f| f.name())
}

impl ValidationReport {
    /// Confusion matrix (rows: withheld effect of single/degenerate/effect-free cases;
    /// columns: top identified) of one set, as text.
    pub fn confusion_matrix(&self, set: ValidationSet) -> String {
        let cases: Vec<&CaseResult> = self
            .cases
            .iter()
            .filter(|c| c.set == set && c.kind != CaseKind::Mixture)
            .collect();
        let mut names: Vec<&'static str> = Vec::new();
        for c in &cases {
            for n in [truth_label(c), label(c.identified.first())] {
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
            let members: Vec<&&CaseResult> =
                cases.iter().filter(|c| truth_label(c) == *row).collect();
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
            "top-1 {}/{} ({:.0} %; creeps as one family {}/{}), false alarms {}/{} ({:.0} %), mixtures {}/{}, out of library unexplained {}/{}, absorbed by the base {} (none or the truth named {}), gap/noise before {:.2} → after {:.2} (worst {:.2}; ≤ 1.2 in {}/{}) — {}",
            self.top1_correct,
            self.effect_cases,
            100.0 * self.top1_rate(),
            self.top1_family_correct,
            self.effect_cases,
            self.false_alarms,
            self.null_cases,
            100.0 * self.false_alarm_rate(),
            self.mixtures_correct,
            self.mixture_cases,
            self.foreign_correct,
            self.foreign_cases,
            self.absorbed_cases,
            self.absorbed_correct,
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
            "{:<44} {:<11} {:<6} {:<34} {:>6} {:>6} {:>6} {:>7} {:<17} ok",
            "case", "set", "path", "identified", "before", "top", "after", "visible", "verdict"
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
                "{:<44} {:<11} {:<6} {:<34} {:>6.2} {:>6} {:>6.2} {:>7} {:<17} {}",
                c.name,
                c.set.name(),
                c.path,
                ids,
                c.gap_before,
                c.gap_after_top.map_or("—".into(), |v| format!("{v:.2}")),
                c.gap_after,
                c.visibility.map_or("—".into(), |v| format!("{v:.2}")),
                c.verdict.map_or("—", |v| v.name()),
                if c.correct { "yes" } else { "NO" }
            )?;
        }
        for set in &self.sets {
            writeln!(
                f,
                "\nconfusion matrix, {} set:\n{}",
                set.set.name(),
                self.confusion_matrix(set.set)
            )?;
        }
        for set in &self.sets {
            let note = match set.set {
                ValidationSet::Tuned => "",
                s if s.is_evidence() => " (evidence)",
                _ => " (development data, not evidence)",
            };
            writeln!(
                f,
                "{:<9} {}{note}",
                format!("{}:", set.set.name()),
                set.summary
            )?;
        }
        Ok(())
    }
}
