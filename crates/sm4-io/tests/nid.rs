//! Nanosurf `.nid` reader: synthetic files written here, the real MIT-licensed AFM files in
//! `tests/data/real`, the real STM file through `DHCT_REAL_DATA`, and hostile inputs.

use std::path::{Path, PathBuf};

use dhct_scan::{FileFormat, ScanDirection, ScanPass, ValueSource};
use dhct_sm4_io::{ASSUMED_TIMING_KEY, ReadError, read_bytes, read_path};
use ndarray::Array2;

/// A synthetic file of one channel `Z` (forward and backward) plus a spectroscopy set
/// stored between them; stored line `k` (bottom first) holds `1000 k + column`.
fn synthetic(columns: usize, rows: usize, direction: &str, bits: u32) -> Vec<u8> {
    let set = |frame: &str| {
        format!(
            "Version=2\r\nPoints={columns}\r\nLines={rows}\r\nFrame={frame}\r\n\
             Dim0Name=X*\r\nDim0Unit=m\r\nDim0Range={}e-10\r\nDim0Min=0\r\n\
             Dim1Name=Y*\r\nDim1Unit=m\r\nDim1Range={}e-10\r\nDim1Min=0\r\n\
             Dim2Name=Z-Axis\r\nDim2Unit=nm\r\nDim2Range=65536\r\nDim2Min=-32768\r\n\
             SaveMode=Binary\r\nSaveBits={bits}\r\nSaveSign=Signed\r\nSaveOrder=Intel\r\n\r\n",
            2 * columns,
            3 * rows
        )
    };
    let mut header = String::from(
        "[DataSet]\r\nVersion=2\r\nGroupCount=3\r\nGr0-Name=Scan forward\r\nGr0-Count=2\r\n\
         Gr1-Name=Spectrum\r\nGr1-Count=1\r\nGr2-Name=Scan backward\r\nGr2-Count=2\r\n\
         Gr0-Ch1=DataSet-0:1\r\nGr1-Ch0=DataSet-1:0\r\nGr2-Ch1=DataSet-2:1\r\n\r\n",
    );
    header.push_str(&format!(
        "[DataSet-Info]\r\nScan direction={direction}\r\nTime/Line=250ms\r\nRotation=30 °\r\n\r\n"
    ));
    header.push_str(&format!("[DataSet-0:1]\r\n{}", set("Scan forward")));
    header.push_str(
        "[DataSet-1:0]\r\nPoints=3\r\nLines=1\r\nFrame=Spectrum\r\nDim2Name=I\r\n\
         Dim2Range=1\r\nDim2Min=0\r\nSaveBits=16\r\n\r\n",
    );
    header.push_str(&format!("[DataSet-2:1]\r\n{}", set("Scan backward")));
    let mut out = header.into_bytes();
    out.extend_from_slice(b"#!");
    let scale = 2f64.powi(bits as i32 - 16);
    for offset in [0.0, f64::NAN, 0.5] {
        if offset.is_nan() {
            out.extend_from_slice(&[0xAB; 6]); // the spectrum: 3 values of 16 bits
            continue;
        }
        for k in 0..rows {
            for c in 0..columns {
                // Value = -32768 nm + 65536 nm · (n + 2^(b-1)) / 2^b = n / 2^(b-16) nm.
                let raw = ((1000 * k + c) as f64 + offset) * scale;
                match bits {
                    16 => out.extend_from_slice(&(raw as i16).to_le_bytes()),
                    _ => out.extend_from_slice(&(raw as i32).to_le_bytes()),
                }
            }
        }
    }
    out
}

