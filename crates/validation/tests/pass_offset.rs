//! Levelling the lines of an image can leave the two passes' features a picometre or so
//! apart across the lines, the same everywhere (docs/diagnose.md, issue 37's `tilted`
//! set). No tip motion does that, so the base model takes it (its `pass-offset` term)
//! and no effect is named for it.

use dhct_diagnose::{DiagnoseOptions, VerdictKind};
use dhct_validation::{ValidationCase, ValidationSet, simulate_positions};

#[test]
fn an_offset_between_the_passes_across_the_lines_is_part_of_the_base() {
    let case =
        ValidationCase::effect_free(8102, &ValidationSet::named("tuned").expect("a shipped set"));
    let mut scan = simulate_positions(&case.config, 2e-12, 5).expect("simulates");
    // The retrace 4 pm further along the slow axis than the trace: twice the features'
    // 2 pm localisation noise, far beyond the floor if nothing in the base took it.
    let offset_m = 4e-12;
    let pitch_y = scan.geometry.pitch_y();
    for f in &mut scan.retrace {
        f.y_m += offset_m;
        f.y_px += offset_m / pitch_y;
    }
    let report = scan
        .diagnosed(&case.config, &DiagnoseOptions::default())
        .expect("diagnoses");
    let (rms, floor) = (report.base.gap.rms_m, report.noise.sigma_m);
    assert!(
        rms[1] / floor[1] < 1.1,
        "y at {:.2} floors",
        rms[1] / floor[1]
    );
    assert_eq!(report.verdict, VerdictKind::NoGap);
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
}
