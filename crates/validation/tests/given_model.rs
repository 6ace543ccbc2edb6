//! `diagnose_with_model` diagnoses the correction it is given (the pipeline's), without
//! refitting it: given the model `diagnose` fits itself, the two agree exactly; given a
//! worse correction, the DHCT gap it reports is that correction's.

use dhct_diagnose::{Candidate, DiagnoseOptions, diagnose, diagnose_with_model};
use dhct_distortion::analyse;
use dhct_lattice::LatticeFitOptions;
use dhct_validation::{ValidationCase, ValidationSet, simulate_positions};

#[test]
fn the_given_correction_is_the_one_diagnosed() {
    let case = ValidationCase::single(
        Candidate::TipChange,
        2,
        &ValidationSet::named("tuned").expect("a shipped set"),
    );
    let scan = simulate_positions(&case.config, 2e-12, 5).expect("simulates");
    let lattice = case.config.surface.lattice.build().expect("lattice");
    let inputs = scan.inputs();
    let options = DiagnoseOptions::default();
    let fitted_here =
        diagnose(&inputs, &scan.geometry, lattice.as_ref(), &options).expect("diagnoses");

    // The diagnosis's own base fit (the paper's local route).
    let model = analyse(&inputs, &scan.geometry, lattice.as_ref(), &options.dhct)
        .expect("DHCT fit")
        .model;
    let lattice_fit = LatticeFitOptions::default();
    let given = diagnose_with_model(
        &inputs,
        &scan.geometry,
        lattice.as_ref(),
        &model,
        &lattice_fit,
        &options,
    )
    .expect("diagnoses the given model");
    assert_eq!(given.dhct, fitted_here.dhct, "same model, same DHCT gap");
    assert_eq!(given.top(), fitted_here.top());

    // A correction with half again the drift velocity: its own (larger) gap is reported.
    let mut worse = model.clone();
    for v in &mut worse.drift.velocity_m_per_s {
        *v *= 1.5;
    }
    worse.drift.velocity_m_per_s[0] += 2e-12;
    let given_worse = diagnose_with_model(
        &inputs,
        &scan.geometry,
        lattice.as_ref(),
        &worse,
        &lattice_fit,
        &options,
    )
    .expect("diagnoses the worse model");
    assert!(
        given_worse.dhct.gap_to_noise > 2.0 * given.dhct.gap_to_noise,
        "worse correction {} vs fitted {}",
        given_worse.dhct.gap_to_noise,
        given.dhct.gap_to_noise
    );
}
