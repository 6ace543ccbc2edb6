//! Configs round-trip through TOML and JSON, and bad configs give errors naming the field.

mod common;

use common::base_config;
use dhct_simulate::effects::{
    AsymmetricHysteresis, ExponentialCreep, FastScanHysteresis, HeightCoupling, LineDrift,
    LogCreep, ScanCoupling, SlowScanHysteresis, ThermalDrift, TipChange, Vibration,
};
use dhct_simulate::{
    EffectConfig, HysteresisLaw, Lobe, NoiseConfig, OutputFormat, Region, SecondDomain, Simulation,
    SimulationConfig, SimulationError, StepEdge, StrainRegion, presets,
};

/// A config using every effect kind and every surface option.
fn everything() -> SimulationConfig {
    let mut config = base_config();
    config.surface.lattice = dhct_simulate::LatticeConfig::User(
        dhct_lattice::UserLattice::from_toml(
            "name = 'c2x2'\nlength_unit = 'A'\na1 = [4.0, 0.0]\na2 = [0.0, 4.0]\n\
             plane_group = 'p4mm'\n[[motif]]\nfractional = [0.0, 0.0]\n\
             [[motif]]\nfractional = [0.5, 0.5]\nrelative_height = 0.7\n",
        )
        .unwrap(),
    );
    config.surface.feature.lobes = vec![Lobe {
        offset_m: [1e-11, 0.0],
        relative_height: 0.5,
        sigma_m: Some([5e-11, 6e-11]),
        angle_rad: None,
    }];
    config.surface.defects.vacancy_fraction = 0.05;
    config.surface.defects.vacancy_positions_m = vec![[1e-9, 1e-9]];
    config.surface.defects.adatom_count = 2;
    config.surface.defects.adatom_positions_m = vec![[2e-9, 2e-9]];
    config.surface.second_domain = Some(SecondDomain {
        region: Region::Rectangle {
            min_m: [0.0, 0.0],
            max_m: [2e-9, 2e-9],
        },
        angle_rad: 0.4,
        origin_m: [1e-10, 0.0],
    });
    config.surface.steps = vec![StepEdge {
        region: Region::HalfPlane {
            point_m: [3e-9, 0.0],
            normal: [1.0, 0.1],
        },
        height_m: 3.35e-10,
    }];
    config.surface.strain = vec![StrainRegion {
        region: Region::Circle {
            centre_m: [4e-9, 4e-9],
            radius_m: 1e-9,
        },
        strain: [[0.01, 0.002], [0.002, -0.01]],
        anchor_m: [4e-9, 4e-9],
    }];
    config.tip.sigma_m = 2e-11;
    config.noise = NoiseConfig {
        white_sigma_m: 1e-12,
        pink_sigma_m: 2e-12,
        line_offset_sigma_m: 3e-12,
        spike_probability: 1e-4,
        spike_height_m: 5e-11,
    };
    config.output.formats = vec![
        OutputFormat::Sm4,
        OutputFormat::Gsf,
        OutputFormat::Npy,
        OutputFormat::Png,
    ];
    config.effects = vec![
        EffectConfig::ThermalDrift(ThermalDrift {
            velocity_m_per_s: [1e-12, -2e-12],
            acceleration_m_per_s2: [1e-15, 0.0],
        }),
        EffectConfig::Creep(LogCreep {
            coefficient_m: [1e-10, 2e-10],
            t0_s: 30.0,
            start_s: 0.0,
        }),
        EffectConfig::Creep(LogCreep {
            coefficient_m: [5e-11, 0.0],
            t0_s: 2.0,
            start_s: 10.0,
        }),
        EffectConfig::ExponentialCreep(ExponentialCreep {
            amplitude_m: [1e-10, 0.0],
            time_constant_s: 5.0,
            start_s: 1.0,
        }),
        EffectConfig::FastHysteresis(FastScanHysteresis {
            law: HysteresisLaw::Quartic {
                coefficients: [0.0, 0.1, -0.2, 0.05, 0.01],
                time_scale_s: 0.128,
            },
        }),
        EffectConfig::AsymmetricHysteresis(AsymmetricHysteresis {
            trace: HysteresisLaw::Power { k: 0.95, n: -0.03 },
            retrace: HysteresisLaw::Exponential {
                amplitude: 0.1,
                time_constant_s: 0.01,
            },
        }),
        EffectConfig::SlowHysteresis(SlowScanHysteresis {
            law: HysteresisLaw::Exponential {
                amplitude: 0.05,
                time_constant_s: 2.0,
            },
        }),
        EffectConfig::LineDrift(LineDrift {
            velocity_m_per_s: [1e-10, 0.0],
        }),
        EffectConfig::ScanCoupling(ScanCoupling {
            slow_to_fast: 0.01,
            fast_to_slow: -0.005,
        }),
        EffectConfig::HeightCoupling(HeightCoupling {
            lateral_per_height: [0.02, 0.0],
        }),
        EffectConfig::Vibration(Vibration {
            frequency_hz: 7.0,
            amplitude_m: [2e-12, 1e-12],
            phase_rad: [0.0, 0.5],
        }),
        EffectConfig::TipChange(TipChange {
            time_s: 20.0,
            jump_m: [3e-11, 0.0],
            height_offset_m: 1e-11,
            contrast: 1.3,
        }),
    ];
    config
}

