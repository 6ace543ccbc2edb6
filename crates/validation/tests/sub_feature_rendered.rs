//! The image view below one feature on the validation's rendered scans: a vibration the
//! feature positions average out is named from the slices; effect-free scans and slices
//! broken by step edges get no vibration.

use dhct_diagnose::{Candidate, DiagnoseOptions, DiagnosisReport};
use dhct_simulate::EffectConfig;
use dhct_validation::{ValidationCase, ValidationSet, simulate_rendered};

/// The rendered scan of `case`, its vibration (if it has one) set to `hz`: the diagnosis
/// as `dhct diagnose` makes it, positions and the view below one feature.
fn rendered_diagnosis(mut case: ValidationCase, hz: Option<f64>) -> DiagnosisReport {
    for e in &mut case.config.effects {
        if let (EffectConfig::Vibration(v), Some(hz)) = (e, hz) {
            v.frequency_hz = hz;
        }
    }
    let report = simulate_rendered(&case.config)
        .expect("renders")
        .diagnosed(&case.config, &DiagnoseOptions::default())
        .expect("diagnoses");
    assert!(report.sub_feature.is_some(), "enough slices");
    report
}

/// A 0.9 Hz vibration (3–5 pm) on the image-path development scans: a feature spans about
/// one period of it, so the positions average it out (the held-out `rendered-2` set's
/// four misses); every line's slices still move with it.
#[test]
fn a_vibration_a_feature_averages_out_is_named_from_the_slices() {
    let case = ValidationCase::single(
        Candidate::Vibration,
        61001,
        &ValidationSet::named("rendered-dev").expect("a shipped set"),
    );
    let report = rendered_diagnosis(case, Some(0.9));
    let view = report.sub_feature.as_ref().unwrap();
    println!("{}", view.describe());
    assert_eq!(
        report.verdict_details.effects.first(),
        Some(&Candidate::Vibration)
    );
    let v = view.strongest.as_ref().unwrap();
    assert!((v.frequency_hz - 0.9).abs() < 0.02 * 0.9, "{v:?}");
    // 0.11 periods per 0.12 s line: each line moves across as a whole, so the amplitude
    // across is not read.
    assert!(
        v.amplitude_across_m.is_none() && !view.across_measured,
        "{v:?}"
    );
}

/// The same scans without an effect: their slices show patterns tied to the lattice, the
/// pixels and the raster that χ²₄ alone would call significant; none is named.
#[test]
fn effect_free_rendered_scans_get_no_vibration_from_the_slices() {
    for seed in [61003, 61007] {
        let case = ValidationCase::effect_free(
            seed,
            &ValidationSet::named("rendered-dev").expect("a shipped set"),
        );
        let report = rendered_diagnosis(case, None);
        let view = report.sub_feature.as_ref().unwrap();
        println!("{seed}: {}", view.describe());
        assert!(!view.vibration_found, "{view:?}");
    }
}

/// A scan with step edges and a height coupling (rendered-3 #91003, looked at after that
/// set's one run): beside the steps the slices scatter 7 × their fit noise along the lines,
/// and a 13 Hz peak among them passed every other test. A vibration must explain why the
/// slices scatter; this one leaves them at 6 ×, so none is named.
#[test]
fn slices_broken_by_step_edges_name_no_vibration() {
    let case = ValidationCase::single(
        Candidate::HeightCoupling,
        91003,
        &ValidationSet::named("rendered-3").expect("a shipped set"),
    );
    let report = rendered_diagnosis(case, None);
    let view = report.sub_feature.as_ref().unwrap();
    println!("{}", view.describe());
    let v = view.strongest.as_ref().unwrap();
    assert!(v.scatter_left_along > 3.0, "{v:?}");
    assert!(!view.vibration_found, "{view:?}");
    assert!(view.describe().contains("something else moves them"));
}
