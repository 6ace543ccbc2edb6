//! WSxM reader: the real files in `tests/data/real` (two `.top`, one `.stp`), the 180°
//! storage rotation, and hostile inputs.

use std::path::PathBuf;

use dhct_scan::{FileFormat, ScanDirection, ScanPass, ValueSource};
use dhct_sm4_io::{ReadError, read_bytes, read_path};

fn real(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/data/real")
        .join(name)
}

#[test]
fn the_real_files_read_with_size_direction_timing_and_name() {
    // (file, pitch m, slow direction, line frequency Hz, z span m)
    let cases = [
        (
            "wsxm_jumpingmode_topography_15um.top",
            15e-6 / 256.0,
            ScanDirection::Down,
            0.543,
            338.867e-9,
        ),
        (
            "wsxm_topography_600nm.top",
            600e-9 / 256.0,
            ScanDirection::Up,
            1.628,
            18.8851e-9,
        ),
        (
            "wsxm_topography_600nm.stp",
            600e-9 / 256.0,
            ScanDirection::Up,
            1.628,
            13.7008e-9,
        ),
    ];
    for (name, pitch, slow, frequency, span) in cases {
        let file = read_path(&real(name)).unwrap();
        assert_eq!(file.format, FileFormat::Wsxm, "{name}");
        assert_eq!(file.pairs.len(), 1);
        let pair = file.topography().unwrap();
        assert_eq!(pair.name(), "Topography");
        let g = pair.geometry();
        assert_eq!((g.columns(), g.rows()), (256, 256));
        assert!((g.pitch_x() / pitch - 1.0).abs() < 1e-12, "{name}");
        assert!((g.pitch_y() / pitch - 1.0).abs() < 1e-12, "{name}");
        assert_eq!(g.fast_direction(ScanPass::Trace), ScanDirection::Right);
        assert_eq!(g.slow_direction(), slow, "{name}");
        assert!((g.line_scan_time() - 1.0 / (2.0 * frequency)).abs() < 1e-12);
        assert_eq!(g.scale_source(), ValueSource::Stated);
        assert_eq!(g.timing_source(), ValueSource::Stated);
        let trace = pair.trace().expect("forward scans are traces");
        assert!(pair.retrace().is_none());
        assert_eq!(trace.unit, "m");
        let (lo, hi) = trace.finite_range().unwrap();
        assert!(
            ((hi - lo) / span - 1.0).abs() < 1e-9,
            "{name}: {:e}",
            hi - lo
        );
    }
}

#[test]
fn the_stored_image_is_rotated_by_180_degrees_and_doubles_keep_their_nanometres() {
    // The .stp stores f64 nanometres whose range is exactly its Z Amplitude.
    let bytes = std::fs::read(real("wsxm_topography_600nm.stp")).unwrap();
    let start = bytes
        .windows(14)
        .position(|w| w == b"[Header end]\r\n")
        .unwrap()
        + 14;
    let stored: Vec<f64> = bytes[start..start + 256 * 256 * 8]
        .chunks_exact(8)
        .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
        .collect();
    let file = read_bytes(&bytes).unwrap();
    let z = &file.pairs[0].trace().unwrap().z;
    let scale = 13.7008e-9 / 13.700807033232238;
    for (r, c) in [(0, 0), (0, 255), (17, 3), (255, 0), (128, 200)] {
        let expected = stored[(255 - r) * 256 + (255 - c)] * scale;
        assert!((z[[r, c]] / expected - 1.0).abs() < 1e-12, "({r}, {c})");
    }
}

fn synthetic(header_extra: &str, data: &[i16]) -> Vec<u8> {
    let mut text = String::from(
        "WSxM file copyright UAM\r\nSxM Image file\r\nImage header size: 0\r\n\r\n[Control]\r\n\r\n",
    );
    text.push_str("    X Amplitude: 30 nm\r\n    Y Amplitude: 20 nm\r\n    X-Frequency: 2 Hz\r\n");
    text.push_str("\r\n[General Info]\r\n\r\n    Image Data Type: short\r\n");
    text.push_str("    Number of columns: 3\r\n    Number of rows: 2\r\n");
    text.push_str("    Z Amplitude: 5 Å\r\n");
    text.push_str(header_extra);
    text.push_str("\r\n[Header end]\r\n");
    let mut out: Vec<u8> = text.chars().map(|c| c as u32 as u8).collect();
    for v in data {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out
}

#[test]
fn a_backward_image_is_a_retrace_and_units_convert() {
    let file = read_bytes(&synthetic(
        "    X scanning direction: Backward\r\n    Y scanning direction: Down\r\n",
        &[0, 1, 2, 3, 4, 5],
    ))
    .unwrap();
    let pair = &file.pairs[0];
    assert!(pair.trace().is_none());
    let z = &pair.retrace().unwrap().z;
    // 5 Å over a span of 5 counts; stored 0..5 rotated by 180°.
    assert!((z[[0, 0]] - 5e-10).abs() < 1e-22 && z[[1, 2]].abs() < 1e-22);
    assert!((z[[1, 0]] - 2e-10).abs() < 1e-22);
    let g = pair.geometry();
    assert!((g.pitch_x() - 1e-8).abs() < 1e-20 && (g.pitch_y() - 1e-8).abs() < 1e-20);
    assert!((g.line_scan_time() - 0.25).abs() < 1e-12);
    assert_eq!(g.fast_direction(ScanPass::Retrace), ScanDirection::Left);
}

#[test]
fn missing_values_are_assumed_and_bad_ones_refused() {
    let unitless = synthetic("", &[0, 1, 2, 3, 4, 5]);
    let text = String::from_utf8_lossy(&unitless).replace("X Amplitude: 30 nm", "X Amplitude: 30");
    let file = read_bytes(text.as_bytes()).unwrap();
    let g = file.pairs[0].geometry();
    assert_eq!(g.scale_source(), ValueSource::Assumed);
    assert_eq!(g.timing_source(), ValueSource::Assumed, "no Y direction");
    assert!(file.metadata["assumed scale"].contains("Amplitude"));

    let constant = read_bytes(&synthetic("", &[7; 6])).unwrap_err();
    assert!(matches!(constant, ReadError::NoImage { .. }), "{constant}");
    let short = synthetic("", &[0, 1, 2]);
    assert!(matches!(
        read_bytes(&short).unwrap_err(),
        ReadError::Truncated { .. }
    ));
    let no_end = synthetic("", &[]);
    let cut = &no_end[..no_end.len() - 8];
    assert!(read_bytes(cut).is_err());
    let huge = String::from_utf8_lossy(&synthetic("", &[0; 6]))
        .replace("Number of columns: 3", "Number of columns: 99999999");
    assert!(matches!(
        read_bytes(huge.as_bytes()).unwrap_err(),
        ReadError::Corrupt { .. }
    ));
    let odd_type = String::from_utf8_lossy(&synthetic("", &[0; 6]))
        .replace("Image Data Type: short", "Image Data Type: complex");
    assert!(matches!(
        read_bytes(odd_type.as_bytes()).unwrap_err(),
        ReadError::Unsupported { .. }
    ));
}