#[test]
fn configs_round_trip_through_toml_and_json() {
    let config = everything();
    config.validate().unwrap();
    let toml = config.to_toml_string().unwrap();
    assert_eq!(
        SimulationConfig::from_toml_str(&toml).unwrap(),
        config,
        "{toml}"
    );
    let json = config.to_json_string().unwrap();
    assert_eq!(SimulationConfig::from_json_str(&json).unwrap(), config);
    for preset in presets::ALL {
        let c = preset.config().unwrap();
        assert_eq!(
            SimulationConfig::from_toml_str(&c.to_toml_string().unwrap()).unwrap(),
            c
        );
    }
}

#[test]
fn configs_load_from_toml_and_json_files() {
    let dir = tempfile::tempdir().unwrap();
    let config = everything();
    let json = dir.path().join("sim.json");
    std::fs::write(&json, config.to_json_string().unwrap()).unwrap();
    assert_eq!(SimulationConfig::from_path(&json).unwrap(), config);
    let toml = dir.path().join("sim.toml");
    std::fs::write(&toml, config.to_toml_string().unwrap()).unwrap();
    assert_eq!(SimulationConfig::from_path(&toml).unwrap(), config);
    let missing = SimulationConfig::from_path(&dir.path().join("nope.toml")).unwrap_err();
    assert!(matches!(missing, SimulationError::Io { .. }));
}

#[test]
fn a_config_with_every_effect_runs() {
    let output = Simulation::from_config(&everything())
        .unwrap()
        .run()
        .unwrap();
    assert_eq!(output.truth.effects.len(), 12);
    assert!(output.truth.features.iter().any(|f| matches!(
        f.kind,
        dhct_simulate::surface::FeatureKind::LatticeSite { domain: 1, .. }
    )));
    let converged = output
        .truth
        .features
        .iter()
        .filter(|f| f.trace.converged)
        .count();
    assert!(converged as f64 > 0.95 * output.truth.features.len() as f64);
}

/// The TOML of [`base_config`] with `key = value` replaced in `section`.
fn edited(section: &str, key: &str, value: &str) -> String {
    let mut table: toml::Table = toml::from_str(&base_config().to_toml_string().unwrap()).unwrap();
    let text = format!("x = {value}");
    let parsed: toml::Table = toml::from_str(&text).unwrap();
    table[section]
        .as_table_mut()
        .unwrap()
        .insert(key.to_string(), parsed["x"].clone());
    toml::to_string(&table).unwrap()
}

fn invalid_field(text: &str) -> String {
    let config = SimulationConfig::from_toml_str(text).unwrap();
    // Simulation::from_config validates too.
    assert!(Simulation::from_config(&config).is_err());
    match config.validate().unwrap_err() {
        SimulationError::InvalidConfig { field, .. } => field,
        other => panic!("expected InvalidConfig, got {other}"),
    }
}

