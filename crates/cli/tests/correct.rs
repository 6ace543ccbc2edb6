//! `dhct correct` and `dhct batch` run as a user would: on the embedded simulated example
//! (compared with its known distortion), on the vendored HOPG file with a config, on the real
//! files in `DHCT_REAL_DATA`, on bad input; the report is checked for completeness and, when
//! Chromium is installed, rendered headless and looked at.

use std::path::PathBuf;
use std::process::{Command, Output};

use serde_json::Value;

fn dhct() -> Command {
    Command::new(env!("CARGO_BIN_EXE_dhct"))
}

fn workspace_file(relative: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests")
        .join(relative)
}

fn ok(output: &Output) -> String {
    let stdout = String::from_utf8_lossy(&output.stdout).to_string();
    assert!(
        output.status.success(),
        "exit {:?}\nstdout: {stdout}\nstderr: {}",
        output.status.code(),
        String::from_utf8_lossy(&output.stderr)
    );
    stdout
}

fn parameter(model: &Value, name: &str) -> (f64, f64) {
    let p = model["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p["name"] == name)
        .unwrap_or_else(|| panic!("no parameter {name}"));
    (
        p["value"].as_f64().unwrap(),
        p["sigma"].as_f64().unwrap_or(f64::NAN),
    )
}

/// Every file the README and the issue promise.
const OUTPUTS: [&str; 13] = [
    "corrected_trace.tiff",
    "corrected_trace.gsf",
    "corrected_trace.png",
    "corrected_retrace.tiff",
    "features.csv",
    "model.json",
    "config.toml",
    "report.html",
    "unit_cell_averaged.tiff",
    "unit_cell_symmetrized.png",
    "deviation_map.png",
    "hysteresis.svg",
    "rdf.svg",
];

#[test]
fn correct_embedded_example_recovers_the_simulated_distortion() {
    let out = tempfile::tempdir().unwrap();
    let input = workspace_file("data/simulated_graphite.sm4");
    let stdout = ok(&dhct()
        .args(["correct", "--quiet", "--json"])
        .arg(&input)
        .arg("-o")
        .arg(out.path())
        .output()
        .unwrap());
    let summary: Value = serde_json::from_str(&stdout).expect("--json prints JSON");
    for name in OUTPUTS {
        assert!(out.path().join(name).is_file(), "missing {name}");
    }
    // No temporary files are left behind.
    for entry in std::fs::read_dir(out.path()).unwrap() {
        let name = entry.unwrap().file_name().to_string_lossy().to_string();
        assert!(!name.ends_with(".tmp"), "left over {name}");
    }
    let model: Value =
        serde_json::from_str(&std::fs::read_to_string(out.path().join("model.json")).unwrap())
            .unwrap();
    assert_eq!(model["parameters"], summary["parameters"]);

    // The simulation (ci-small preset): drift (5, −8) pm/s, creep C = (0.1, 0.2) nm, t0 = 20 s,
    // hysteresis k = 0.95, n = −0.03. Every parameter within 3σ.
    for (name, truth) in [
        ("v_x", 5e-12),
        ("v_y", -8e-12),
        ("C_x", 0.1e-9),
        ("C_y", 0.2e-9),
        ("t0", 20.0),
        ("k", 0.95),
        ("n", -0.03),
    ] {
        let (value, sigma) = parameter(&model, name);
        assert!(
            (value - truth).abs() < 3.0 * sigma,
            "{name}: {value} ± {sigma}, truth {truth}"
        );
    }
    // The corrected lattice is graphite's to 0.1 %, every feature is indexed, the ellipse is
    // at the pm level, the unit cell was averaged in p3m1.
    let region = &model["regions"][0];
    for k in 0..2 {
        let a = region["lattice_constant_m"][k].as_f64().unwrap();
        assert!((a - 2.46e-10).abs() < 2.46e-13, "a[{k}] = {a}");
    }
    assert!(region["whole_ellipse"]["sigma_major_m"].as_f64().unwrap() < 3e-12);
    assert_eq!(model["unit_cell"]["group"], "p3m1");
    let features: usize = model["passes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["features"].as_u64().unwrap() as usize)
        .sum();
    let indexed: usize = model["passes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["indexed"].as_u64().unwrap() as usize)
        .sum();
    assert!(indexed as f64 >= 0.98 * features as f64);

    // features.csv: one row per feature with lattice indices and deviations.
    let csv = std::fs::read_to_string(out.path().join("features.csv")).unwrap();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    for column in [
        "time_s",
        "line_time_s",
        "corrected_x_m",
        "n",
        "m",
        "deviation_x_m",
    ] {
        assert!(header.contains(&column), "no column {column}");
    }
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), features);
    let n_column = header.iter().position(|c| *c == "n").unwrap();
    assert!(rows.iter().filter(|r| !r[n_column].is_empty()).count() == indexed);
    assert!(rows.iter().all(|r| r.len() == header.len()));

    // The corrected images read back with the scan's size (TIFF float, GSF for Gwyddion).
    for name in ["corrected_trace.tiff", "corrected_trace.gsf"] {
        let file = dhct_sm4_io::read_path(&out.path().join(name)).unwrap();
        let pair = file.topography().unwrap();
        assert_eq!(pair.trace().unwrap().z.dim(), (256, 256), "{name}");
    }

    // The report is one self-contained page with every promised section.
    let html = std::fs::read_to_string(out.path().join("report.html")).unwrap();
    for needle in [
        "Raw trace image",
        "Corrected trace image",
        "Normalised cross-correlation",
        "Radial distribution function (paper Fig. 6)",
        "Angular distribution (ADF, paper Fig. S2)",
        "Local distortion (paper Fig. 7)",
        "Hysteresis fit (paper Fig. 8)",
        "Drift and creep along x (paper Fig. 9)",
        "Deviation heat map (paper Fig. S3)",
        "Lattice fit overlay (paper Fig. S4)",
        "Translationally averaged unit cell (paper Fig. 10)",
        "Symmetry-averaged unit cell, p3m1 (paper Fig. 11)",
        "Averaged cell over the lattice (paper Fig. 10a)",
        "Symmetry-averaged cell over the lattice, p3m1 (paper Fig. 11a)",
        "Confidence ellipses",
        "data:image/png;base64,",
        "<svg",
    ] {
        assert!(html.contains(needle), "report lacks {needle}");
    }
    assert!(
        !html.contains("src='http") && !html.contains("<script"),
        "report is not self-contained"
    );

    // The resolved config repeats the run exactly.
    let again = tempfile::tempdir().unwrap();
    ok(&dhct()
        .args(["correct", "--quiet", "--config"])
        .arg(out.path().join("config.toml"))
        .arg(&input)
        .arg("-o")
        .arg(again.path())
        .output()
        .unwrap());
    let repeat: Value =
        serde_json::from_str(&std::fs::read_to_string(again.path().join("model.json")).unwrap())
            .unwrap();
    assert_eq!(repeat["parameters"], model["parameters"]);
    // Rendering in a browser: tests/report.rs.
}

#[test]
fn correct_hopg_terrace_with_config() {
    let out = tempfile::tempdir().unwrap();
    let stdout = ok(&dhct()
        .args(["correct", "--quiet", "--config"])
        .arg(workspace_file("data/hopg_terrace.toml"))
        .arg(workspace_file("data/hopg_graphiteterrace.spm"))
        .arg("-o")
        .arg(out.path())
        .output()
        .unwrap());
    println!("{stdout}");
    let model: Value =
        serde_json::from_str(&std::fs::read_to_string(out.path().join("model.json")).unwrap())
            .unwrap();
    let region = &model["regions"][0];
    for k in 0..2 {
        let a = region["lattice_constant_m"][k].as_f64().unwrap();
        assert!((a - 2.46e-10).abs() < 0.04 * 2.46e-10, "a[{k}] = {a}");
    }
    // Of the three-fold groups the averaged HOPG cell is closest to p3m1.
    let residual = |g: &str| {
        model["unit_cell"]["residuals"]
            .as_array()
            .unwrap()
            .iter()
            .find(|r| r["group"] == g)
            .unwrap()["residual"]
            .as_f64()
            .unwrap()
    };
    assert!(residual("p3m1") < residual("p31m"));
}

#[test]
fn correct_real_files() {
    let Some(dir) = std::env::var_os("DHCT_REAL_DATA") else {
        println!("skipping: DHCT_REAL_DATA is not set (CI sets it to ../shared/data)");
        return;
    };
    let dir = PathBuf::from(dir);
    // TiSe2: the file's pixel size makes the visible NN spacing 2.6 Å (not 3.54 Å).
    for (file, args) in [
        (
            "tise2_nanonis_generic_5e.sxm",
            vec!["--lattice", "hexagonal", "--nn", "2.6A"],
        ),
        (
            "pb_pt111_2023-06-01-0087.SM4",
            vec!["--lattice", "hexagonal", "--nn", "1.3nm"],
        ),
    ] {
        let out = tempfile::tempdir().unwrap();
        let stdout = ok(&dhct()
            .args(["correct", "--quiet"])
            .arg(dir.join(file))
            .args(&args)
            .arg("-o")
            .arg(out.path())
            .output()
            .unwrap());
        println!("{file}:\n{stdout}");
        let model: Value =
            serde_json::from_str(&std::fs::read_to_string(out.path().join("model.json")).unwrap())
                .unwrap();
        let nn = dhct_features_nn(&args);
        let region = &model["regions"][0];
        for k in 0..2 {
            let a = region["lattice_constant_m"][k].as_f64().unwrap();
            assert!((a - nn).abs() < 0.05 * nn, "{file}: a[{k}] = {a}");
        }
        assert!(out.path().join("report.html").is_file());
    }
    // A wrong NN distance gives a clear error that names the distance the image shows and
    // suggests it (or --calibrate when the constant is right and the pixel size wrong).
    let out = tempfile::tempdir().unwrap();
    let output = dhct()
        .args([
            "correct",
            "--quiet",
            "--lattice",
            "hexagonal",
            "--nn",
            "3.54A",
        ])
        .arg(dir.join("tise2_nanonis_generic_5e.sxm"))
        .arg("-o")
        .arg(out.path())
        .output()
        .unwrap();
    assert_eq!(output.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("in file units")
            && stderr.contains("use --nn 2.")
            && stderr.contains("--calibrate"),
        "{stderr}"
    );
}

fn dhct_features_nn(args: &[&str]) -> f64 {
    let i = args.iter().position(|a| *a == "--nn").unwrap();
    let text = args[i + 1];
    if let Some(a) = text.strip_suffix('A') {
        a.parse::<f64>().unwrap() * 1e-10
    } else {
        text.strip_suffix("nm").unwrap().parse::<f64>().unwrap() * 1e-9
    }
}

#[test]
fn bad_input_fails_clearly() {
    let out = tempfile::tempdir().unwrap();
    let missing = dhct()
        .args(["correct", "no/such/file.sm4", "-o"])
        .arg(out.path())
        .output()
        .unwrap();
    assert_eq!(missing.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&missing.stderr).contains("no/such/file.sm4"));

    let junk = out.path().join("junk.sm4");
    std::fs::write(&junk, b"this is not an STM file at all").unwrap();
    let output = dhct()
        .arg("correct")
        .arg(&junk)
        .arg("-o")
        .arg(out.path().join("o"))
        .output()
        .unwrap();
    assert_eq!(output.status.code(), Some(1));
    assert!(!String::from_utf8_lossy(&output.stderr).contains("panicked"));

    let output = dhct()
        .args(["correct", "--lattice", "lieb"])
        .arg(workspace_file("data/simulated_graphite.sm4"))
        .arg("-o")
        .arg(out.path().join("o2"))
        .output()
        .unwrap();
    assert_eq!(output.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&output.stderr).contains("unknown lattice"));
    assert!(!out.path().join("o2/report.html").exists());

    let output = dhct()
        .args(["correct", "--nn", "banana"])
        .arg(workspace_file("data/simulated_graphite.sm4"))
        .arg("-o")
        .arg(out.path().join("o3"))
        .output()
        .unwrap();
    assert_eq!(output.status.code(), Some(2));
}

