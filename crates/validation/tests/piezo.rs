//! A piezo non-linearity (the scanner's displacement not proportional to its drive) is the
//! same in trace and retrace at the same commanded position. Within one pair of images its
//! fast-axis curve is what can be fitted: the quadratic part always, the cubic part where
//! the base's hysteresis law is rigid (power, exponential; a polynomial law takes it whole).
//! A polynomial law also wins the base's comparison by taking that odd part, so the rigid
//! laws are tried again with effects, as whole models: with the right law the piezo
//! non-linearity is named, not an asymmetric hysteresis (two polynomial laws can mimic it).

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
                EffectConfig::PiezoNonlinearity(p) => Some([p.quadratic_m[0], p.cubic_m[0]]),
                _ => None,
            })
            .expect("the case holds a piezo non-linearity");
        let report = simulate_positions(&case.config, 2e-12, seed)
            .expect("simulates")
            .diagnosed(&case.config, &DiagnoseOptions::default())
            .expect("diagnoses");
        println!("{report}");
        let first = report.added.first().expect("an effect is named");
        if first.candidate != Candidate::PiezoNonlinearity {
            // Reported as not told apart, never silently another effect.
            assert!(
                first.about_as_good.contains(&Candidate::PiezoNonlinearity)
                    && report
                        .verdict_details
                        .summary
                        .contains("do not tell them apart"),
                "seed {seed}: {:?} {:?}",
                first.candidate,
                first.about_as_good
            );
            continue;
        }
        named_first += 1;
        let near = |index: usize, name: &str, truth: f64| {
            let fitted = &first.parameters[index];
            assert_eq!(fitted.name, name);
            let error = (fitted.value - truth).abs();
            assert!(
                error < 0.15 * truth.abs() + 3.0 * fitted.sigma.unwrap(),
                "seed {seed}: {name} {} ± {:?}, truth {truth}",
                fitted.value,
                fitted.sigma
            );
        };
        near(0, "quadratic_x_m", truth[0]);
        // q_y is drift; c_x is fitted where the chosen law is rigid.
        let rigid = matches!(
            report.base_choice.hysteresis_law.as_str(),
            "power" | "exponential"
        );
        assert_eq!(first.parameters[2].name, "cubic_x_m");
        assert_eq!(first.parameters[2].sigma.is_some(), rigid, "seed {seed}");
        if rigid {
            near(2, "cubic_x_m", truth[1]);
        }
    }
    // Measured: named first on every seed (before the rigid laws were tried again with
    // effects, only on seed 1: an asymmetric hysteresis of two quartic laws came first).
    assert!(named_first >= 3, "named first on {named_first} of 4 seeds");
}