#[test]
fn bad_values_are_rejected_naming_the_field() {
    assert_eq!(
        invalid_field(&edited("scan", "width_m", "-1e-9")),
        "scan.width_m"
    );
    assert_eq!(
        invalid_field(&edited("scan", "height_m", "0.0")),
        "scan.height_m"
    );
    assert_eq!(
        invalid_field(&edited("scan", "fast_speed_m_per_s", "nan")),
        "scan.fast_speed_m_per_s"
    );
    assert_eq!(
        invalid_field(&edited("scan", "turnaround_s", "-0.1")),
        "scan.turnaround_s"
    );
    assert_eq!(
        invalid_field(&edited("scan", "columns", "0")),
        "scan.columns"
    );
    assert_eq!(
        invalid_field(&edited("scan", "slow", "'left'")),
        "scan.slow"
    );
    let huge = edited("scan", "columns", "20000").replace("rows = 128", "rows = 20000");
    assert_eq!(invalid_field(&huge), "scan.columns × scan.rows");
    assert_eq!(
        invalid_field(&edited("tip", "sigma_m", "-1e-12")),
        "tip.sigma_m"
    );
    assert_eq!(
        invalid_field(&edited("noise", "spike_probability", "2.0")),
        "noise.spike_probability"
    );

    let mut config = base_config();
    config
        .effects
        .push(EffectConfig::FastHysteresis(FastScanHysteresis {
            law: HysteresisLaw::Power { k: 1.0, n: -1.5 },
        }));
    config.effects.push(EffectConfig::Creep(LogCreep {
        coefficient_m: [0.0, 0.0],
        t0_s: 0.0,
        start_s: 0.0,
    }));
    let error = config.validate().unwrap_err().to_string();
    assert!(error.contains("effects[0].law.n"), "{error}");
    config.effects.remove(0);
    let error = config.validate().unwrap_err().to_string();
    assert!(error.contains("effects[0].t0_s"), "{error}");

    let mut config = base_config();
    config.surface.feature.sigma_m = [1e-10, 0.0];
    assert!(
        config
            .validate()
            .unwrap_err()
            .to_string()
            .contains("surface.feature.sigma_m")
    );
    let mut config = base_config();
    config.surface.lattice = dhct_simulate::LatticeConfig::Square { a_m: 0.0 };
    assert!(
        config
            .validate()
            .unwrap_err()
            .to_string()
            .contains("surface.lattice")
    );
}

fn parse_error(text: &str) -> String {
    match SimulationConfig::from_toml_str(text).unwrap_err() {
        SimulationError::Parse { message, .. } => message,
        other => panic!("expected a parse error, got {other}"),
    }
}

#[test]
fn malformed_configs_are_parse_errors_that_say_what_is_wrong() {
    let base = base_config()
        .to_toml_string()
        .unwrap()
        .replace("effects = []\n", "");
    let message = parse_error(&edited("scan", "columns", "-5"));
    assert!(message.contains("columns"), "{message}");
    let unknown = format!("{base}\n[[effects]]\nkind = \"earthquake\"\n");
    let message = parse_error(&unknown);
    assert!(
        message.contains("earthquake") && message.contains("thermal-drift"),
        "{message}"
    );
    let misspelt =
        format!("{base}\n[[effects]]\nkind = \"thermal-drift\"\nvelocity = [1.0, 0.0]\n");
    let message = parse_error(&misspelt);
    assert!(message.contains("velocity"), "{message}");
    let bad_law = format!(
        "{base}\n[[effects]]\nkind = \"fast-hysteresis\"\nlaw = {{ kind = \"power\", k = 1.0, n = 0.1, extra = 2 }}\n"
    );
    let message = parse_error(&bad_law);
    assert!(message.contains("extra"), "{message}");
    let message = parse_error("seed = 1\n");
    assert!(message.contains("scan"), "{message}");
}