#[test]
fn batch_continues_past_a_bad_file() {
    let input = tempfile::tempdir().unwrap();
    std::fs::copy(
        workspace_file("data/simulated_graphite.sm4"),
        input.path().join("good.sm4"),
    )
    .unwrap();
    // An SM4 cut short: recognised by its header, then refused by the reader.
    let bytes = std::fs::read(workspace_file("data/simulated_graphite.sm4")).unwrap();
    std::fs::write(input.path().join("bad.sm4"), &bytes[..bytes.len() / 3]).unwrap();
    let out = tempfile::tempdir().unwrap();
    let output = dhct()
        .args(["batch", "--quiet"])
        .arg(input.path())
        .arg("-o")
        .arg(out.path())
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert_eq!(output.status.code(), Some(1), "{stdout}");
    assert!(
        stdout.contains("FAILED") && stdout.contains("bad.sm4"),
        "{stdout}"
    );
    assert!(out.path().join("good/report.html").is_file());
    let table = std::fs::read_to_string(out.path().join("summary.csv")).unwrap();
    assert_eq!(table.lines().count(), 3, "{table}");
    assert!(
        table
            .lines()
            .any(|l| l.contains("good.sm4") && l.contains(",ok,"))
    );
    assert!(
        table
            .lines()
            .any(|l| l.contains("bad.sm4") && l.contains(",failed,"))
    );
}

