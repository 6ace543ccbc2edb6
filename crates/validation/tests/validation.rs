//! The issue's acceptance test: diagnose simulated scans with one effect withheld (8
//! identifiable simulator effects + scan coupling, which is degenerate), effect-free scans
//! and two-effect mixtures; tuned, development and held-out sets reported separately.
//!
//! The sweep uses the position-only path (true controller positions + 2 pm Gaussian
//! localisation noise); `full_image_path_identifies_effects` runs a few cases through
//! rendered images and the feature finder.
//!
//! The full sweep takes ~25 minutes on 2 cores and is not part of the default `cargo test`
//! nor of CI; it is the documented validation benchmark:
//!
//! ```text
//! cargo test --release -p dhct-validation --test validation -- --ignored withheld --nocapture
//! ```
//!
//! The default suite (and so CI) runs `held_out_sample_meets_the_acceptance_criteria`: the
//! three position-path held-out sets at their first seeds, judged pooled.

use dhct_diagnose::{Candidate, DiagnoseOptions};
use dhct_validation::{
    Catalogue, SetSummary, ValidationCase, ValidationOptions, ValidationSet, simulate_images,
    validate,
};

/// Every set's scans are its own: no seed of any kind (single effects, effect-free,
/// out of library, mixtures) is shared between two sets, the held-out image-path sets
/// included, so a held-out set never holds a scan another set was looked at on.
#[test]
fn no_two_sets_share_a_scan() {
    let options = ValidationOptions::default();
    let sets = Catalogue::shipped().sets;
    let mixture_seeds = |s: &ValidationSet| -> Vec<u64> {
        let seeds = options.mixture_seeds.iter();
        seeds.map(|seed| seed + s.mixture_offset).collect()
    };
    for (i, a) in sets.iter().enumerate() {
        for b in &sets[i + 1..] {
            let kinds = |s: &ValidationSet| {
                [
                    s.seeds.clone(),
                    s.null_seeds.clone(),
                    s.foreign_seeds.clone(),
                    mixture_seeds(s),
                ]
            };
            for (ka, kb) in kinds(a).iter().zip(kinds(b).iter()) {
                let shared: Vec<&u64> = ka.iter().filter(|x| kb.contains(x)).collect();
                assert!(
                    shared.is_empty(),
                    "{} and {} share seeds {shared:?}",
                    a.name,
                    b.name
                );
            }
        }
    }
}

#[test]
#[ignore = "minutes: run in release mode (see the module docs)"]
fn withheld_effects_are_identified_and_the_gap_closes() {
    let report = validate(&ValidationOptions::default());
    println!("{report}");
    for c in &report.cases {
        assert!(c.error.is_none(), "{}: {:?}", c.name, c.error);
    }
    let set = |s: &str| *report.summary(s).expect("every set is run");
    let in_library = |s: &SetSummary| s.effect_cases + s.absorbed_cases;
    let (tuned, held_out) = (set("tuned"), set("held-out"));
    assert!(in_library(&tuned) >= 24 && in_library(&held_out) >= 32);
    assert!(tuned.null_cases >= 20 && held_out.null_cases >= 40);
    // The issue's acceptance criteria, on the set the method was developed on and on the
    // held-out sets (see the module docs of `validate` for the protocol). Effects the base
    // model absorbs (noise-free gap ≤ 0.663 floor: `CaseKind::Absorbed`) are scored apart.
    // Measured 2026-11-27: tuned top-1 21/21, false alarms 0/20; held-out 27/29, 0/40.
    assert!(tuned.accepted(), "tuned: {tuned}");
    assert!(held_out.accepted(), "held-out: {held_out}");
    // Issue 17's first held-out set (other fast-scan laws, out-of-library effects). Its one
    // run (2026-11-25) missed top-1 (27/32 with every case scored as identifiable); scored
    // with absorbed cases apart and re-run with the later method (no longer untouched):
    // top-1 27/28, false alarms 0/40, out of library 9/10.
    let foreign = set("foreign");
    assert!(foreign.null_cases >= 40 && foreign.foreign_cases >= 10);
    assert!(foreign.accepted(), "foreign: {foreign}");
    // Issue 17's second held-out set (other fast-scan laws, localisation noise correlated
    // in time, slow-scan hysteresis over 3–10 % of the frame), fixed before its first run.
    // Measured at that run (2026-11-27): top-1 25/27 (93 %), 5 absorbed, false alarms 0/40,
    // out of library 10/10, gap ≤ 1.2 × floor in 25/25.
    let second = set("foreign-2");
    assert!(in_library(&second) >= 32 && second.null_cases >= 40 && second.foreign_cases >= 10);
    assert!(second.accepted(), "foreign-2: {second}");
    // The development sets (earlier held-out sets, looked at since): regression guards.
    for dev in ["dev", "dev-2", "dev-3", "foreign-dev"] {
        let d = set(dev);
        assert!(d.top1_rate() >= 0.9, "{dev}: {d}");
        assert!(d.false_alarm_rate() <= 0.05, "{dev}: {d}");
    }
    // The image path's development set (rendered images with white, 1/f and line-offset
    // noise and halo atoms, found by the feature finder): a regression guard at what it
    // measured (2026-11-27: top-1 13/15, false alarms 3/20, out of library 6/6), not the
    // acceptance targets, which it misses on false alarms.
    let rendered = set("rendered-dev");
    assert!(rendered.null_cases >= 20 && rendered.foreign_cases >= 6);
    assert!(rendered.top1_rate() >= 0.8, "rendered-dev: {rendered}");
    assert!(
        rendered.false_alarm_rate() <= 0.2,
        "rendered-dev: {rendered}"
    );
    assert!(rendered.foreign_rate() >= 0.65, "rendered-dev: {rendered}");
}

