//! `dhct simulate CONFIG -o DIR`: simulate an STM acquisition (trace + retrace) with
//! distortion effects and write the images and the ground truth; or, when the config has a
//! `[sequence]` table, an image sequence (every frame's images and `sequence_truth.json`).

use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use dhct_simulate::sequence::{FrameTruth, SEQUENCE_TRUTH_FILE};
use dhct_simulate::{SequenceSimulation, Simulation, SimulationConfig, SimulationError, presets};

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
    if config.sequence.is_some() {
        return run_sequence(&config, dir);
    }
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

/// Runs and writes the sequence `config` describes, one frame at a time; returns one line
/// per frame and a summary.
fn run_sequence(config: &SimulationConfig, dir: &Path) -> Result<String> {
    let sequence = SequenceSimulation::from_config(config).context("invalid simulation config")?;
    let g = config
        .scan
        .geometry()
        .context("invalid simulation config")?;
    let timeline = sequence.timeline();
    let mut text = String::new();
    let _ = writeln!(
        text,
        "simulating {} ({} frames of {} x {} px, {:.4} x {:.4} nm, frame {:.1} s, {:.0} s in all)",
        if config.name.is_empty() {
            "sequence"
        } else {
            &config.name
        },
        sequence.frame_count(),
        g.columns(),
        g.rows(),
        g.width() * 1e9,
        g.height() * 1e9,
        g.frame_duration(),
        timeline.end_s(),
    );
    let started = Instant::now();
    let written = sequence
        .write(dir, |frame, _| {
            let _ = writeln!(text, "{}", frame_line(frame));
        })
        .with_context(|| format!("cannot write the sequence to {}", dir.display()))?;
    let _ = writeln!(
        text,
        "wrote {} files into {} in {:.2} s; the ground truth is {SEQUENCE_TRUTH_FILE}",
        written.len(),
        dir.display(),
        started.elapsed().as_secs_f64()
    );
    Ok(text)
}

/// One frame of a sequence: time, scan angle, centre, drift at its start, features imaged.
fn frame_line(frame: &FrameTruth) -> String {
    let p = &frame.placement;
    format!(
        "frame {:>3}: T = {:>6.0} s, scan angle {:6.1} deg, centre ({:.3}, {:.3}) nm, \
         drift at start ({:.3}, {:.3}) nm, {} features imaged by the trace",
        p.index,
        p.start_s,
        p.scan_angle_rad.to_degrees(),
        p.offset_m[0] * 1e9,
        p.offset_m[1] * 1e9,
        p.displacement_at_start_m[0] * 1e9,
        p.displacement_at_start_m[1] * 1e9,
        frame.imaged_features(dhct_scan::ScanPass::Trace).count(),
    )
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
    fn a_sequence_config_writes_every_frame_and_the_truth() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("sequence.toml");
        let mut config = presets::graphite_sequence();
        config.scan.columns = 32;
        config.scan.rows = 32;
        config.scan.width_m = 0.5e-9;
        config.scan.height_m = 0.5e-9;
        config.sequence.as_mut().unwrap().frames = 3;
        config.sequence.as_mut().unwrap().moves[0].before_frame = 2;
        std::fs::write(&path, config.to_toml_string().unwrap()).unwrap();
        let out = dir.path().join("seq");
        let text = run(&SimulateRequest {
            source: ConfigSource::File(&path),
            output: Some(&out),
            seed: Some(4),
            print_config: false,
        })
        .unwrap();
        assert!(text.contains("3 frames of 32 x 32 px"), "{text}");
        assert_eq!(text.matches("frame   ").count(), 3, "{text}");
        for name in [
            "frame_00.sm4",
            "frame_02.sm4",
            "frame_01_trace.png",
            SEQUENCE_TRUTH_FILE,
        ] {
            assert!(out.join(name).is_file(), "{name} missing: {text}");
        }
        let truth: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join(SEQUENCE_TRUTH_FILE)).unwrap())
                .unwrap();
        assert_eq!(truth["config"]["seed"], 4);
        assert_eq!(truth["frames"].as_array().unwrap().len(), 3);
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
