//! Changes of the height alone move no feature: a tip that changes its contrast without
//! jumping is no scan distortion. The diagnosis names nothing for it and its height view
//! says when the heights changed and by how much.

use dhct_diagnose::{DiagnoseOptions, VerdictKind};
use dhct_simulate::EffectConfig;
use dhct_simulate::effects::TipChange;
use dhct_validation::{ValidationCase, ValidationSet, simulate_rendered};

#[test]
fn a_contrast_change_without_a_jump_is_reported_as_a_height_change_only() {
    let mut case = ValidationCase::effect_free(
        62001,
        &ValidationSet::named("rendered-dev").expect("a shipped set"),
    );
    let change_s = 40.0;
    case.config.effects.push(EffectConfig::TipChange(TipChange {
        time_s: change_s,
        jump_m: [0.0, 0.0],
        height_offset_m: 0.0,
        contrast: 0.7,
    }));
    let report = simulate_rendered(&case.config)
        .expect("renders")
        .diagnosed(&case.config, &DiagnoseOptions::default())
        .expect("diagnoses");
    println!("{report}");
    assert_eq!(report.verdict, VerdictKind::NoGap);
    assert!(report.added.is_empty(), "{:?}", report.added);
    let heights = report.heights.expect("a height view");
    let change = heights.change.expect("the change is found");
    assert!((change.time_s - change_s).abs() < 2.0, "{change:?}");
    assert!((change.relative + 0.3).abs() < 0.08, "{change:?}");

    // Without the contrast change, no change is reported.
    let case = ValidationCase::effect_free(
        62001,
        &ValidationSet::named("rendered-dev").expect("a shipped set"),
    );
    let report = simulate_rendered(&case.config)
        .expect("renders")
        .diagnosed(&case.config, &DiagnoseOptions::default())
        .expect("diagnoses");
    let heights = report.heights.expect("a height view");
    println!("{}", heights.describe());
    assert!(heights.change.is_none(), "{heights:?}");
}
