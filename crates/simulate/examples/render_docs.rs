//! Renders the PNGs of docs/simulator/: the Fig. 3 presets (trace and retrace) and one
//! picture per effect family.
//!
//! `cargo run --release -p dhct-simulate --example render_docs [OUT_DIR]`
//! (default OUT_DIR: docs/simulator under the workspace root).

use std::path::PathBuf;

use dhct_simulate::effects::{FastScanHysteresis, HeightCoupling, LogCreep, TipChange, Vibration};
use dhct_simulate::{
    EffectConfig, HysteresisLaw, LatticeConfig, Region, SecondDomain, Simulation, SimulationConfig,
    StepEdge, output::write_png, presets,
};

/// 256 × 256 px over 8 nm of a hexagonal lattice (a = 0.5 nm), 50 nm/s, no noise.
fn gallery_base(name: &str) -> SimulationConfig {
    let mut config = presets::fig3_no_drift();
    config.name = name.into();
    config.scan.columns = 256;
    config.scan.rows = 256;
    config.scan.width_m = 8e-9;
    config.scan.height_m = 8e-9;
    config.surface.lattice = LatticeConfig::Hexagonal { a_m: 0.5e-9 };
    config.surface.feature.sigma_m = [0.1e-9, 0.1e-9];
    config
}

/// One picture per effect family.
fn gallery() -> Vec<SimulationConfig> {
    let line = 256.0 * (8e-9 / 256.0) / 50e-9;
    let mut hysteresis = gallery_base("effect-fast-hysteresis");
    hysteresis
        .effects
        .push(EffectConfig::FastHysteresis(FastScanHysteresis {
            law: HysteresisLaw::Exponential {
                amplitude: 0.5,
                time_constant_s: 0.1 * line,
            },
        }));
    let mut creep = gallery_base("effect-creep");
    creep.effects.push(EffectConfig::Creep(LogCreep {
        coefficient_m: [0.3e-9, 1.0e-9],
        t0_s: 3.0,
        start_s: 0.0,
    }));
    let mut vibration = gallery_base("effect-vibration");
    vibration.effects.push(EffectConfig::Vibration(Vibration {
        frequency_hz: 1.5,
        amplitude_m: [40e-12, 0.0],
        phase_rad: [0.0, 0.0],
    }));
    let mut tip = gallery_base("effect-tip-change");
    tip.effects.push(EffectConfig::TipChange(TipChange {
        time_s: 0.5 * 2.0 * 256.0 * line,
        jump_m: [0.15e-9, 0.0],
        height_offset_m: 0.0,
        contrast: 0.6,
    }));
    let mut terrain = gallery_base("surface-step-domain-height-coupling");
    terrain.surface.steps.push(StepEdge {
        region: Region::HalfPlane {
            point_m: [5e-9, 0.0],
            normal: [1.0, -0.3],
        },
        height_m: 0.1e-9,
    });
    terrain.surface.second_domain = Some(SecondDomain {
        region: Region::Circle {
            centre_m: [2.5e-9, 5.5e-9],
            radius_m: 1.8e-9,
        },
        angle_rad: 15f64.to_radians(),
        origin_m: [2.5e-9, 5.5e-9],
    });
    terrain.tip.sigma_m = 30e-12;
    terrain
        .effects
        .push(EffectConfig::HeightCoupling(HeightCoupling {
            lateral_per_height: [1.0, 0.0],
        }));
    let mut noisy = gallery_base("surface-defects-noise");
    noisy.surface.defects.vacancy_fraction = 0.03;
    noisy.surface.defects.adatom_count = 6;
    noisy.noise.white_sigma_m = 3e-12;
    noisy.noise.pink_sigma_m = 3e-12;
    noisy.noise.line_offset_sigma_m = 4e-12;
    noisy.noise.spike_probability = 2e-4;
    noisy.noise.spike_height_m = 40e-12;
    vec![hysteresis, creep, vibration, tip, terrain, noisy]
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let out = std::env::args_os()
        .nth(1)
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../docs/simulator"));
    std::fs::create_dir_all(&out)?;
    let fig3 = [
        presets::fig3_no_drift(),
        presets::fig3_drift_fast(),
        presets::fig3_drift_along_slow(),
        presets::fig3_drift_against_slow(),
    ];
    for config in fig3 {
        let output = Simulation::from_config(&config)?.run()?;
        for (pass, image) in output.pair.images() {
            let path = out.join(format!("{}-{}.png", config.name, pass.name()));
            write_png(&path, image)?;
            println!("{}", path.display());
        }
    }
    for config in gallery() {
        let output = Simulation::from_config(&config)?.run()?;
        if let Some(image) = output.pair.trace() {
            let path = out.join(format!("{}.png", config.name));
            write_png(&path, image)?;
            println!("{}", path.display());
        }
    }
    Ok(())
}
