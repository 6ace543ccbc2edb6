//! Repeated effects: a scan with two tip jumps is explained by two tip changes, each with
//! its own time and jump (issue 17: "several tip jumps"); with one jump only one is added.

use dhct_diagnose::{Candidate, DiagnoseOptions, DiagnosisReport, VerdictKind};
use dhct_simulate::{EffectConfig, SimulationConfig};
use dhct_validation::{ValidationCase, ValidationSet, simulate_positions};

fn diagnosed(config: &SimulationConfig) -> DiagnosisReport {
    let scan = simulate_positions(config, 2e-12, 11).expect("simulates");
    scan.diagnosed(config, &DiagnoseOptions::default())
        .expect("diagnoses")
}

fn tip_changes(report: &DiagnosisReport) -> usize {
    report
        .added
        .iter()
        .filter(|a| a.candidate == Candidate::TipChange)
        .count()
}

#[test]
fn two_tip_jumps_are_two_tip_changes() {
    let case = ValidationCase::single(
        Candidate::TipChange,
        4,
        &ValidationSet::named("tuned").expect("a shipped set"),
    );
    let mut config = case.config.clone();
    let frame = config.scan.geometry().expect("geometry").frame_duration();
    let mut jumps = config
        .effects
        .iter()
        .filter(|e| matches!(e, EffectConfig::TipChange(_)))
        .count();
    assert_eq!(jumps, 1, "the single case has one jump");
    for effect in &mut config.effects {
        if let EffectConfig::TipChange(tip) = effect {
            tip.time_s = 0.3 * frame;
            tip.jump_m = [30e-12, -20e-12];
        }
    }
    let one = diagnosed(&config);
    println!("one jump:\n{one}");
    assert_eq!(tip_changes(&one), 1);

    let second = config
        .effects
        .iter()
        .find_map(|e| match e {
            EffectConfig::TipChange(tip) => {
                Some(EffectConfig::TipChange(dhct_simulate::effects::TipChange {
                    time_s: 0.7 * frame,
                    jump_m: [-25e-12, -30e-12],
                    ..tip.clone()
                }))
            }
            _ => None,
        })
        .expect("a tip change");
    config.effects.push(second);
    jumps += 1;
    let two = diagnosed(&config);
    println!("two jumps:\n{two}");
    assert_eq!(tip_changes(&two), jumps, "{:?}", two.added);
    assert_eq!(two.verdict, VerdictKind::Explained);
    assert!(two.shrink.after_greedy <= 1.2, "{:?}", two.shrink);
    // Each fitted jump time lies near one of the true ones (within 3 % of the frame).
    let times: Vec<f64> = two
        .added
        .iter()
        .filter(|a| a.candidate == Candidate::TipChange)
        .filter_map(|a| a.parameters.iter().find(|p| p.name.contains("time")))
        .map(|p| p.value / frame)
        .collect();
    assert_eq!(times.len(), 2, "{:?}", two.added);
    for truth in [0.3, 0.7] {
        assert!(
            times.iter().any(|t| (t - truth).abs() < 0.03),
            "no fitted jump near {truth} of the frame: {times:?}"
        );
    }
}