/// The default suite's (and so CI's) share of the sweep: the three position-path held-out
/// sets (`held-out`, `foreign`, `foreign-2`) at their first seed of every effect, 8
/// effect-free scans and the first two seeds of the out-of-library effects each (the same
/// scans as the full sweep's; no mixtures, which the criteria do not score), judged pooled
/// by the issue's acceptance criteria (a handful of cases per set is no rate). What it checks can fail: a
/// missed effect, a false alarm, a foreign effect called explained, a gap left open.
#[test]
fn held_out_sample_meets_the_acceptance_criteria() {
    let held_out = ["held-out", "foreign", "foreign-2"];
    let mut options = ValidationOptions::default();
    options.sets.retain(|s| held_out.contains(&s.name.as_str()));
    for set in &mut options.sets {
        set.seeds.truncate(1);
        set.null_seeds.truncate(8);
        set.foreign_seeds.truncate(2);
    }
    options.mixtures.clear();
    let report = validate(&options);
    println!("{report}");
    for c in &report.cases {
        assert!(c.error.is_none(), "{}: {:?}", c.name, c.error);
        assert!(
            c.noise_floor_m.iter().all(|s| s.is_finite() && *s > 0.0),
            "{}: floor {:?}",
            c.name,
            c.noise_floor_m
        );
    }
    let pooled = report.pooled(&held_out);
    println!("pooled: {pooled}");
    assert!(pooled.null_cases == 24 && pooled.effect_cases >= 20 && pooled.foreign_cases >= 8);
    assert!(pooled.accepted(), "pooled held-out sample: {pooled}");
}

#[test]
fn full_image_path_identifies_effects() {
    for (candidate, seed) in [(Candidate::TipChange, 3), (Candidate::LineDrift, 4)] {
        let case = ValidationCase::single(
            candidate,
            seed,
            &ValidationSet::named("tuned").expect("a shipped set"),
        );
        let scan = simulate_images(&case.config).expect("simulates");
        let report = scan
            .diagnosed(&case.config, &DiagnoseOptions::default())
            .expect("diagnoses");
        println!("{}:\n{report}", case.name);
        assert_eq!(report.top(), Some(candidate));
        // On rendered images the gap closes by at least half but not to the 1.2 × floor of
        // the position-only sweep (measured: tip change 3.89 → 1.44): feature-finding
        // systematics are not in the trace/retrace noise floor.
        assert!(
            report.shrink.after_greedy <= 0.5 * report.shrink.before,
            "{:?}",
            report.shrink
        );
    }
}
