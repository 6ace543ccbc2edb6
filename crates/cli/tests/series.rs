//! `dhct series` on simulated sequences with known truth: every frame registered into one
//! sample frame within the single-frame localisation floor, frames against each other within
//! 0.02 px, the shared hysteresis far better fixed than by one frame; and the inputs a
//! series cannot be made of refused.

#[allow(dead_code)]
mod common;

use std::path::Path;

use common::dhct;
use dhct_simulate::{SequenceSimulation, SequenceTruth, presets};

/// Simulates `config` into `dir`; returns the truth.
fn simulate(config: &dhct_simulate::SimulationConfig, dir: &Path) -> SequenceTruth {
    let simulation = SequenceSimulation::from_config(config).expect("a valid sequence");
    simulation.write(dir, |_, _| {}).expect("written");
    let text = std::fs::read_to_string(dir.join("sequence_truth.json")).expect("truth");
    serde_json::from_str(&text).expect("truth parses")
}

/// `dhct series PATTERN -o OUT --quiet ARGS…`.
fn series(pattern: &str, out: &Path, args: &[&str]) -> std::process::Output {
    dhct()
        .arg("series")
        .arg(pattern)
        .arg("-o")
        .arg(out)
        .arg("--quiet")
        .args(args)
        .output()
        .expect("dhct runs")
}

/// One found feature: frame, pass, raw pixel position, registered session position.
struct Registered {
    frame: usize,
    pass: String,
    px: [f64; 2],
    session_m: [f64; 2],
}

fn read_features(path: &Path) -> Vec<Registered> {
    let mut reader = csv::Reader::from_path(path).expect("features.csv");
    reader
        .records()
        .map(|r| {
            let r = r.expect("a row");
            let num = |k: usize| r[k].parse::<f64>().expect("a number");
            Registered {
                frame: r[0].parse().expect("frame"),
                pass: r[1].to_string(),
                px: [num(2), num(3)],
                session_m: [num(6), num(7)],
            }
        })
        .collect()
}

/// One frame and pass: its index, and the localisation and registration error (pixels)
/// of every found feature matched to its true site.
type FrameErrors = (usize, Vec<[f64; 2]>, Vec<[f64; 2]>);

/// Per frame and pass: (localisation error, registration error) of each found feature
/// matched to its true site (within 1 px of where the truth says it was imaged), pixels.
fn errors(truth: &SequenceTruth, found: &[Registered]) -> Vec<FrameErrors> {
    let pitch = truth.frames[0].geometry.pitch_x();
    let mut out = Vec::new();
    for (k, frame) in truth.frames.iter().enumerate() {
        for pass in ["trace", "retrace"] {
            let (mut local, mut registered) = (Vec::new(), Vec::new());
            for f in found.iter().filter(|f| f.frame == k && f.pass == pass) {
                let best = frame
                    .features
                    .iter()
                    .filter_map(|t| {
                        let a = if pass == "trace" {
                            &t.trace
                        } else {
                            &t.retrace
                        };
                        let d = [
                            f.px[0] - a.controller_position_px[0],
                            f.px[1] - a.controller_position_px[1],
                        ];
                        (a.in_image && d[0].hypot(d[1]) < 1.0)
                            .then_some((d, t.instrument_position_m))
                    })
                    .min_by(|a, b| a.0[0].hypot(a.0[1]).total_cmp(&b.0[0].hypot(b.0[1])));
                if let Some((d, site)) = best {
                    local.push(d);
                    registered.push([
                        (f.session_m[0] - site[0]) / pitch,
                        (f.session_m[1] - site[1]) / pitch,
                    ]);
                }
            }
            out.push((k, local, registered));
        }
    }
    out
}

fn mean(v: &[[f64; 2]]) -> [f64; 2] {
    let n = v.len().max(1) as f64;
    let s = v.iter().fold([0.0; 2], |a, d| [a[0] + d[0], a[1] + d[1]]);
    [s[0] / n, s[1] / n]
}

fn rms_about(v: &[[f64; 2]], centre: [f64; 2]) -> f64 {
    let n = v.len().max(1) as f64;
    (v.iter()
        .map(|d| (d[0] - centre[0]).powi(2) + (d[1] - centre[1]).powi(2))
        .sum::<f64>()
        / n)
        .sqrt()
}

