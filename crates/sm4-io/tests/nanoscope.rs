//! Bruker/Veeco Nanoscope reader: synthetic files written here, the two real files in
//! `tests/data/real` (Bruker's own example and the nanoscope project's test file), and
//! hostile inputs.

use std::path::{Path, PathBuf};

use dhct_scan::{FileFormat, ScanDirection, ScanPass, ValueSource};
use dhct_sm4_io::{ASSUMED_SCALE_KEY, ASSUMED_TIMING_KEY, ReadError, read_bytes, read_path};

/// A synthetic file with a Height trace and retrace of `columns × rows`; stored line `k`
/// (bottom first) holds `1000 k + column` (+ 1 in the retrace).
fn synthetic(columns: usize, rows: usize, extra: &str) -> Vec<u8> {
    let header_len = 8192;
    let image_len = columns * rows * 2;
    let image = |offset: usize, direction: &str| {
        format!(
            "\\*Ciao image list\r\n\\Data offset: {offset}\r\n\\Data length: {image_len}\r\n\
             \\Bytes/pixel: 2\r\n\\Frame direction: Up\r\n\\Samps/line: {columns}\r\n\
             \\Number of lines: {rows}\r\n\\Aspect ratio: 1:1\r\n\\Scan Size: 40 60 nm\r\n\
             \\Scan line: Main\r\n\\Line direction: {direction}\r\n{extra}\
             \\@2:Image Data: S [Height] \"Height\"\r\n\
             \\@2:Z scale: V [Sens. Zscan] (0.006713867 V/LSB) 65.536 V\r\n\
             \\@2:Z offset: V [Sens. Zscan] (0.006713867 V/LSB) 0 V\r\n"
        )
    };
    let mut header = String::from(
        "\\*File list\r\n\\Version: 0x05120108\r\n\\Data length: 8192\r\n\
         \\*Scanner list\r\n\\@Sens. Zscan: V 2.5 nm/V\r\n\
         \\*Ciao scan list\r\n\\Scan size: 999 nm\r\n\\Scan rate: 2.5\r\n",
    );
    header.push_str(&image(header_len, "Trace"));
    header.push_str(&image(header_len + image_len, "Retrace"));
    header.push_str("\\*File list end\r\n\x1a");
    let mut out = header.into_bytes();
    assert!(out.len() <= header_len);
    out.resize(header_len, 0);
    for offset in [0, 1] {
        for k in 0..rows {
            for c in 0..columns {
                out.extend_from_slice(&((1000 * k + c + offset) as i16).to_le_bytes());
            }
        }
    }
    out
}

/// One stored unit: 65.536 V / 2^16 · 2.5 nm/V = 2.5 pm.
const UNIT: f64 = 2.5e-12;

#[test]
fn values_orientation_size_and_timing() {
    let scan = read_bytes(&synthetic(4, 2, "")).unwrap();
    assert_eq!(scan.format, FileFormat::Nanoscope);
    assert_eq!(scan.pairs.len(), 1);
    let pair = &scan.pairs[0];
    assert_eq!(pair.name(), "Height");
    let (trace, retrace) = (pair.trace().unwrap(), pair.retrace().unwrap());
    assert_eq!(trace.unit, "m");
    for r in 0..2 {
        for c in 0..4 {
            // Row 0 of the display is the last stored line.
            let stored = (1000 * (1 - r) + c) as f64;
            assert!((trace.z[[r, c]] - stored * UNIT).abs() < 1e-20);
            assert!((retrace.z[[r, c]] - (stored + 1.0) * UNIT).abs() < 1e-20);
        }
    }
    let g = pair.geometry();
    assert!((g.pitch_x() - 10e-9).abs() < 1e-18 && (g.pitch_y() - 30e-9).abs() < 1e-18);
    assert_eq!(g.slow_direction(), ScanDirection::Up);
    assert_eq!(g.fast_direction(ScanPass::Trace), ScanDirection::Right);
    // 2.5 Hz trace-and-retrace cycles: 0.2 s per line and direction.
    assert!((g.line_scan_time() - 0.2).abs() < 1e-12);
    assert_eq!(g.scale_source(), ValueSource::Stated);
    assert_eq!(g.timing_source(), ValueSource::Stated);
}

#[test]
fn an_unequal_aspect_ratio_is_reported_as_an_assumed_scale() {
    let bytes = synthetic(4, 2, "");
    let text = String::from_utf8_lossy(&bytes[..8192]).replace(
        "Aspect ratio: 1:1\r\n\\Scan Size: 40 60 nm",
        "Aspect ratio: 2:1\r\n\\Scan Size: 40 60 nm",
    );
    let mut edited = text.into_bytes();
    edited.truncate(8192);
    edited.extend_from_slice(&bytes[8192..]);
    let scan = read_bytes(&edited).unwrap();
    let g = scan.pairs[0].geometry();
    assert_eq!(g.scale_source(), ValueSource::Assumed);
    assert!((g.height() - 30e-9).abs() < 1e-18);
    assert!(scan.metadata[ASSUMED_SCALE_KEY].contains("Aspect ratio 2:1"));
}

