//! Levelling the lines of an image can leave the two passes' features a picometre or so
//! apart across the lines, the same everywhere (docs/diagnose.md, issue 37's `tilted`
//! set). No tip motion does that, so the base model takes it (its `pass-offset` term)
//! and no effect is named for it; beyond what measuring makes (two floors), the verdict
//! says the correction does not explain the scan, and what to check.

use dhct_diagnose::{DiagnoseOptions, DiagnosisReport, VerdictKind};
use dhct_validation::{ValidationCase, ValidationSet, simulate_positions};

#[test]
fn an_offset_between_the_passes_across_the_lines_is_part_of_the_base() {
    // The retrace 4 pm further along the slow axis than the trace: twice the features'
    // 2 pm localisation noise, far beyond the floor if nothing in the base took it.
    let offset_m = 4e-12;
    let report = diagnosed_with_offset(offset_m);
    let (rms, floor) = (report.base.gap.rms_m, report.noise.sigma_m);
    assert!(
        rms[1] / floor[1] < 1.1,
        "y at {:.2} floors",
        rms[1] / floor[1]
    );
    // Twice the floor is more than measuring makes: the correction's model (which has no
    // such term) does not explain the scan, though no effect is named for it.
    assert_eq!(report.verdict, VerdictKind::Unexplained);
    assert!(report.added.is_empty(), "{:?}", report.added);
    let offset = report
        .base
        .parameters
        .iter()
        .find(|p| p.name.ends_with("across_lines_m"))
        .expect("the base's pass offset");
    assert!(
        (offset.value - offset_m).abs() < 0.5e-12,
        "pass offset {:.2} pm",
        offset.value * 1e12
    );
    // Twice the floor: said, with what to check.
    let reading = report.pass_offset.as_ref().expect("a reading");
    assert!(reading.finding, "{reading:?}");
    let summary = &report.verdict_details.summary;
    assert!(summary.contains("apart across the lines"), "{summary}");
    // What levelling leaves (about a floor or less) is not.
    let small = diagnosed_with_offset(1.5e-12);
    assert_eq!(small.verdict, VerdictKind::NoGap);
    assert!(small.added.is_empty(), "{:?}", small.added);
    assert!(!small.pass_offset.expect("a reading").finding);
    assert!(!small.verdict_details.summary.contains("across the lines"));
}

/// An effect-free scan (2 pm localisation noise) whose retrace features are moved
/// `offset_m` along the slow axis, diagnosed.
fn diagnosed_with_offset(offset_m: f64) -> DiagnosisReport {
    let case =
        ValidationCase::effect_free(8102, &ValidationSet::named("tuned").expect("a shipped set"));
    let mut scan = simulate_positions(&case.config, 2e-12, 5).expect("simulates");
    let pitch_y = scan.geometry.pitch_y();
    for f in &mut scan.retrace {
        f.y_m += offset_m;
        f.y_px += offset_m / pitch_y;
    }
    scan.diagnosed(&case.config, &DiagnoseOptions::default())
        .expect("diagnoses")
}
