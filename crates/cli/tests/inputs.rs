//! Wrong inputs stop the run with the value the image shows: a wrong `--nn` (0.5, 0.7, 1.4
//! and 2 × the truth), a wrong lattice (square on graphite, hexagonal on a square lattice),
//! a corrupted pixel size; and the explicit ways out (`--calibrate`, `--nn auto`,
//! `--trust-inputs`) do what they say.

mod common;

use std::path::{Path, PathBuf};
use std::process::Output;

use common::{correct, dhct};

use serde_json::Value;

fn example() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/data/simulated_graphite.sm4")
}

/// Fails, without a panic, with every `needles` in stderr.
fn fails_saying(output: &Output, needles: &[&str]) -> String {
    let stderr = String::from_utf8_lossy(&output.stderr).to_string();
    assert!(!output.status.success(), "exit 0; stderr: {stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    for needle in needles {
        assert!(stderr.contains(needle), "no '{needle}' in: {stderr}");
    }
    stderr
}

#[test]
fn a_wrong_nn_stops_with_the_distance_the_image_shows() {
    let dir = tempfile::tempdir().unwrap();
    for factor in [0.5, 0.7, 1.4, 2.0] {
        let nn = format!("{:.4}A", 2.46 * factor);
        let output = correct(&example(), &["--nn", &nn], &dir.path().join("out"));
        let stderr = fails_saying(
            &output,
            &[
                "nearest-neighbour distance is 2.5",
                "in file units",
                "cannot match",
            ],
        );
        assert!(
            stderr.contains("--calibrate") && stderr.contains("--nn 2.5"),
            "{stderr}"
        );
    }
}

#[test]
fn a_wrong_lattice_stops_with_what_the_image_shows() {
    let dir = tempfile::tempdir().unwrap();
    let output = correct(
        &example(),
        &["--lattice", "square", "--nn", "2.46A"],
        &dir.path().join("out"),
    );
    fails_saying(
        &output,
        &["the image shows", "square lattice cannot match it"],
    );

    // A square lattice, simulated, read as hexagonal.
    let config = dhct()
        .args(["simulate", "--preset", "ci-small", "--print-config"])
        .output()
        .unwrap();
    let text = String::from_utf8(config.stdout)
        .unwrap()
        .replace("kind = \"graphite\"", "kind = \"square\"\na_m = 3.6e-10");
    let config_path = dir.path().join("square.toml");
    std::fs::write(&config_path, text).unwrap();
    let simulated = dir.path().join("square");
    let run = dhct()
        .arg("simulate")
        .arg(&config_path)
        .arg("-o")
        .arg(&simulated)
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let image = std::fs::read_dir(&simulated)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|e| e == "sm4"))
        .expect("an SM4 file");
    let output = correct(
        &image,
        &["--lattice", "hexagonal", "--nn", "3.6A"],
        &dir.path().join("out2"),
    );
    fails_saying(
        &output,
        &["the image shows", "hexagonal lattice cannot match it"],
    );
    // The right lattice passes the check.
    let output = correct(
        &image,
        &["--lattice", "square", "--nn", "3.6A", "--json"],
        &dir.path().join("out3"),
    );
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
}

#[test]
fn a_corrupted_pixel_size_stops_with_the_measured_distance() {
    let dir = tempfile::tempdir().unwrap();
    // The file says 4 nm over 256 px (15.6 pm); a pixel size 10× too large.
    let output = correct(&example(), &["--pitch", "156pm"], &dir.path().join("out"));
    fails_saying(&output, &["in file units", "wrong by a factor"]);
}

fn model(out: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(out.join("model.json")).unwrap()).unwrap()
}

