//! The quick robustness sweep (256² images): no panic on any input, a clear error for
//! inputs without a lattice, and the baseline at the noise floor. Prints the degradation
//! table (`cargo test -p dhct-bench --test robustness -- --nocapture`).

use dhct_bench::robustness::{Expect, Outcome, SweepSize, cases, run_case, table};

#[test]
fn sweep_never_panics_and_fails_clearly_without_a_lattice() {
    let cases = cases(SweepSize::Quick);
    assert!(cases.len() >= 20, "the sweep covers every axis");
    let rows: Vec<_> = cases.iter().map(run_case).collect();
    println!("{}", table(&rows));

    let panics: Vec<_> = rows
        .iter()
        .filter_map(|r| match &r.outcome {
            Outcome::Panic(m) => Some(format!("{} / {}: {m}", r.axis, r.level)),
            _ => None,
        })
        .collect();
    assert!(panics.is_empty(), "panics: {panics:#?}");

    let unexpected: Vec<_> = rows
        .iter()
        .filter(|r| !r.as_expected())
        .map(|r| {
            format!(
                "{} / {}: expected {:?}, got {:?}",
                r.axis, r.level, r.expect, r.outcome
            )
        })
        .collect();
    assert!(unexpected.is_empty(), "not as expected: {unexpected:#?}");

    // Every input without a lattice was among the cases and ended in an error.
    let without = rows.iter().filter(|r| r.expect == Expect::Error).count();
    assert!(without >= 3);

    // The baseline is analysed at the localisation noise floor.
    let Outcome::Analysis(Some(baseline)) = &rows[0].outcome else {
        panic!("the baseline must be analysed: {:?}", rows[0].outcome);
    };
    assert!(baseline.recall > 0.95, "recall {}", baseline.recall);
    assert!(
        baseline.indexed_fraction > 0.95,
        "indexed {}",
        baseline.indexed_fraction
    );
    assert!(
        baseline.corrected_over_floor < 1.5,
        "corrected rms {} pm is {} x the floor",
        baseline.corrected_rms_m * 1e12,
        baseline.corrected_over_floor
    );
    assert!(
        baseline
            .lattice_constant_error
            .iter()
            .all(|e| e.abs() < 2e-3)
    );
}
