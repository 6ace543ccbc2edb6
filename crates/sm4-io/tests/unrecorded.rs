//! Lines a scan never recorded are read as missing, whatever the format.

use dhct_scan::{ImageChannel, ScanDirection, ScanGeometry};
use dhct_sm4_io::{UNRECORDED_LINES_KEY, gsf, read_bytes};
use ndarray::Array2;

/// A GSF file of 16 × 12 px with the slow direction `slow` whose rows `blank` hold `value`.
fn file(slow: ScanDirection, blank: std::ops::Range<usize>, value: f64) -> (Vec<u8>, Array2<f64>) {
    let mut z = Array2::from_shape_fn((12, 16), |(r, c)| {
        1e-10 * ((r * 16 + c) as f64 * 0.37).sin()
    });
    for r in blank {
        z.row_mut(r).fill(value);
    }
    let channel = ImageChannel::new("Z", "m", z.clone());
    let geometry =
        ScanGeometry::new(16, 12, 1e-10, 1e-10, 1e-3, ScanDirection::Right, slow).unwrap();
    let mut bytes = Vec::new();
    gsf::write(&channel, &geometry, &mut bytes).unwrap();
    (bytes, z)
}

/// Rows of the trace read back that are entirely NaN.
fn missing_rows(bytes: &[u8]) -> (Vec<usize>, Option<String>) {
    let scan = read_bytes(bytes).unwrap();
    let z = &scan.pairs[0].trace().unwrap().z;
    let rows = (0..z.nrows())
        .filter(|&r| z.row(r).iter().all(|v| v.is_nan()))
        .collect();
    (rows, scan.metadata.get(UNRECORDED_LINES_KEY).cloned())
}

#[test]
fn lines_after_the_scan_stopped_are_read_as_missing() {
    // Scanned downwards: the last lines are the bottom rows.
    let (bytes, z) = file(ScanDirection::Down, 8..12, 0.0);
    let (rows, note) = missing_rows(&bytes);
    assert_eq!(rows, vec![8, 9, 10, 11]);
    let note = note.expect("the metadata says which lines");
    assert!(note.contains("the last 4 of 12 lines"), "{note}");
    let back = read_bytes(&bytes).unwrap();
    let kept = &back.pairs[0].trace().unwrap().z;
    for r in 0..8 {
        for c in 0..16 {
            assert_eq!(kept[[r, c]], f64::from(z[[r, c]] as f32));
        }
    }
    // Scanned upwards: the last lines are the top rows.
    let (bytes, _) = file(ScanDirection::Up, 0..3, 5e-9);
    assert_eq!(missing_rows(&bytes).0, vec![0, 1, 2]);
}

#[test]
fn a_flat_line_within_the_scan_or_a_flat_image_is_data() {
    // Zeros in the middle of the frame, with recorded lines after them.
    let (bytes, _) = file(ScanDirection::Down, 5..7, 0.0);
    assert_eq!(missing_rows(&bytes), (vec![], None));
    // The first lines acquired (the top, scanning down) are not after the scan stopped.
    let (bytes, _) = file(ScanDirection::Down, 0..3, 0.0);
    assert_eq!(missing_rows(&bytes), (vec![], None));
    // A frame of one value throughout is left to the feature finder (a flat image).
    let (bytes, _) = file(ScanDirection::Down, 0..12, 0.0);
    assert_eq!(missing_rows(&bytes), (vec![], None));
}