#[test]
fn a_simulated_session_registers_every_frame_within_the_localisation_floor() {
    let dir = tempfile::tempdir().expect("tempdir");
    let frames = dir.path().join("frames");
    let truth = simulate(&presets::graphite_sequence(), &frames);
    let out = dir.path().join("out");
    let pattern = frames.join("*.sm4");
    let run = series(pattern.to_str().expect("utf-8"), &out, &[]);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let found = read_features(&out.join("features.csv"));
    let per_frame = errors(&truth, &found);
    // The session frame is defined up to one translation (the lattice has no origin of its
    // own): the mean over every frame is taken out, nothing per frame.
    let all: Vec<[f64; 2]> = per_frame.iter().flat_map(|(_, _, r)| r.clone()).collect();
    let global = mean(&all);
    for (k, local, registered) in &per_frame {
        assert!(
            registered.len() > 150,
            "frame {k}: {} matched",
            registered.len()
        );
        let floor = rms_about(local, [0.0; 2]);
        let error = rms_about(registered, global);
        assert!(
            error <= 1.2 * floor,
            "frame {k}: registered {error:.4} px against a floor of {floor:.4} px"
        );
        let offset = mean(registered);
        let between = (offset[0] - global[0]).hypot(offset[1] - global[1]);
        assert!(
            between <= 0.02,
            "frame {k}: {between:.4} px from the others"
        );
    }
    // The shared hysteresis, fitted to every frame, against the best single frame's σ.
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("series.json")).expect("json"))
            .expect("parses");
    for name in ["k", "n"] {
        let sigma_of = |list: &serde_json::Value| {
            list.as_array()
                .expect("parameters")
                .iter()
                .find(|p| p["name"] == name)
                .and_then(|p| p["sigma"].as_f64())
                .expect("a determined parameter")
        };
        let series_sigma = sigma_of(&summary["fit"]["parameters"]);
        let best_frame = summary["frames"]
            .as_array()
            .expect("frames")
            .iter()
            .map(|f| sigma_of(&f["own_hysteresis"]))
            .fold(f64::INFINITY, f64::min);
        assert!(
            series_sigma <= 0.5 * best_frame,
            "{name}: σ {series_sigma:e} in the series, {best_frame:e} in the best frame"
        );
    }
    for file in [
        "trajectory.csv",
        "registered/stack.tif",
        "registered/mean.gsf",
        "registered/frame_11_retrace.gsf",
    ] {
        assert!(out.join(file).is_file(), "{file}");
    }
}

#[test]
fn inputs_a_series_cannot_be_made_of_are_refused() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mut config = presets::graphite_sequence();
    config.scan.columns = 96;
    config.scan.rows = 96;
    config.scan.width_m = 3e-9;
    config.scan.height_m = 3e-9;
    if let Some(sequence) = config.sequence.as_mut() {
        sequence.frames = 2;
        sequence.moves.clear();
    }
    let frames = dir.path().join("frames");
    simulate(&config, &frames);
    // One frame.
    let one = series(
        frames.join("frame_00.sm4").to_str().expect("utf-8"),
        &dir.path().join("a"),
        &[],
    );
    assert!(!one.status.success());
    let err = String::from_utf8_lossy(&one.stderr);
    assert!(err.contains("at least two frames"), "{err}");
    // Frames of two sizes.
    let other = dir.path().join("other");
    config.scan.columns = 80;
    config.scan.rows = 80;
    config.scan.width_m = 2.5e-9;
    config.scan.height_m = 2.5e-9;
    simulate(&config, &other);
    std::fs::copy(other.join("frame_01.sm4"), frames.join("frame_01.sm4")).expect("copied");
    let mixed = series(
        frames.join("*.sm4").to_str().expect("utf-8"),
        &dir.path().join("b"),
        &[],
    );
    assert!(!mixed.status.success());
    let err = String::from_utf8_lossy(&mixed.stderr);
    assert!(err.contains("one size, pitch and timing"), "{err}");
    assert!(
        !dir.path().join("b").exists(),
        "nothing written on a refusal"
    );
}
