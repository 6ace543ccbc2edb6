//! NPY files read with the JSON sidecar dhct writes beside them: geometry, channel and unit
//! come back, trace and retrace pair up from either file, and sidecars that contradict the
//! array or describe another scan are refused or left unpaired, each with its reason.

use std::path::Path;

use dhct_scan::{ImageChannel, ScanDirection, ScanGeometry, ScanPass, ValueSource};
use dhct_sm4_io::{ReadError, npy, read_path};
use ndarray::Array2;

fn geometry() -> ScanGeometry {
    ScanGeometry::new(
        5,
        3,
        1.5e-11,
        2e-11,
        3e-5,
        ScanDirection::Right,
        ScanDirection::Down,
    )
    .unwrap()
}

/// Writes `NAME.npy` and its sidecar for `pass` of `geometry`.
fn write_pass(dir: &Path, name: &str, pass: ScanPass, geometry: &ScanGeometry) -> ImageChannel {
    let offset = if pass == ScanPass::Trace { 0.0 } else { 100.0 };
    let z = Array2::from_shape_fn((geometry.rows(), geometry.columns()), |(r, c)| {
        offset + (10 * r + c) as f64
    });
    let channel = ImageChannel::new("Topography", "m", z);
    let mut bytes = Vec::new();
    npy::write(&channel, &mut bytes).unwrap();
    std::fs::write(dir.join(format!("{name}.npy")), bytes).unwrap();
    let sidecar = npy::Sidecar::new(&channel, geometry, pass, Vec::new());
    std::fs::write(
        dir.join(format!("{name}.json")),
        serde_json::to_string_pretty(&sidecar).unwrap(),
    )
    .unwrap();
    channel
}

#[test]
fn a_trace_and_its_retrace_come_back_with_their_geometry_from_either_file() {
    let dir = tempfile::tempdir().unwrap();
    let trace = write_pass(dir.path(), "scan_trace", ScanPass::Trace, &geometry());
    let retrace = write_pass(dir.path(), "scan_retrace", ScanPass::Retrace, &geometry());
    for name in ["scan_trace.npy", "scan_retrace.npy"] {
        let file = read_path(&dir.path().join(name)).unwrap();
        let pair = file.topography().unwrap();
        let g = pair.geometry();
        assert_eq!(
            (g.pitch_x(), g.pitch_y(), g.pixel_period()),
            (1.5e-11, 2e-11, 3e-5)
        );
        assert_eq!(g.scale_source(), ValueSource::Stated);
        assert_eq!(g.timing_source(), ValueSource::Stated);
        assert_eq!(pair.trace().unwrap(), &trace, "{name}");
        assert_eq!(pair.retrace().unwrap(), &retrace, "{name}");
        assert!(
            !file.metadata.contains_key("assumed scale"),
            "{:?}",
            file.metadata
        );
        assert!(file.metadata["npy pairing"].contains("other pass read from"));
    }
}

#[test]
fn a_sidecar_of_another_scan_is_not_paired_and_a_contradicting_one_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    write_pass(dir.path(), "trace", ScanPass::Trace, &geometry());
    let other = geometry().with_pitch(1e-11, 1e-11).unwrap();
    write_pass(dir.path(), "retrace", ScanPass::Retrace, &other);
    let file = read_path(&dir.path().join("trace.npy")).unwrap();
    let pair = file.topography().unwrap();
    assert!(pair.retrace().is_none());
    assert!(
        file.metadata["npy pairing"].contains("not paired"),
        "{:?}",
        file.metadata
    );

    // A sidecar whose shape is not the array's.
    let text = std::fs::read_to_string(dir.path().join("trace.json")).unwrap();
    let wrong = text.replacen("\"shape\": [\n    3,", "\"shape\": [\n    4,", 1);
    assert_ne!(wrong, text);
    std::fs::write(dir.path().join("trace.json"), wrong).unwrap();
    match read_path(&dir.path().join("trace.npy")) {
        Err(ReadError::Corrupt { reason, .. }) => {
            assert!(
                reason.contains("trace.json") && reason.contains("5 x 4 px"),
                "{reason}"
            )
        }
        other => panic!("expected a sidecar error, got {other:?}"),
    }
}

#[test]
fn a_json_file_that_is_no_sidecar_leaves_the_geometry_assumed() {
    let dir = tempfile::tempdir().unwrap();
    write_pass(dir.path(), "image", ScanPass::Trace, &geometry());
    std::fs::write(dir.path().join("image.json"), "{\"sample\": \"HOPG\"}").unwrap();
    let file = read_path(&dir.path().join("image.npy")).unwrap();
    let g = file.topography().unwrap().geometry();
    assert_eq!(g.scale_source(), ValueSource::Assumed);
    assert!(file.metadata.contains_key("assumed scale"));
    // Nor does a large or binary file of that name stop the array from being read.
    for content in [vec![b' '; 1 << 20], vec![0xff, 0xfe, 0x00, 0x93]] {
        std::fs::write(dir.path().join("image.json"), content).unwrap();
        let file = read_path(&dir.path().join("image.npy")).unwrap();
        let g = file.topography().unwrap().geometry();
        assert_eq!(g.scale_source(), ValueSource::Assumed);
    }
}
