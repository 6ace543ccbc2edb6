//! The acceptance test: diagnose simulated scans with one effect withheld (8
//! identifiable simulator effects + scan coupling, which is degenerate), effect-free scans
//! and two-effect mixtures; tuned, development and held-out sets reported separately.
//!
//! The sweep uses the position-only path (true controller positions + 2 pm Gaussian
//! localisation noise); `full_image_path_identifies_effects` runs a few cases through
//! rendered images and the feature finder.

use dhct_diagnose::synth::{ValidationCase, ValidationSet, simulate_images};
use dhct_diagnose::{Candidate, DiagnoseOptions, ValidationOptions, diagnose, validate};

#[test]
fn withheld_effects_are_identified_and_the_gap_closes() {
    let report = validate(&ValidationOptions::default());
    println!("{report}");
    for c in &report.cases {
        assert!(c.error.is_none(), "{}: {:?}", c.name, c.error);
    }
    assert!(report.tuned.effect_cases >= 24 && report.held_out.effect_cases >= 24);
    assert!(report.tuned.null_cases >= 20 && report.held_out.null_cases >= 40);
    // The acceptance criteria, on the set the method was developed on.
    let s = &report.tuned;
    assert!(s.top1_rate() >= 0.9, "tuned: {s}");
    assert!(s.false_alarm_rate() <= 0.05, "tuned: {s}");
    assert_eq!(s.gap_ok, s.top1_correct, "tuned: {s}");
    // The development set (the first held-out set, looked at since; see the module docs
    // of `validate`): measured 16/16, false alarms 0/20.
    let d = &report.development;
    assert!(d.top1_rate() >= 0.9, "dev: {d}");
    assert!(d.false_alarm_rate() <= 0.05, "dev: {d}");
    // The fresh held-out set, run once with the method final. Measured: top-1 19/24
    // (79 %: exponential creep and slow-scan hysteresis taken for a second creep), false
    // alarms 0/40, gap ≤ 1.2 in 19/19 — the false-alarm and gap targets hold, the top-1
    // target does not (issue 8 stays open); these bounds guard against regressions.
    let h = &report.held_out;
    assert!(h.top1_rate() >= 0.75, "held-out: {h}");
    assert!(h.false_alarm_rate() <= 0.05, "held-out: {h}");
    assert_eq!(h.gap_ok, h.top1_correct, "held-out: {h}");
}

#[test]
fn full_image_path_identifies_effects() {
    for (candidate, seed) in [(Candidate::TipChange, 3), (Candidate::LineDrift, 4)] {
        let case = ValidationCase::single(candidate, seed, ValidationSet::Tuned);
        let scan = simulate_images(&case.config).expect("simulates");
        let lattice = case.config.surface.lattice.build().expect("lattice");
        let report = diagnose(
            &scan.inputs(),
            &scan.geometry,
            lattice.as_ref(),
            &DiagnoseOptions::default(),
        )
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
