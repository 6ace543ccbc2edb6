//! A piezo non-linearity (the scanner's displacement not proportional to its drive) is the
//! same in trace and retrace at the same commanded position. Within one pair of images its
//! quadratic part along the fast axis is what can be fitted, and an asymmetric fast-scan
//! hysteresis explains that part about as well: the diagnosis names one of the two and
//! reports the other as not told apart.

use dhct_diagnose::{Candidate, DiagnoseOptions};
use dhct_simulate::EffectConfig;
use dhct_validation::{ValidationCase, ValidationSet, simulate_positions};

#[test]
fn a_piezo_nonlinearity_is_named_or_reported_as_not_told_apart() {
    let mut named_first = 0;
    for seed in 1..=4u64 {
        let case = ValidationCase::single(
            Candidate::PiezoNonlinearity,
            seed,
            &ValidationSet::named("tuned").expect("a shipped set"),
        );
        let truth = case
            .config
            .effects
            .iter()
            .find_map(|e| match e {
                EffectConfig::PiezoNonlinearity(p) => Some(p.quadratic_m[0]),
                _ => None,
            })
            .expect("the case holds a piezo non-linearity");
        let report = simulate_positions(&case.config, 2e-12, seed)
            .expect("simulates")
            .diagnosed(&case.config, &DiagnoseOptions::default())
            .expect("diagnoses");
        println!("{report}");
        let first = report.added.first().expect("an effect is named");
        assert!(
            first.candidate == Candidate::PiezoNonlinearity
                || first.about_as_good.contains(&Candidate::PiezoNonlinearity),
            "seed {seed}: {:?} {:?}",
            first.candidate,
            first.about_as_good
        );
        if first.candidate == Candidate::PiezoNonlinearity {
            named_first += 1;
            let fitted = &first.parameters[0];
            assert_eq!(fitted.name, "quadratic_x_m");
            // Only q_x is free: the rest of the curve is the base model's.
            assert!(first.parameters[1..].iter().all(|p| p.sigma.is_none()));
            let error = (fitted.value - truth).abs();
            assert!(
                error < 0.15 * truth.abs() + 3.0 * fitted.sigma.unwrap(),
                "seed {seed}: q_x {} ± {:?}, truth {truth}",
                fitted.value,
                fitted.sigma
            );
        } else {
            assert!(
                report
                    .verdict_details
                    .summary
                    .contains("do not tell them apart")
            );
        }
    }
    // Measured: named first on seed 1, asymmetric hysteresis first on seeds 2–4.
    assert!(named_first >= 1);
}
