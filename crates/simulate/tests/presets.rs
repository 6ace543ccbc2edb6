//! The shipped preset files equal the API presets, and every preset is valid.

use dhct_simulate::{Simulation, SimulationConfig, SimulationError, presets};

#[test]
fn every_preset_file_equals_its_api_preset() {
    for preset in presets::ALL {
        let from_file = SimulationConfig::from_toml_str(preset.toml)
            .unwrap_or_else(|e| panic!("{}: {e}", preset.name));
        assert_eq!(from_file, (preset.build)(), "preset {}", preset.name);
        assert_eq!(from_file.name, preset.name);
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
        assert_eq!(config, (preset.build)());
    }
}

#[test]
fn every_preset_validates_and_builds() {
    for preset in presets::ALL {
        let config = (preset.build)();
        config
            .validate()
            .unwrap_or_else(|e| panic!("{}: {e}", preset.name));
        Simulation::from_config(&config).unwrap();
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
