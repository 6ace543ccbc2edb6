//! Every shipped preset file parses, carries its own name, is valid and builds; the
//! shorthands and `by_name` read those files; the files hold the physics the docs name.

use dhct_simulate::{SequenceSimulation, Simulation, SimulationConfig, SimulationError, presets};

#[test]
fn every_preset_file_parses_with_its_name() {
    for preset in presets::ALL {
        let config = preset
            .config()
            .unwrap_or_else(|e| panic!("{}: {e}", preset.name));
        assert_eq!(config.name, preset.name);
        assert_eq!(presets::by_name(preset.name).unwrap(), config);
    }
}

#[test]
fn preset_files_on_disk_are_the_embedded_ones() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("presets");
    let mut on_disk: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    on_disk.sort();
    let mut expected: Vec<String> = presets::ALL
        .iter()
        .map(|p| format!("{}.toml", p.name))
        .collect();
    expected.sort();
    assert_eq!(on_disk, expected);
    for preset in presets::ALL {
        let config =
            SimulationConfig::from_path(&dir.join(format!("{}.toml", preset.name))).unwrap();
        assert_eq!(config, preset.config().unwrap());
    }
}

#[test]
fn the_shorthands_read_their_files() {
    let pairs = [
        ("fig3a-no-drift", presets::fig3_no_drift()),
        ("fig3b-drift-fast", presets::fig3_drift_fast()),
        ("fig3c-drift-along-slow", presets::fig3_drift_along_slow()),
        (
            "fig3d-drift-against-slow",
            presets::fig3_drift_against_slow(),
        ),
        ("headline-2048", presets::headline_2048()),
        ("ci-small", presets::ci_small()),
        ("graphite-sequence", presets::graphite_sequence()),
    ];
    for (name, config) in pairs {
        assert_eq!(config, presets::by_name(name).unwrap(), "{name}");
    }
}

#[test]
fn the_files_hold_the_documented_physics() {
    let headline = presets::headline_2048();
    assert_eq!((headline.scan.columns, headline.scan.rows), (2048, 2048));
    assert_eq!(headline.scan.width_m, 25e-9);
    assert_eq!(headline.scan.fast_speed_m_per_s, 100e-9);
    assert_eq!(headline.effects.len(), 3);
    let fig3 = presets::fig3_drift_fast();
    assert_eq!((fig3.scan.columns, fig3.scan.width_m), (512, 20e-9));
    assert_eq!(fig3.scan.fast_speed_m_per_s, 50e-9);
    assert_eq!(presets::fig3_no_drift().effects.len(), 0);
    let sequence = presets::graphite_sequence();
    let table = sequence.sequence.as_ref().unwrap();
    assert_eq!((sequence.scan.columns, table.frames), (256, 12));
    assert_eq!((table.pause_s, table.moves[0].before_frame), (3.0, 6));
    for drifting in [
        presets::fig3_drift_fast(),
        presets::fig3_drift_along_slow(),
        presets::fig3_drift_against_slow(),
    ] {
        assert_eq!(drifting.effects.len(), 1, "{}", drifting.name);
    }
}

#[test]
fn every_preset_validates_and_builds() {
    for preset in presets::ALL {
        let config = preset.config().unwrap();
        config
            .validate()
            .unwrap_or_else(|e| panic!("{}: {e}", preset.name));
        if config.sequence.is_some() {
            SequenceSimulation::from_config(&config).unwrap();
            let error = Simulation::from_config(&config).unwrap_err();
            assert!(error.to_string().contains("sequence"), "{error}");
        } else {
            Simulation::from_config(&config).unwrap();
        }
    }
}

#[test]
fn presets_are_found_by_name() {
    assert_eq!(presets::by_name("ci-small").unwrap(), presets::ci_small());
    assert_eq!(
        presets::by_name("headline-2048").unwrap(),
        presets::headline_2048()
    );
    let error = presets::by_name("fig9").unwrap_err();
    assert!(matches!(error, SimulationError::UnknownPreset { .. }));
    assert!(error.to_string().contains("ci-small"), "{error}");
}

#[test]
fn ci_small_runs_and_images_the_lattice() {
    let output = Simulation::from_config(&presets::ci_small())
        .unwrap()
        .run()
        .unwrap();
    let trace = output.pair.trace().unwrap();
    assert_eq!(trace.z.dim(), (256, 256));
    assert_eq!(output.pair.retrace().unwrap().z.dim(), (256, 256));
    // 4 nm x 4 nm of graphite holds about 16e-18 / 5.24e-20 ≈ 305 atoms.
    let imaged = output
        .truth
        .imaged_features(dhct_scan::ScanPass::Trace)
        .count();
    assert!((250..=360).contains(&imaged), "{imaged} features imaged");
    let (low, high) = trace.finite_range().unwrap();
    assert!(
        high - low > 30e-12 && high - low < 80e-12,
        "{low} .. {high}"
    );
    assert_eq!(output.truth.effects.len(), 3);
}
