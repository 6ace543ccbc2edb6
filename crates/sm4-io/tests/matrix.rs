//! Omicron MATRIX reader: the real data/parameter pair in `tests/data/real`, the link
//! between them, stopped scans and hostile inputs.

use std::path::PathBuf;

use dhct_scan::{FileFormat, ScanDirection, ScanPass, ValueSource};
use dhct_sm4_io::{ReadError, ReadLimits, matrix, read_bytes, read_path};

const DATA: &str = "20201111--4_1.Z_mtrx";
const PARAMETERS: &str = "20201111_0001.mtrx";

fn real(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/data/real")
        .join(name)
}

#[test]
fn the_real_pair_reads_with_size_directions_timing_and_calibration() {
    let file = read_path(&real(DATA)).unwrap();
    assert_eq!(file.format, FileFormat::OmicronMatrix);
    assert_eq!(file.pairs.len(), 1, "forward/up and backward/up only");
    let z = file.topography().unwrap();
    assert_eq!(z.name(), "Z");
    let g = z.geometry();
    assert_eq!((g.columns(), g.rows()), (400, 400));
    assert!((g.width() - 100e-9).abs() < 1e-18 && (g.height() - 100e-9).abs() < 1e-18);
    assert!((g.pixel_period() - 0.5e-3).abs() < 1e-15);
    assert!((g.line_scan_time() - 0.2).abs() < 1e-12);
    assert_eq!(g.fast_direction(ScanPass::Trace), ScanDirection::Right);
    assert_eq!(g.fast_direction(ScanPass::Retrace), ScanDirection::Left);
    assert_eq!(g.slow_direction(), ScanDirection::Up);
    assert_eq!(g.scale_source(), ValueSource::Stated);
    assert_eq!(g.timing_source(), ValueSource::Stated);
    let (trace, retrace) = (z.trace().unwrap(), z.retrace().unwrap());
    assert_eq!(trace.unit, "m");
    assert_eq!(trace.non_finite_count() + retrace.non_finite_count(), 0);
    // Counts / 2.4e15 m: a few nanometres of steps around −0.51 µm.
    let (lo, hi) = trace.finite_range().unwrap();
    assert!(
        lo > -6e-7 && hi < -4e-7 && hi - lo > 5e-10,
        "{lo:e}..{hi:e}"
    );
    // The backward line, reversed to display order, matches its forward line.
    let row = 200;
    let diff: f64 = (0..400)
        .map(|c| (trace.z[[row, c]] - retrace.z[[row, c]]).abs())
        .sum::<f64>()
        / 400.0;
    let mirrored: f64 = (0..400)
        .map(|c| (trace.z[[row, c]] - retrace.z[[row, 399 - c]]).abs())
        .sum::<f64>()
        / 400.0;
    assert!(diff < mirrored, "{diff:e} vs {mirrored:e}");
    assert_eq!(file.metadata["bias"], "0.6000000000000001 Volt");
}

#[test]
fn a_data_file_without_its_parameter_file_names_the_missing_file() {
    let dir = tempfile::tempdir().unwrap();
    let copy = dir.path().join(DATA);
    std::fs::copy(real(DATA), &copy).unwrap();
    let error = read_path(&copy).unwrap_err();
    assert!(
        matches!(error, ReadError::MissingCompanion { .. }),
        "{error}"
    );
    assert!(error.to_string().contains(PARAMETERS), "{error}");
    // From memory, neither file alone is an image.
    let data = std::fs::read(real(DATA)).unwrap();
    let error = read_bytes(&data).unwrap_err();
    assert!(error.to_string().contains("_0001.mtrx"), "{error}");
    let parameters = std::fs::read(real(PARAMETERS)).unwrap();
    let error = read_path(&real(PARAMETERS)).unwrap_err();
    assert!(error.to_string().contains("parameter file"), "{error}");
    assert!(read_bytes(&parameters).is_err());
    // A renamed data file is not in the journal.
    let error = matrix::read_pair(
        &data,
        "20201111--9_9.Z_mtrx",
        &parameters,
        &ReadLimits::default(),
    )
    .unwrap_err();
    assert!(error.to_string().contains("never mentions"), "{error}");
}

#[test]
fn a_stopped_scan_keeps_its_frame_with_the_lines_never_scanned_as_nan() {
    let mut data = std::fs::read(real(DATA)).unwrap();
    let parameters = std::fs::read(real(PARAMETERS)).unwrap();
    // The CSED count of stored values is at bytes 24..28 of its content: keep 100.5 line pairs.
    let csed = data.windows(4).position(|w| w == b"CSED").unwrap() + 8;
    data[csed + 24..csed + 28].copy_from_slice(&(400 * 2 * 100 + 200i32).to_le_bytes());
    let file = matrix::read_pair(&data, DATA, &parameters, &ReadLimits::default()).unwrap();
    let trace = file.pairs[0].trace().unwrap();
    assert_eq!((trace.rows(), trace.columns()), (400, 400));
    assert_eq!(
        trace.non_finite_count(),
        300 * 400,
        "only the 100 complete lines"
    );
    assert!(trace.z[[299, 0]].is_nan() && trace.z[[300, 0]].is_finite());
    assert!(file.metadata["incomplete scan"].contains("100 of 400"));
    // A count beyond the stored bytes is a truncation.
    data[csed + 24..csed + 28].copy_from_slice(&i32::MAX.to_le_bytes());
    let error = matrix::read_pair(&data, DATA, &parameters, &ReadLimits::default()).unwrap_err();
    assert!(matches!(error, ReadError::Truncated { .. }), "{error}");
}
