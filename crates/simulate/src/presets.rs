//! Ready-made simulations. Each is also shipped as a TOML file under
//! `crates/simulate/presets/` with identical content (tested), so a user can copy and edit it.
//!
//! * `fig3-*`: the DHCT paper's Fig. 3 situation — a hexagonal lattice with 1 nm spacing,
//!   512 × 512 px over 20 nm, 50 nm/s fast scan, no noise — without drift and with 10 pm/s
//!   of drift along the fast axis, along the slow scan and against it. (The paper's exact
//!   panel list is not available here; these are the cases its text discusses.) The slow
//!   speed is 50 nm/s / 1024 = 48.8 pm/s, so 10 pm/s changes the slow scale by 20.5 %.
//! * `headline-2048`: the paper's Fig. 4 headline acquisition — graphite (a = 2.46 Å),
//!   2048 × 2048 px over 25 nm, 100 nm/s, trace and retrace — with drift, acceleration,
//!   creep, power-law hysteresis and noise of typical room-temperature magnitude.
//! * `ci-small`: the same physics on 256 × 256 px over 4 nm of graphite; runs in well
//!   under a second.

use crate::SimulationError;
use crate::config::{
    DefectConfig, FeatureShape, LatticeConfig, NoiseConfig, OutputConfig, ScanConfig,
    SimulationConfig, SurfaceConfig, TipConfig,
};
use crate::effects::{EffectConfig, FastScanHysteresis, HysteresisLaw, LogCreep, ThermalDrift};
use dhct_scan::ScanDirection;

/// One named preset.
#[derive(Debug, Clone, Copy)]
pub struct Preset {
    /// Name for `dhct simulate --preset`, also the TOML file's stem.
    pub name: &'static str,
    /// One line on what it shows.
    pub summary: &'static str,
    /// Builds the config.
    pub build: fn() -> SimulationConfig,
    /// The shipped TOML file's text.
    pub toml: &'static str,
}

/// Every preset.
pub const ALL: [Preset; 6] = [
    Preset {
        name: "fig3a-no-drift",
        summary: "Fig. 3 lattice (1 nm, 512², 50 nm/s) without drift",
        build: fig3_no_drift,
        toml: include_str!("../presets/fig3a-no-drift.toml"),
    },
    Preset {
        name: "fig3b-drift-fast",
        summary: "Fig. 3 lattice with 10 pm/s drift along +x (the fast axis)",
        build: fig3_drift_fast,
        toml: include_str!("../presets/fig3b-drift-fast.toml"),
    },
    Preset {
        name: "fig3c-drift-along-slow",
        summary: "Fig. 3 lattice with 10 pm/s drift along +y (with the slow scan)",
        build: fig3_drift_along_slow,
        toml: include_str!("../presets/fig3c-drift-along-slow.toml"),
    },
    Preset {
        name: "fig3d-drift-against-slow",
        summary: "Fig. 3 lattice with 10 pm/s drift along −y (against the slow scan)",
        build: fig3_drift_against_slow,
        toml: include_str!("../presets/fig3d-drift-against-slow.toml"),
    },
    Preset {
        name: "headline-2048",
        summary: "Fig. 4 headline: graphite, 2048², 25 nm, 100 nm/s, drift+creep+hysteresis+noise",
        build: headline_2048,
        toml: include_str!("../presets/headline-2048.toml"),
    },
    Preset {
        name: "ci-small",
        summary: "CI-sized graphite, 256², 4 nm, drift+creep+hysteresis+noise",
        build: ci_small,
        toml: include_str!("../presets/ci-small.toml"),
    },
];

/// The preset called `name`.
pub fn by_name(name: &str) -> Result<SimulationConfig, SimulationError> {
    ALL.iter()
        .find(|p| p.name == name)
        .map(|p| (p.build)())
        .ok_or_else(|| SimulationError::UnknownPreset {
            name: name.to_string(),
            known: ALL.map(|p| p.name).join(", "),
        })
}