#[test]
fn hostile_headers_are_typed_errors() {
    let bytes = synthetic(4, 2, "");
    let edit = |from: &str, to: &str| {
        let text = String::from_utf8_lossy(&bytes[..8192]).replacen(from, to, 1);
        let mut out = text.into_bytes();
        out.resize(8192, 0);
        out.extend_from_slice(&bytes[8192..]);
        out
    };
    for (from, to) in [
        ("Samps/line: 4", "Samps/line: 4000000000"),
        ("Number of lines: 2", "Number of lines: 0"),
        ("Data offset: 8192", "Data offset: 18446744073709551615"),
        ("Bytes/pixel: 2", "Bytes/pixel: 3"),
        ("Scan Size: 40 60 nm", "Scan Size: 40 60 V"),
        ("Scan rate: 2.5", "Scan rate: -1"),
        ("[Sens. Zscan] (", "[Sens. Nothing] ("),
        ("Data length: 16", "Data length: 15"),
    ] {
        let error = read_bytes(&edit(from, to)).expect_err(to);
        assert!(
            matches!(
                error,
                ReadError::Truncated { .. }
                    | ReadError::Corrupt { .. }
                    | ReadError::Unsupported { .. }
                    | ReadError::NoImage { .. }
            ),
            "{to}: {error}"
        );
    }
    let without_rate = edit("\\Scan rate: 2.5\r\n", "");
    let scan = read_bytes(&without_rate).unwrap();
    assert_eq!(
        scan.pairs[0].geometry().timing_source(),
        ValueSource::Assumed
    );
    assert!(scan.metadata[ASSUMED_TIMING_KEY].contains("Scan rate"));
    for cut in (0..bytes.len()).step_by(5) {
        assert!(read_bytes(&bytes[..cut]).is_err(), "cut at {cut}");
    }
}

fn real(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/data/real")
        .join(name)
}

#[test]
fn real_bruker_example_image() {
    let scan = read_path(&real("bruker_example_40um.spm")).unwrap();
    let names: Vec<&str> = scan.pairs.iter().map(|p| p.name()).collect();
    // The interleave (lifted) friction trace does not pair with the main retrace.
    assert_eq!(names, ["Height", "Friction (interleave)", "Friction"]);
    let height = &scan.pairs[0];
    assert!(height.trace().is_some() && height.retrace().is_none());
    assert!(scan.pairs[2].trace().is_none() && scan.pairs[2].retrace().is_some());
    let g = height.geometry();
    assert_eq!((g.columns(), g.rows()), (512, 512));
    assert!((g.width() / 40e-6 - 1.0).abs() < 1e-9 && (g.height() / 40e-6 - 1.0).abs() < 1e-9);
    assert!((g.line_scan_time() - 0.5 / 1.96888).abs() < 1e-9);
    assert_eq!(g.slow_direction(), ScanDirection::Down);
    assert_eq!(g.timing_source(), ValueSource::Stated);
    let z = height.trace().unwrap();
    assert_eq!(z.unit, "m");
    // Gwyddion 2.62 reads this channel as -543.10 .. 442.34 nm.
    let (low, high) = z.finite_range().unwrap();
    assert!((low / -5.430956e-7 - 1.0).abs() < 1e-6, "{low}");
    assert!((high / 4.423394e-7 - 1.0).abs() < 1e-6, "{high}");
    assert_eq!(scan.pairs[1].trace().unwrap().unit, "V");
}

#[test]
fn real_nanoscope_file_with_the_scan_size_in_the_scan_list() {
    let scan = read_path(&real("nanoscope_d3100_2um.000")).unwrap();
    let names: Vec<&str> = scan.pairs.iter().map(|p| p.name()).collect();
    assert_eq!(names, ["Height", "Amplitude"]);
    for pair in &scan.pairs {
        assert!(pair.trace().is_none(), "both images are retrace");
        let g = pair.geometry();
        assert_eq!((g.columns(), g.rows()), (512, 512));
        assert!((g.width() / 2e-6 - 1.0).abs() < 1e-9 && (g.height() / 2e-6 - 1.0).abs() < 1e-9);
        assert!((g.line_scan_time() - 0.5 / 1.99943).abs() < 1e-9);
        assert_eq!(g.fast_direction(ScanPass::Retrace), ScanDirection::Left);
    }
    assert_eq!(scan.topography().unwrap().name(), "Height");
}
