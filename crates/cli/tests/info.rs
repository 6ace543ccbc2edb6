//! `dhct info` run as a user would: on the vendored real ISO 28600 file, on junk, with --json.

use std::path::PathBuf;
use std::process::Command;

fn dhct() -> Command {
    Command::new(env!("CARGO_BIN_EXE_dhct"))
}

fn workspace_file(relative: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests")
        .join(relative)
}

#[test]
fn info_describes_the_vendored_graphite_file() {
    let output = dhct()
        .arg("info")
        .arg(workspace_file("data/hopg_graphiteterrace.spm"))
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
    assert!(stdout.contains("ISO 28600"), "{stdout}");
    assert!(stdout.contains("512 x 512 px"), "{stdout}");
    assert!(stdout.contains("11.4807 nm"), "{stdout}");
    assert!(
        stdout.contains("assumed"),
        "timing is not in the file: {stdout}"
    );
}

#[test]
fn info_json_is_machine_readable_and_honours_overrides() {
    let output = dhct()
        .args(["info", "--json", "--line-time", "0.5s"])
        .arg(workspace_file("data/hopg_graphiteterrace.spm"))
        .output()
        .unwrap();
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let summary: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
    let geometry = &summary["channels"][0]["geometry"];
    assert_eq!(geometry["columns"], 512);
    assert_eq!(geometry["timing_source"], "stated");
    let period = geometry["pixel_period_s"].as_f64().unwrap();
    assert!((period - 0.5 / 512.0).abs() < 1e-12, "{period}");
}

#[test]
fn info_rejects_foreign_and_missing_files_with_a_clear_message() {
    let dir = tempfile::tempdir().unwrap();
    let junk = dir.path().join("notes.txt");
    std::fs::write(&junk, "not an STM file").unwrap();
    let output = dhct().arg("info").arg(&junk).output().unwrap();
    assert_eq!(output.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("notes.txt") && stderr.contains("unrecognised file format"),
        "{stderr}"
    );

    let output = dhct()
        .arg("info")
        .arg(dir.path().join("missing.sm4"))
        .output()
        .unwrap();
    assert_eq!(output.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&output.stderr).contains("No such file"));

    let output = dhct()
        .args(["info", "--fast", "sideways", "x"])
        .output()
        .unwrap();
    assert_eq!(
        output.status.code(),
        Some(2),
        "malformed command lines exit with 2"
    );
}
