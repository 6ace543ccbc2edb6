//! The form of the creep from frame start is chosen by the data (`base.rs`): DHCT's
//! logarithmic creep when the scan has one, an exponential relaxation when the scan's
//! creep relaxes so, and neither form's shape is then taken for an effect.

use dhct_diagnose::{Candidate, DiagnoseOptions, DiagnosisReport, VerdictKind};
use dhct_simulate::EffectConfig;
use dhct_simulate::SimulationConfig;
use dhct_simulate::effects::ExponentialCreep;
use dhct_validation::{ValidationCase, ValidationSet, base_config, simulate_positions};

/// The base scan of `seed` with its creep replaced by an exponential relaxation of
/// `amplitude_m` per axis and time constant `tau_s`, from frame start.
fn exponential_base(seed: u64, amplitude_m: [f64; 2], tau_s: f64) -> SimulationConfig {
    let mut config = base_config(seed);
    for effect in config.effects.iter_mut() {
        if matches!(effect, EffectConfig::Creep(_)) {
            *effect = EffectConfig::ExponentialCreep(ExponentialCreep {
                amplitude_m,
                time_constant_s: tau_s,
                start_s: 0.0,
            });
        }
    }
    config
}

/// The diagnosis of `config`'s positions with 2 pm of localisation noise.
fn diagnosed(config: &SimulationConfig, noise_seed: u64) -> DiagnosisReport {
    let scan = simulate_positions(config, 2e-12, noise_seed).expect("simulates");
    let report = scan
        .diagnosed(config, &DiagnoseOptions::default())
        .expect("diagnoses");
    println!("{report}");
    report
}

/// The fitted base creep's parameter `name`.
fn base_creep(report: &DiagnosisReport, name: &str) -> f64 {
    report
        .base
        .parameters
        .iter()
        .find(|p| p.name == name)
        .unwrap_or_else(|| panic!("no base creep {name}"))
        .value
}

#[test]
fn an_exponential_creep_from_frame_start_is_part_of_the_base_model() {
    // With DHCT's log creep alone as the base, 3 of these 4 scans (seeds 1–4) named an
    // "exponential creep" event starting 1–24 s into the frame.
    for seed in 1..=2u64 {
        let tau = 6.0 + 3.0 * seed as f64;
        let config = exponential_base(seed, [0.4e-9, -0.3e-9], tau);
        let report = diagnosed(&config, seed + 100);
        assert_eq!(report.base_choice.creep_form, "exponential", "seed {seed}");
        assert_eq!(report.verdict, VerdictKind::NoGap, "seed {seed}");
        assert!(report.added.is_empty(), "seed {seed}: {:?}", report.added);
        let fitted = base_creep(&report, "time_constant_s");
        assert!(
            (fitted / tau - 1.0).abs() < 0.03,
            "seed {seed}: τ {fitted} s, truth {tau} s"
        );
    }
}

#[test]
fn a_logarithmic_creep_keeps_dhcts_form() {
    for seed in 1..=2u64 {
        let report = diagnosed(&base_config(seed), seed + 100);
        assert_eq!(report.base_choice.creep_form, "log", "seed {seed}");
        let log = report
            .base_choice
            .creep
            .iter()
            .find(|c| c.law == "log")
            .unwrap();
        assert!(log.chosen && log.delta_bic == 0.0);
        let none = report
            .base_choice
            .creep
            .iter()
            .find(|c| c.law == "none")
            .unwrap();
        assert!(none.delta_bic > 100.0, "{none:?}");
        assert_eq!(report.verdict, VerdictKind::NoGap, "seed {seed}");
    }
}

#[test]
fn a_creep_event_does_not_decide_the_frame_start_creeps_form() {
    // tuned #1: a log base with a second log creep from 23 s. Before any effect the
    // exponential form fits the base better (ΔBIC −165: it takes part of the event), so
    // the selection is also run with the log form; with the effects each names, the whole
    // model with the log form is the better one (ΔBIC 109) and the event is named as what
    // it is. Choosing the form before the effects alone named an exponential creep.
    let case = ValidationCase::single(
        Candidate::SecondCreep,
        1,
        &ValidationSet::named("tuned").expect("a shipped set"),
    );
    let report = diagnosed(&case.config, 1);
    assert_eq!(report.base_choice.creep_form, "log");
    let whole = report.base_choice.creep_form_whole_model_delta_bic;
    assert!(whole.is_some_and(|d| d > 6.0), "{whole:?}");
    assert_eq!(report.top(), Some(Candidate::SecondCreep));
}

#[test]
fn creep_events_the_data_do_not_tell_apart_are_both_reported() {
    // held-out #12004: an exponential creep from 23 s, named a second creep; the two
    // reduce χ² by 1230 and 1210 (within 2 %).
    let case = ValidationCase::single(
        Candidate::ExponentialCreep,
        12004,
        &ValidationSet::named("held-out").expect("a shipped set"),
    );
    let report = diagnosed(&case.config, 12004);
    let first = &report.added[0];
    let named = [first.candidate]
        .into_iter()
        .chain(first.about_as_good.iter().copied())
        .collect::<Vec<_>>();
    assert!(named.contains(&Candidate::ExponentialCreep), "{named:?}");
    assert!(
        report
            .verdict_details
            .summary
            .contains("do not tell them apart"),
        "{}",
        report.verdict_details.summary
    );
}
