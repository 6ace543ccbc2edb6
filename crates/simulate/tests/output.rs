//! Writing a simulation: SM4, GSF, NPY, PNG and the ground truth, read back.

mod common;

use common::{base_config, run};
use dhct_scan::ScanPass;
use dhct_simulate::effects::ThermalDrift;
use dhct_simulate::{EffectConfig, GroundTruth, OutputFormat};

#[test]
fn every_file_is_written_and_reads_back() {
    let mut config = base_config();
    config.noise.white_sigma_m = 1e-12;
    config.output.formats = vec![
        OutputFormat::Sm4,
        OutputFormat::Gsf,
        OutputFormat::Npy,
        OutputFormat::Png,
    ];
    config
        .effects
        .push(EffectConfig::ThermalDrift(ThermalDrift {
            velocity_m_per_s: [5e-12, 8e-12],
            acceleration_m_per_s2: [0.0, 0.0],
        }));
    let output = run(&config);
    let dir = tempfile::tempdir().unwrap();
    let written = output.write(dir.path()).unwrap();
    let names: Vec<String> = written
        .iter()
        .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    for name in [
        "simulation.sm4",
        "trace.gsf",
        "retrace.gsf",
        "trace.npy",
        "retrace.npy",
        "trace.json",
        "retrace.json",
        "trace.png",
        "retrace.png",
        "displacement_trace_dx.npy",
        "displacement_trace_dy.npy",
        "displacement_retrace_dx.npy",
        "displacement_retrace_dy.npy",
        "ground_truth.json",
    ] {
        assert!(
            names.iter().any(|n| n == name),
            "{name} missing from {names:?}"
        );
        assert!(dir.path().join(name).is_file());
    }

    // SM4: both passes, same geometry, values to the i32 quantisation.
    let file = dhct_sm4_io::read_path(&dir.path().join("simulation.sm4")).unwrap();
    let pair = file.topography().unwrap();
    let g = pair.geometry();
    assert_eq!((g.columns(), g.rows()), (128, 128));
    assert!((g.pitch_x() - common::PITCH).abs() < 1e-6 * common::PITCH);
    assert!((g.pixel_period() - output.pair.geometry().pixel_period()).abs() < 1e-9);
    for pass in ScanPass::BOTH {
        let (read, original) = (pair.image(pass).unwrap(), output.pair.image(pass).unwrap());
        let (low, high) = original.finite_range().unwrap();
        let worst = read
            .z
            .iter()
            .zip(original.z.iter())
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(worst < 1e-6 * (high - low), "{pass:?}: {worst}");
    }

    // GSF and NPY images.
    let gsf = dhct_sm4_io::read_path(&dir.path().join("retrace.gsf")).unwrap();
    let gsf_z = &gsf.pairs[0].images().next().unwrap().1.z;
    let retrace = &output.pair.retrace().unwrap().z;
    assert!(
        gsf_z
            .iter()
            .zip(retrace.iter())
            .all(|(a, b)| (a - b).abs() <= 1e-6 * b.abs().max(1e-12))
    );
    // The NPY's sidecar holds what NPY cannot: the pixel size and unit of the scan.
    let sidecar: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("trace.json")).unwrap())
            .unwrap();
    let geometry = output.pair.geometry();
    assert_eq!(
        sidecar["pixel_size_m"][0].as_f64(),
        Some(geometry.pitch_x())
    );
    assert_eq!(sidecar["unit"], "m");
    assert_eq!(sidecar["pass"], "trace");
    let npy = dhct_sm4_io::read_path(&dir.path().join("trace.npy")).unwrap();
    assert_eq!(
        &npy.pairs[0].images().next().unwrap().1.z,
        &output.pair.trace().unwrap().z
    );

    // Displacement fields, exactly.
    let dy = dhct_sm4_io::read_path(&dir.path().join("displacement_retrace_dy.npy")).unwrap();
    let field = output.truth.displacement_of(ScanPass::Retrace).unwrap();
    assert_eq!(dy.pairs[0].images().next().unwrap().1.z, field.dy.z);

    // The ground truth JSON is everything but the fields.
    let text = std::fs::read_to_string(dir.path().join("ground_truth.json")).unwrap();
    let read: GroundTruth = serde_json::from_str(&text).unwrap();
    let mut expected = output.truth.clone();
    expected.displacement.clear();
    assert_eq!(read, expected);
    assert!(text.contains("\"velocity_x_m_per_s\""));
    assert!(text.contains("\"controller_position_px\""));
}
