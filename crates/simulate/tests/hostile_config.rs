//! Hostile simulator configs: refused quickly, with the field and the number in the message.

use std::time::{Duration, Instant};

use dhct_simulate::{SimulationConfig, SimulationError, presets};

fn message(config: &SimulationConfig) -> String {
    let start = Instant::now();
    let error = config.validate().expect_err("must be refused");
    assert!(start.elapsed() < Duration::from_secs(2));
    error.to_string()
}

#[test]
fn huge_images_are_refused_with_the_memory_they_would_need() {
    let mut config = presets::ci_small();
    config.scan.columns = 16384;
    config.scan.rows = 16384;
    let text = message(&config);
    assert!(
        text.contains("16384 x 16384") && text.contains("21.5 GB"),
        "{text}"
    );
    config.scan.columns = 5120;
    config.scan.rows = 5120;
    config.scan.width_m = 1e-7;
    config.scan.height_m = 1e-7;
    config.validate().expect("5120² fits the memory limit");
}

#[test]
fn ten_thousand_effects_are_refused() {
    let mut config = presets::ci_small();
    let effect = config
        .effects
        .first()
        .cloned()
        .expect("ci-small has effects");
    config.effects = vec![effect; 10_000];
    let text = message(&config);
    assert!(
        text.contains("10000 effects") && text.contains("64"),
        "{text}"
    );
}

#[test]
fn too_many_lattice_sites_and_long_lists_are_refused() {
    let mut config = presets::ci_small();
    config.scan.width_m = 1e-5;
    config.scan.height_m = 1e-5;
    let text = message(&config);
    assert!(text.contains("lattice sites"), "{text}");

    let mut config = presets::ci_small();
    config.surface.defects.vacancy_positions_m = vec![[0.0, 0.0]; 1_000_001];
    assert!(message(&config).contains("vacancy_positions_m"));
}

#[test]
fn non_finite_values_are_refused_naming_the_field() {
    let mut config = presets::ci_small();
    config.scan.fast_speed_m_per_s = f64::NAN;
    assert!(message(&config).contains("scan.fast_speed_m_per_s"));
    let mut config = presets::ci_small();
    config.surface.angle_rad = f64::INFINITY;
    assert!(message(&config).contains("surface.angle_rad"));
    let mut config = presets::ci_small();
    config.noise.spike_probability = f64::NAN;
    assert!(message(&config).contains("noise.spike_probability"));
}

#[test]
fn special_files_are_refused_before_opening() {
    let dir = tempfile::tempdir().unwrap();
    let error = SimulationConfig::from_path(dir.path()).expect_err("a directory");
    assert!(matches!(error, SimulationError::Io { .. }), "{error}");
    let fifo = dir.path().join("pipe.toml");
    if std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .is_ok_and(|s| s.success())
    {
        let (send, receive) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let _ = send.send(SimulationConfig::from_path(&fifo).map(|_| ()));
        });
        let result = receive
            .recv_timeout(Duration::from_secs(10))
            .expect("reading a FIFO config blocked");
        let text = format!("{:#}", anyhow_like(result.expect_err("a FIFO")));
        assert!(text.contains("named pipe"), "{text}");
    }
}

/// The error with its source chain, as the CLI prints it.
fn anyhow_like(error: SimulationError) -> String {
    let mut text = error.to_string();
    let mut source = std::error::Error::source(&error);
    while let Some(s) = source {
        text.push_str(": ");
        text.push_str(&s.to_string());
        source = s.source();
    }
    text
}