fn fig3(name: &str, description: &str, velocity_m_per_s: Option<[f64; 2]>) -> SimulationConfig {
    SimulationConfig {
        name: name.into(),
        description: description.into(),
        seed: 3,
        scan: ScanConfig {
            columns: 512,
            rows: 512,
            width_m: 20e-9,
            height_m: 20e-9,
            fast_speed_m_per_s: 50e-9,
            turnaround_s: 0.0,
            trace_fast: ScanDirection::Right,
            slow: ScanDirection::Down,
            memory_limit_gib: None,
        },
        surface: SurfaceConfig {
            lattice: LatticeConfig::Hexagonal { a_m: 1e-9 },
            angle_rad: 0.0,
            origin_m: [0.0, 0.0],
            feature: FeatureShape {
                height_m: 50e-12,
                sigma_m: [0.2e-9, 0.2e-9],
                angle_rad: 0.0,
                lobes: Vec::new(),
            },
            defects: DefectConfig::default(),
            second_domain: None,
            steps: Vec::new(),
            strain: Vec::new(),
            modulations: Vec::new(),
        },
        tip: TipConfig::default(),
        noise: NoiseConfig::default(),
        output: OutputConfig::default(),
        effects: velocity_m_per_s
            .map(|velocity_m_per_s| {
                vec![EffectConfig::ThermalDrift(ThermalDrift {
                    velocity_m_per_s,
                    acceleration_m_per_s2: [0.0, 0.0],
                })]
            })
            .unwrap_or_default(),
    }
}

/// Fig. 3: hexagonal lattice, a = 1 nm, 512², 20 nm, 50 nm/s, no drift.
pub fn fig3_no_drift() -> SimulationConfig {
    fig3(
        "fig3a-no-drift",
        "Hexagonal lattice, a = 1 nm, 512 x 512 px over 20 nm, 50 nm/s, no drift",
        None,
    )
}

/// Fig. 3 with 10 pm/s tip drift along +x: lines shear, the trace is stretched by
/// 1 + 10 pm/s / 50 nm/s along x and the retrace compressed by the same amount.
pub fn fig3_drift_fast() -> SimulationConfig {
    fig3(
        "fig3b-drift-fast",
        "Fig. 3 lattice with 10 pm/s tip drift along +x (fast axis): shear",
        Some([10e-12, 0.0]),
    )
}

/// Fig. 3 with 10 pm/s tip drift along +y, with the downward slow scan: the slow scale is
/// stretched by 1 + 10/48.83, so the lattice looks compressed along y.
pub fn fig3_drift_along_slow() -> SimulationConfig {
    fig3(
        "fig3c-drift-along-slow",
        "Fig. 3 lattice with 10 pm/s tip drift along +y (with the slow scan): compressed along y",
        Some([0.0, 10e-12]),
    )
}

/// Fig. 3 with 10 pm/s tip drift along −y, against the slow scan: the slow scale shrinks
/// by 1 − 10/48.83, so the lattice looks stretched along y.
pub fn fig3_drift_against_slow() -> SimulationConfig {
    fig3(
        "fig3d-drift-against-slow",
        "Fig. 3 lattice with 10 pm/s tip drift along -y (against the slow scan): stretched along y",
        Some([0.0, -10e-12]),
    )
}

fn graphite_with_distortions(
    name: &str,
    description: &str,
    seed: u64,
    scan: ScanConfig,
    effects: Vec<EffectConfig>,
    noise: NoiseConfig,
) -> SimulationConfig {
    SimulationConfig {
        name: name.into(),
        description: description.into(),
        seed,
        scan,
        surface: SurfaceConfig {
            lattice: LatticeConfig::Graphite,
            angle_rad: 0.0,
            origin_m: [0.0, 0.0],
            feature: FeatureShape {
                height_m: 40e-12,
                sigma_m: [0.6e-10, 0.6e-10],
                angle_rad: 0.0,
                lobes: Vec::new(),
            },
            defects: DefectConfig::default(),
            second_domain: None,
            steps: Vec::new(),
            strain: Vec::new(),
            modulations: Vec::new(),
        },
        tip: TipConfig::default(),
        noise,
        output: OutputConfig::default(),
        effects,
    }
}

