//! The output depends only on the config: bit-identical across runs and thread counts.

mod common;

use common::{base_config, run};
use dhct_scan::ScanDirection;
use dhct_simulate::effects::{FastScanHysteresis, ThermalDrift, Vibration};
use dhct_simulate::{EffectConfig, HysteresisLaw, Simulation, SimulationConfig, SimulationOutput};

/// A non-square scan with a vertical fast axis, every kind of noise and random defects.
fn busy_config() -> SimulationConfig {
    let mut config = base_config();
    config.scan.columns = 96;
    config.scan.rows = 80;
    config.scan.width_m = 96.0 * common::PITCH;
    config.scan.height_m = 80.0 * common::PITCH;
    config.scan.trace_fast = ScanDirection::Up;
    config.scan.slow = ScanDirection::Left;
    config.scan.turnaround_s = 0.01;
    config.noise.white_sigma_m = 3e-12;
    config.noise.pink_sigma_m = 2e-12;
    config.noise.line_offset_sigma_m = 4e-12;
    config.noise.spike_probability = 0.002;
    config.noise.spike_height_m = 40e-12;
    config.surface.defects.vacancy_fraction = 0.1;
    config.surface.defects.adatom_count = 7;
    config.effects = vec![
        EffectConfig::ThermalDrift(ThermalDrift {
            velocity_m_per_s: [7e-12, -3e-12],
            acceleration_m_per_s2: [0.0, 1e-13],
        }),
        EffectConfig::FastHysteresis(FastScanHysteresis {
            law: HysteresisLaw::Power { k: 0.92, n: -0.04 },
        }),
        EffectConfig::Vibration(Vibration {
            frequency_hz: 3.0,
            amplitude_m: [5e-12, 5e-12],
            phase_rad: [0.0, 1.0],
        }),
    ];
    config
}

fn run_with_threads(config: &SimulationConfig, threads: usize) -> SimulationOutput {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    let simulation = Simulation::from_config(config).unwrap();
    pool.install(|| simulation.run().unwrap())
}

fn bits(output: &SimulationOutput) -> Vec<u64> {
    output
        .pair
        .images()
        .flat_map(|(_, image)| image.z.iter().map(|v| v.to_bits()).collect::<Vec<_>>())
        .collect()
}

#[test]
fn output_is_bit_identical_for_any_number_of_threads() {
    let config = busy_config();
    let one = run_with_threads(&config, 1);
    let three = run_with_threads(&config, 3);
    assert_eq!(bits(&one), bits(&three));
    assert_eq!(one.truth, three.truth);
    assert_eq!(one, run(&config), "and across runs");
}

#[test]
fn a_different_seed_gives_different_noise_and_defects() {
    let config = busy_config();
    let mut other = config.clone();
    other.seed += 1;
    let (a, b) = (run(&config), run(&other));
    assert_ne!(bits(&a), bits(&b));
    assert_ne!(a.truth.features.len(), 0);
    assert_ne!(
        a.truth
            .features
            .iter()
            .map(|f| f.sample_position_m)
            .collect::<Vec<_>>(),
        b.truth
            .features
            .iter()
            .map(|f| f.sample_position_m)
            .collect::<Vec<_>>()
    );
}
