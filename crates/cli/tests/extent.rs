//! Features that the correction moves outside the frame are counted and said: the corrected
//! image (cropped to the raw frame) does not show them, `features.csv` keeps them.

mod common;

use common::{correct, dhct};
use serde_json::Value;

#[test]
fn features_moved_outside_the_frame_are_counted() {
    let dir = tempfile::tempdir().unwrap();
    // A drift along the slow scan stretches the raw lattice: corrected, the lowest rows'
    // features lie beyond the frame.
    let sim = dir.path().join("sim");
    let made = dhct()
        .args(["simulate", "--preset", "fig3c-drift-along-slow", "-o"])
        .arg(&sim)
        .output()
        .unwrap();
    assert!(
        made.status.success(),
        "{}",
        String::from_utf8_lossy(&made.stderr)
    );
    let out = dir.path().join("out");
    let run = correct(
        &sim.join("simulation.sm4"),
        &["--lattice", "hexagonal", "--nn", "1nm"],
        &out,
    );
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let model: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("model.json")).unwrap()).unwrap();
    let geometry = &model["geometry"];
    let (columns, rows) = (
        geometry["columns"].as_f64().unwrap(),
        geometry["rows"].as_f64().unwrap(),
    );
    let (px, py) = (
        geometry["pitch_x_m"].as_f64().unwrap(),
        geometry["pitch_y_m"].as_f64().unwrap(),
    );
    let csv = std::fs::read_to_string(out.join("features.csv")).unwrap();
    let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let (pass, cx, cy) = (col("pass"), col("corrected_x_m"), col("corrected_y_m"));
    for p in model["passes"].as_array().unwrap() {
        let name = p["pass"].as_str().unwrap();
        let outside = csv
            .lines()
            .skip(1)
            .map(|l| l.split(',').collect::<Vec<_>>())
            .filter(|v| v[pass] == name)
            .filter(|v| {
                let x = v[cx].parse::<f64>().unwrap() / px;
                let y = v[cy].parse::<f64>().unwrap() / py;
                !(-0.5..=columns - 0.5).contains(&x) || !(-0.5..=rows - 0.5).contains(&y)
            })
            .count();
        assert!(
            outside > 0,
            "{name}: the drift should move some features out"
        );
        assert_eq!(p["outside_frame"].as_u64(), Some(outside as u64), "{name}");
    }
}