/// The paper's Fig. 4 headline acquisition: graphite, 2048 × 2048 px over 25 nm, 100 nm/s
/// (pixel period 122 µs, line 0.25 s, frame 1024 s, slow speed 24.4 pm/s), trace and
/// retrace, with drift (3, −2) pm/s, acceleration (−1, 0.5) fm/s², creep C = (0.2, 0.5) nm
/// with t0 = 60 s, the power-law hysteresis S = 0.93·τ^−0.035 (S ≈ 1.16 at 2 ms, 0.98 at
/// the line end) and 3 pm white, 2 pm 1/f, 5 pm line-offset noise and rare 50 pm spikes.
pub fn headline_2048() -> SimulationConfig {
    graphite_with_distortions(
        "headline-2048",
        "Graphite, 2048 x 2048 px over 25 nm, 100 nm/s, trace and retrace, with drift, creep, hysteresis and noise",
        2017,
        ScanConfig {
            columns: 2048,
            rows: 2048,
            width_m: 25e-9,
            height_m: 25e-9,
            fast_speed_m_per_s: 100e-9,
            turnaround_s: 0.0,
            trace_fast: ScanDirection::Right,
            slow: ScanDirection::Down,
            memory_limit_gib: None,
        },
        vec![
            EffectConfig::ThermalDrift(ThermalDrift {
                velocity_m_per_s: [3e-12, -2e-12],
                acceleration_m_per_s2: [-1e-15, 0.5e-15],
            }),
            EffectConfig::Creep(LogCreep {
                coefficient_m: [0.2e-9, 0.5e-9],
                t0_s: 60.0,
                start_s: 0.0,
            }),
            EffectConfig::FastHysteresis(FastScanHysteresis {
                law: HysteresisLaw::Power { k: 0.93, n: -0.035 },
            }),
        ],
        NoiseConfig {
            white_sigma_m: 3e-12,
            pink_sigma_m: 2e-12,
            line_offset_sigma_m: 5e-12,
            spike_probability: 1e-5,
            spike_height_m: 50e-12,
        },
    )
}

/// A CI-sized version: graphite, 256 × 256 px over 4 nm, 50 nm/s (line 80 ms, frame 41 s,
/// slow speed 97.7 pm/s), drift (5, −8) pm/s, creep C = (0.1, 0.2) nm with t0 = 20 s,
/// hysteresis S = 0.95·τ^−0.03, 2 pm white noise.
pub fn ci_small() -> SimulationConfig {
    graphite_with_distortions(
        "ci-small",
        "Graphite, 256 x 256 px over 4 nm, 50 nm/s, with drift, creep, hysteresis and white noise",
        1,
        ScanConfig {
            columns: 256,
            rows: 256,
            width_m: 4e-9,
            height_m: 4e-9,
            fast_speed_m_per_s: 50e-9,
            turnaround_s: 0.0,
            trace_fast: ScanDirection::Right,
            slow: ScanDirection::Down,
            memory_limit_gib: None,
        },
        vec![
            EffectConfig::ThermalDrift(ThermalDrift {
                velocity_m_per_s: [5e-12, -8e-12],
                acceleration_m_per_s2: [0.0, 0.0],
            }),
            EffectConfig::Creep(LogCreep {
                coefficient_m: [0.1e-9, 0.2e-9],
                t0_s: 20.0,
                start_s: 0.0,
            }),
            EffectConfig::FastHysteresis(FastScanHysteresis {
                law: HysteresisLaw::Power { k: 0.95, n: -0.03 },
            }),
        ],
        NoiseConfig {
            white_sigma_m: 2e-12,
            ..NoiseConfig::default()
        },
    )
}