#[test]
fn rows_are_flipped_to_display_and_the_backward_image_is_kept_left_to_right() {
    for bits in [16, 32] {
        let scan = read_bytes(&synthetic(5, 3, "Up", bits)).unwrap();
        assert_eq!(scan.format, FileFormat::NanosurfNid);
        assert_eq!(scan.pairs.len(), 1, "the spectrum is not an image");
        let z = &scan.pairs[0];
        assert_eq!(z.name(), "Z-Axis");
        let trace = z.trace().unwrap();
        let retrace = z.retrace().unwrap();
        assert_eq!(trace.unit, "m");
        // Display row 0 is the last stored line (the top of the frame).
        let expect = |offset: f64| {
            Array2::from_shape_fn((3, 5), |(r, c)| {
                ((1000 * (2 - r) + c) as f64 + offset) * 1e-9
            })
        };
        for (image, offset) in [(trace, 0.0), (retrace, if bits == 32 { 0.5 } else { 0.0 })] {
            let want = expect(offset);
            for (a, b) in image.z.iter().zip(want.iter()) {
                assert!(
                    (a - b).abs() <= 1e-9 * b.abs().max(1e-9),
                    "{a} vs {b} ({bits} bits)"
                );
            }
        }
        let g = z.geometry();
        assert_eq!(g.slow_direction(), ScanDirection::Up);
        assert_eq!(g.fast_direction(ScanPass::Retrace), ScanDirection::Left);
        assert!((g.pitch_x() - 2e-10).abs() < 1e-22 && (g.pitch_y() - 3e-10).abs() < 1e-22);
        assert!((g.line_scan_time() - 0.25).abs() < 1e-12);
        assert!((g.scan_angle() - 30f64.to_radians()).abs() < 1e-12);
        assert_eq!(g.timing_source(), ValueSource::Stated);
    }
}

/// `Date` and `Time` of `[DataSet-Info]` (day first, decimal-comma headers alike) are
/// the frame's start; without them there is none.
#[test]
fn the_header_date_and_time_are_the_frames_start() {
    let text = String::from_utf8_lossy(&synthetic(4, 2, "Down", 16)).into_owned();
    let bytes = synthetic(4, 2, "Down", 16);
    let header_end = text.find("#!").unwrap();
    let dated = |date: &str| {
        let mut edited = text[..header_end]
            .replace("Time/Line=250ms\r\n", &format!("Time/Line=250ms\r\n{date}"))
            .into_bytes();
        edited.extend_from_slice(&bytes[header_end..]);
        read_bytes(&edited).unwrap().pairs[0]
            .geometry()
            .start_time()
    };
    let start = dated("Date=18-05-2016\r\nTime=10:42:55\r\n").expect("a start");
    let next = dated("Date=18-05-2016\r\nTime=10:43:22\r\n").expect("a start");
    assert_eq!(next - start, 27.0);
    // 2016-05-18 10:42:55 as seconds since 1970 (the clock dhct keeps, zone ignored).
    assert_eq!(start, 1_463_568_175.0);
    assert_eq!(dated(""), None);
    assert_eq!(dated("Date=yesterday\r\nTime=10:42:55\r\n"), None);
}

#[test]
fn a_missing_scan_direction_or_time_is_an_assumption() {
    let text = String::from_utf8_lossy(&synthetic(4, 2, "Down", 16)).into_owned();
    let bytes = synthetic(4, 2, "Down", 16);
    let header_end = text.find("#!").unwrap();
    let mut edited = text[..header_end]
        .replace("Scan direction=Down\r\n", "")
        .replace("Time/Line=250ms\r\n", "")
        .into_bytes();
    edited.extend_from_slice(&bytes[header_end..]);
    let scan = read_bytes(&edited).unwrap();
    let g = scan.pairs[0].geometry();
    assert_eq!(g.timing_source(), ValueSource::Assumed);
    assert_eq!(g.slow_direction(), ScanDirection::Down);
    let why = &scan.metadata[ASSUMED_TIMING_KEY];
    assert!(
        why.contains("Scan direction") && why.contains("Time/Line"),
        "{why}"
    );
}

#[test]
fn hostile_headers_are_typed_errors() {
    let bytes = synthetic(4, 2, "Down", 16);
    let text = String::from_utf8_lossy(&bytes).into_owned();
    let header_end = text.find("#!").unwrap();
    let edit = |from: &str, to: &str| {
        let mut out = text[..header_end].replacen(from, to, 1).into_bytes();
        out.extend_from_slice(&bytes[header_end..]);
        out
    };
    for (from, to) in [
        ("Points=4", "Points=4000000000"),
        ("Lines=2", "Lines=0"),
        ("SaveBits=16", "SaveBits=12"),
        ("SaveOrder=Intel", "SaveOrder=Motorola"),
        ("Dim0Range=8e-10", "Dim0Range=8e10"),
        ("Time/Line=250ms", "Time/Line=1e-30s"),
        ("Rotation=30 °", "Rotation=9999 °"),
    ] {
        let error = read_bytes(&edit(from, to)).expect_err(to);
        assert!(
            matches!(
                error,
                ReadError::Truncated { .. }
                    | ReadError::Corrupt { .. }
                    | ReadError::Unsupported { .. }
            ),
            "{to}: {error}"
        );
    }
    for cut in (0..bytes.len()).step_by(7) {
        assert!(read_bytes(&bytes[..cut]).is_err(), "cut at {cut}");
    }
}

