//! Issue 37, point 3: on an effect-free scan whose base differs from dhct's (another
//! fast-scan law, a tilted sample, line offsets), an effect that is significant but leaves
//! the gap within the floor either way is listed apart (`below_floor`), never under
//! `effects` or `added`, and the verdict stays `no_gap`. The scan is the held-out set
//! `tilted-2`'s effect-free #122019, whose sub-floor line drift the strict validation count
//! takes for an alarm (docs/diagnose.md).

use dhct_diagnose::{DiagnoseOptions, VerdictKind};
use dhct_validation::{ValidationCase, ValidationSet, simulate_rendered};

#[test]
fn an_effect_within_the_floor_is_listed_apart_and_not_as_a_finding() {
    let set = ValidationSet::named("tilted-2").expect("a shipped set");
    let case = ValidationCase::effect_free(122019, &set);
    let report = simulate_rendered(&case.config)
        .expect("renders")
        .diagnosed(&case.config, &DiagnoseOptions::default())
        .expect("diagnoses");
    println!("{report}");
    assert_eq!(report.verdict, VerdictKind::NoGap);
    assert!(report.added.is_empty(), "{:?}", report.added);
    let details = &report.verdict_details;
    assert!(details.effects.is_empty(), "{:?}", details.effects);
    // The case is one where something was still significant: what this test is about.
    assert!(!report.below_floor.is_empty(), "nothing below the floor");
    let listed: Vec<_> = report.below_floor.iter().map(|a| a.candidate).collect();
    assert_eq!(details.below_floor, listed);
    assert!(
        details.summary.contains("not a finding"),
        "{}",
        details.summary
    );
}