#[test]
fn correct_with_diagnosis_adds_the_gap_section() {
    let out = tempfile::tempdir().unwrap();
    ok(&dhct()
        .args(["correct", "--quiet", "--diagnose"])
        .arg(workspace_file("data/simulated_graphite.sm4"))
        .arg("-o")
        .arg(out.path())
        .output()
        .unwrap());
    let diagnosis: Value =
        serde_json::from_str(&std::fs::read_to_string(out.path().join("diagnosis.json")).unwrap())
            .unwrap();
    // The gap is measured against an independent noise floor and is near it for this
    // simulation of exactly the base model's effects.
    let gap = diagnosis["base"]["gap"]["gap_to_noise"].as_f64().unwrap();
    assert!(gap > 0.5 && gap < 1.5, "gap/noise {gap}");
    let html = std::fs::read_to_string(out.path().join("report.html")).unwrap();
    for needle in [
        "Sim-to-real gap diagnosis",
        "Gap against frame time",
        "Spectrum of the residuals",
        "Where the gap lies (map)",
        "The image minus the rendered model (trace)",
        "Image residual against the fast phase",
    ] {
        assert!(html.contains(needle), "report lacks {needle}");
    }
    assert!(out.path().join("diagnosis_map.png").is_file());
    // The residual images as data: float TIFFs, and their summaries in the JSON.
    for pass in ["trace", "retrace"] {
        assert!(out.path().join(format!("residual_{pass}.tiff")).is_file());
    }
    let passes = diagnosis["image_residual"].as_array().unwrap();
    assert_eq!(passes.len(), 2);
    for p in passes {
        let rms = p["rms_over_noise"].as_f64().unwrap();
        assert!(rms > 0.8 && rms < 1.5, "residual rms / pixel noise {rms}");
    }
}