fn real(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/data/real")
        .join(name)
}

/// Channel names, size (m), line time (s) and slow direction of a real file.
fn check_real(path: &Path, names: &[&str], size: f64, line_time: f64, slow: ScanDirection) {
    let scan = read_path(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let found: Vec<&str> = scan.pairs.iter().map(|p| p.name()).collect();
    assert_eq!(found, names, "{}", path.display());
    for pair in &scan.pairs {
        let g = pair.geometry();
        assert_eq!((g.columns(), g.rows()), (256, 256));
        assert!((g.width() / size - 1.0).abs() < 1e-3, "width {}", g.width());
        assert!(
            (g.height() / size - 1.0).abs() < 1e-3,
            "height {}",
            g.height()
        );
        assert!(
            (g.line_scan_time() / line_time - 1.0).abs() < 1e-3,
            "line time {}",
            g.line_scan_time()
        );
        assert_eq!(g.slow_direction(), slow);
        assert_eq!(g.timing_source(), ValueSource::Stated);
        assert!(pair.trace().is_some() && pair.retrace().is_some());
    }
}

#[test]
fn real_nanosurf_afm_files() {
    check_real(
        &real("nanosurf_afm_7um.nid"),
        &["Z-Axis", "Amplitude", "Phase"],
        7.40729e-6,
        0.80325,
        ScanDirection::Up,
    );
    check_real(
        &real("nanosurf_grid_3um.nid"),
        &["Z-Axis", "Amplitude", "Phase"],
        3e-6,
        0.78,
        ScanDirection::Down,
    );
    let scan = read_path(&real("nanosurf_grid_3um.nid")).unwrap();
    assert!((scan.pairs[0].geometry().scan_angle() - 45f64.to_radians()).abs() < 1e-12);
}

#[test]
fn real_nanosurf_stm_file() {
    let Some(dir) = std::env::var_os("DHCT_REAL_DATA") else {
        eprintln!("note: DHCT_REAL_DATA is unset; skipping the real Nanosurf STM file test");
        return;
    };
    // GPL-3.0 (matkrin/proespm-py3), so not vendored; read only where it has been put
    // beside the other non-redistributable files.
    let path = Path::new(&dir).join("stm-nanosurf-nid.nid");
    if !path.is_file() {
        eprintln!(
            "note: {} is absent; skipping the real Nanosurf STM file test",
            path.display()
        );
        return;
    }
    check_real(
        &path,
        &["Tip Current", "Z-Axis"],
        2e-8,
        0.09996,
        ScanDirection::Down,
    );
    let scan = read_path(&path).unwrap();
    let z = scan.topography().unwrap();
    assert_eq!(z.name(), "Z-Axis");
    // Forward and backward images show the same surface (a lattice, with a lag of a few
    // pixels between the passes) without a left-right flip. Measured: 0.33 (at a 4 px
    // lag) against at most -0.01 when the backward image is mirrored.
    let (a, b) = (&z.trace().unwrap().z, &z.retrace().unwrap().z);
    let mut flipped = b.clone();
    flipped.invert_axis(ndarray::Axis(1));
    let best = |b: &Array2<f64>| {
        (-12..=12)
            .map(|shift| shifted_correlation(a, b, shift))
            .fold(f64::MIN, f64::max)
    };
    let (same, mirrored) = (best(b), best(&flipped));
    assert!(
        same > 0.25 && mirrored < 0.1,
        "{same} vs mirrored {mirrored}"
    );
}

/// Correlation of `a` with `b` shifted by `shift` columns, after subtracting every row's
/// mean, ignoring a margin of 20 columns.
fn shifted_correlation(a: &Array2<f64>, b: &Array2<f64>, shift: isize) -> f64 {
    let level = |m: &Array2<f64>| {
        let mut m = m.clone();
        for mut row in m.rows_mut() {
            let mean = row.mean().unwrap_or(0.0);
            row.mapv_inplace(|v| v - mean);
        }
        m
    };
    let (a, b) = (level(a), level(b));
    let (mut ab, mut aa, mut bb) = (0.0, 0.0, 0.0);
    for r in 0..a.nrows() {
        for c in 20..a.ncols() - 20 {
            let (x, y) = (a[[r, c]], b[[r, (c as isize + shift) as usize]]);
            ab += x * y;
            aa += x * x;
            bb += y * y;
        }
    }
    ab / (aa * bb).sqrt()
}