#[test]
fn the_explicit_ways_out_do_what_they_say() {
    let dir = tempfile::tempdir().unwrap();
    // --calibrate: the constant is right, the pixel size wrong by 1.4.
    let out = dir.path().join("calibrate");
    let output = correct(&example(), &["--nn", "3.444A", "--calibrate"], &out);
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let m = model(&out);
    let scale = m["calibration"]["calibration"]["mean_scale"]
        .as_f64()
        .unwrap();
    assert!((scale - 2.56 / 3.444).abs() < 0.03, "mean scale {scale}");
    assert!(
        m["warnings"]
            .as_array()
            .unwrap()
            .iter()
            .any(|w| w["code"] == "pixel_size_calibrated" && w["what_to_do"].is_string())
    );

    // --nn auto on a lattice without a constant.
    let out = dir.path().join("auto");
    let output = correct(
        &example(),
        &["--lattice", "hexagonal", "--nn", "auto"],
        &out,
    );
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let nn = model(&out)["nearest_neighbour_distance_m"]
        .as_f64()
        .unwrap();
    assert!((nn / 2.46e-10 - 1.0).abs() < 0.06, "nn {nn}");

    // --trust-inputs: no check, and the report says the inputs were not checked.
    let out = dir.path().join("trust");
    let output = correct(&example(), &["--nn", "2.3A", "--trust-inputs"], &out);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!stderr.contains("cannot match"), "{stderr}");
    if output.status.success() {
        assert!(
            model(&out)["warnings"]
                .as_array()
                .unwrap()
                .iter()
                .any(|w| w["code"] == "lattice_not_measured")
        );
    }
}

#[test]
fn assumed_timing_is_a_warning_with_what_to_do() {
    let dir = tempfile::tempdir().unwrap();
    let hopg = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/data");
    let out = dir.path().join("hopg");
    let output = correct(
        &hopg.join("hopg_graphiteterrace.spm"),
        &["--config", hopg.join("hopg_terrace.toml").to_str().unwrap()],
        &out,
    );
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("assumed_timing"), "{stderr}");
    let m = model(&out);
    let warnings = m["warnings"].as_array().unwrap();
    let timing = warnings
        .iter()
        .find(|w| w["code"] == "assumed_timing")
        .expect("an assumed-timing warning");
    // model.json names the inputs (not a flag); stderr adds the flags.
    assert_eq!(timing["inputs"][0], "line_time", "{timing}");
    assert!(
        stderr.contains("[options: --line-time, --pixel-period]"),
        "{stderr}"
    );
    // The affine floor is reported with the same measure as the model.
    let baseline = &m["affine_baseline"][0];
    assert!(baseline["model_rms_m"].as_f64().unwrap() > 0.0);
    assert!(baseline["affine_rms_m"].as_f64().unwrap() > 0.0);
}

#[test]
fn the_read_budget_is_a_flag() {
    let info = |args: &[&str]| {
        dhct()
            .args(args)
            .arg("info")
            .arg(example())
            .output()
            .expect("dhct runs")
    };
    let refused = info(&["--max-read-bytes", "1KiB"]);
    assert!(!refused.status.success());
    assert!(String::from_utf8_lossy(&refused.stderr).contains("read limit of 1024 bytes"));
    let refused = info(&["--max-read-pixels", "1000"]);
    assert!(String::from_utf8_lossy(&refused.stderr).contains("read limit of 1000 pixels"));
    assert!(info(&["--max-read-bytes", "3GiB"]).status.success());
    assert!(!info(&["--max-read-bytes", "3XB"]).status.success());
}

#[test]
fn a_preset_takes_a_head_off_by_40_percent_but_not_by_a_factor_2() {
    let dir = tempfile::tempdir().unwrap();
    // The file's pixel size is 15.625 pm: with the graphite preset named, 40 % smaller and
    // 40 % larger pass (calibrated from the lattice, with a warning), twice as large stops.
    for (pitch, name) in [("9.375pm", "small"), ("21.875pm", "large")] {
        let out = dir.path().join(name);
        let output = correct(
            &example(),
            &["--lattice", "graphite", "--pitch", pitch],
            &out,
        );
        assert!(
            output.status.success(),
            "{pitch}: {}",
            String::from_utf8_lossy(&output.stderr)
        );
        let model: Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("model.json")).unwrap())
                .unwrap();
        let a = model["regions"][0]["lattice_constant_m"][0]
            .as_f64()
            .unwrap();
        assert!((a / 2.46e-10 - 1.0).abs() < 0.01, "{pitch}: a = {a}");
    }
    let output = correct(
        &example(),
        &["--lattice", "graphite", "--pitch", "31.25pm"],
        &dir.path().join("double"),
    );
    fails_saying(&output, &["wrong by a factor 2.", "in file units"]);
    // A lattice nobody named is an assumption: it never rescales the pixel size beyond a
    // typed constant's 15 %.
    let output = correct(
        &example(),
        &["--pitch", "9.375pm"],
        &dir.path().join("unnamed"),
    );
    fails_saying(&output, &["wrong by a factor 0.6", "in file units"]);
}
