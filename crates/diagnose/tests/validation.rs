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
    let set = |s: ValidationSet| *report.summary(s).expect("every set is run");
    let (tuned, held_out) = (set(ValidationSet::Tuned), set(ValidationSet::HeldOut));
    assert!(tuned.effect_cases >= 24 && held_out.effect_cases >= 32);
    assert!(tuned.null_cases >= 20 && held_out.null_cases >= 40);
    // The acceptance criteria, on the set the method was developed on and on the
    // fresh held-out set (see the module docs of `validate` for the protocol). Measured:
    // tuned top-1 22/24, false alarms 0/20; held-out 29/32, 0/40, gap ≤ 1.2 in 29/29.
    assert!(tuned.accepted(), "tuned: {tuned}");
    assert!(held_out.accepted(), "held-out: {held_out}");
    // The development sets (earlier held-out sets, looked at since): regression guards.
    for dev in [
        ValidationSet::Development,
        ValidationSet::SecondDevelopment,
        ValidationSet::ThirdDevelopment,
    ] {
        let d = set(dev);
        assert!(d.top1_rate() >= 0.9, "{}: {d}", dev.name());
        assert!(d.false_alarm_rate() <= 0.05, "{}: {d}", dev.name());
    }
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
