//! `dhct simulate CONFIG -o DIR`: simulate an STM acquisition (trace + retrace) with
//! distortion effects and write the images and the ground truth.

use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use dhct_simulate::{Simulation, SimulationConfig, SimulationError, presets};

/// Where the config comes from.
pub enum ConfigSource<'a> {
    /// A TOML or JSON file.
    File(&'a Path),
    /// A built-in preset.
    Preset(&'a str),
}

/// What `dhct simulate` was asked to do.
pub struct SimulateRequest<'a> {
    /// The simulation config: a file or a preset.
    pub source: ConfigSource<'a>,
    /// The directory the simulated files and ground truth go to (needed unless only the
    /// config is printed).
    pub output: Option<&'a Path>,
    /// Replaces the config's random seed.
    pub seed: Option<u64>,
    /// Only return the resolved config as TOML; simulate nothing.
    pub print_config: bool,
}

/// The preset table for `--list-presets`.
pub fn list_presets() -> String {
    let width = presets::ALL.iter().map(|p| p.name.len()).max().unwrap_or(0);
    let mut text = String::new();
    for preset in presets::ALL {
        let _ = writeln!(text, "{:width$}  {}", preset.name, preset.summary);
    }
    text
}

fn load(source: &ConfigSource) -> Result<SimulationConfig> {
    match source {
        ConfigSource::File(path) => match SimulationConfig::from_path(path) {
            // These already name the file.
            Err(error @ (SimulationError::Parse { .. } | SimulationError::Io { .. })) => {
                Err(error.into())
            }
            other => {
                other.with_context(|| format!("cannot use simulation config {}", path.display()))
            }
        },
        ConfigSource::Preset(name) => Ok(presets::by_name(name)?),
    }
}

/// Runs the request; returns what to print on stdout.
pub fn run(request: &SimulateRequest) -> Result<String> {
    let mut config = load(&request.source)?;
    if let Some(seed) = request.seed {
        config.seed = seed;
    }
    if request.print_config {
        return Ok(config.to_toml_string()?);
    }
    let Some(dir) = request.output else {
        bail!("no output directory: give -o DIR (or --print-config to only show the config)");
    };
    let simulation = Simulation::from_config(&config).context("invalid simulation config")?;
    let started = Instant::now();
    let output = simulation.run().context("simulation failed")?;
    let elapsed = started.elapsed().as_secs_f64();
    let written = output
        .write(dir)
        .with_context(|| format!("cannot write the simulation to {}", dir.display()))?;

    let g = output.pair.geometry();
    let mut text = String::new();
    let _ = writeln!(
        text,
        "simulated {} ({} x {} px, {:.4} x {:.4} nm, frame {:.1} s) in {elapsed:.2} s",
        if config.name.is_empty() {
            "scan"
        } else {
            &config.name
        },
        g.columns(),
        g.rows(),
        g.width() * 1e9,
        g.height() * 1e9,
        g.frame_duration(),
    );
    let imaged = output
        .truth
        .imaged_features(dhct_scan::ScanPass::Trace)
        .count();
    let _ = writeln!(
        text,
        "{} features in the scanned area, {imaged} imaged by the trace; {} effects",
        output.truth.features.len(),
        output.truth.effects.len()
    );
    for path in written {
        let _ = writeln!(text, "wrote {}", path.display());
    }
    Ok(text)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_are_listed() {
        let list = list_presets();
        assert!(
            list.contains("ci-small") && list.contains("headline-2048"),
            "{list}"
        );
    }

    #[test]
    fn a_preset_is_simulated_into_a_directory() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("sim");
        let text = run(&SimulateRequest {
            source: ConfigSource::Preset("ci-small"),
            output: Some(&out),
            seed: Some(5),
            print_config: false,
        })
        .unwrap();
        assert!(text.contains("256 x 256 px"), "{text}");
        assert!(out.join("simulation.sm4").is_file());
        assert!(out.join("ground_truth.json").is_file());
        let truth: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("ground_truth.json")).unwrap())
                .unwrap();
        assert_eq!(truth["config"]["seed"], 5);
    }

    #[test]
    fn config_errors_name_the_file_and_the_field() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bad.toml");
        let mut config = presets::ci_small();
        config.scan.width_m = -1.0;
        std::fs::write(&path, config.to_toml_string().unwrap()).unwrap();
        let error = run(&SimulateRequest {
            source: ConfigSource::File(&path),
            output: Some(dir.path()),
            seed: None,
            print_config: false,
        })
        .unwrap_err();
        let message = format!("{error:#}");
        assert!(
            message.contains("bad.toml") && message.contains("scan.width_m"),
            "{message}"
        );

        let error = run(&SimulateRequest {
            source: ConfigSource::Preset("nope"),
            output: Some(dir.path()),
            seed: None,
            print_config: false,
        })
        .unwrap_err();
        assert!(format!("{error:#}").contains("ci-small"));
    }

    #[test]
    fn print_config_round_trips() {
        let text = run(&SimulateRequest {
            source: ConfigSource::Preset("fig3b-drift-fast"),
            output: None,
            seed: None,
            print_config: true,
        })
        .unwrap();
        assert_eq!(
            SimulationConfig::from_toml_str(&text).unwrap(),
            presets::fig3_drift_fast()
        );
    }
}
