//! RHK SM4 reader and writer: round trips, hostile input, the real file, and a cross-check
//! against spym's independent reader.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use dhct_scan::{
    FileFormat, ImageChannel, ScanDirection, ScanFile, ScanGeometry, ScanPair, ScanPass,
    ValueSource,
};
use dhct_sm4_io::{ReadError, WriteError, sm4};
use ndarray::Array2;
use proptest::prelude::*;

use ScanDirection::{Down, Left, Right, Up};

/// Smooth topography (≈ 0.3 nm corrugation on a 5 nm offset) plus deterministic noise, metres.
fn surface(rows: usize, columns: usize, seed: u64) -> Array2<f64> {
    let mut state = seed
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    Array2::from_shape_fn((rows, columns), |(r, c)| {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let noise = ((state >> 33) as f64 / (1u64 << 31) as f64 - 0.5) * 2e-11;
        5e-9 + 3e-10 * ((r as f64 * 0.7).sin() + (c as f64 * 0.45 + r as f64 * 0.1).cos()) + noise
    })
}

fn geometry(columns: usize, rows: usize, fast: ScanDirection, slow: ScanDirection) -> ScanGeometry {
    ScanGeometry::new(columns, rows, 4.3e-11, 5.1e-11, 1.51e-3, fast, slow)
        .unwrap()
        .with_scan_angle(0.25)
        .unwrap()
        .with_offset(-5.4e-9, 2.17e-8)
        .unwrap()
}

fn pair(columns: usize, rows: usize, fast: ScanDirection, slow: ScanDirection) -> ScanPair {
    let g = geometry(columns, rows, fast, slow);
    let trace = ImageChannel::new("Topography", "m", surface(rows, columns, 1));
    let retrace = ImageChannel::new("Topography", "m", surface(rows, columns, 2));
    ScanPair::new(g, trace, Some(retrace)).unwrap()
}

fn scan_file(pairs: Vec<ScanPair>) -> ScanFile {
    let mut metadata = BTreeMap::new();
    metadata.insert("date".to_string(), "2023-06-03".to_string());
    metadata.insert("time".to_string(), "19:50:21".to_string());
    metadata.insert("bias".to_string(), "-2 V".to_string());
    metadata.insert("current".to_string(), "4e-10 A".to_string());
    metadata.insert(
        "user text".to_string(),
        "written by the dhct tests".to_string(),
    );
    ScanFile {
        format: FileFormat::RhkSm4,
        pairs,
        metadata,
    }
}

fn to_bytes(file: &ScanFile) -> Vec<u8> {
    let mut bytes = Vec::new();
    sm4::write(file, &mut bytes).unwrap();
    bytes
}

/// The largest quantisation error the writer promises: half its z scale, which is about
/// `half range / (2^31 − 128)` (plus the rounding of the f32 offset and scale), plus the
/// f64 rounding of `raw · z_scale + z_offset` when the quantum is below f64 resolution.
fn tolerance(channel: &ImageChannel) -> f64 {
    let (lo, hi) = channel.finite_range().unwrap_or((0.0, 0.0));
    let mid = (lo + hi) / 2.0;
    let half = (hi - lo) / 2.0 + mid.abs() * 1.2e-7;
    let f64_rounding = lo.abs().max(hi.abs()) * 4.5e-16;
    half / 2_147_483_520.0 / 2.0 * 1.000_01 + f64_rounding + f64::MIN_POSITIVE
}

fn assert_close(what: &str, a: f64, b: f64, relative: f64) {
    assert!(
        (a - b).abs() <= relative * a.abs().max(b.abs()),
        "{what}: {a} vs {b}"
    );
}

fn assert_same_geometry(a: &ScanGeometry, b: &ScanGeometry) {
    assert_eq!((a.columns(), a.rows()), (b.columns(), b.rows()));
    assert_close("pitch x", a.pitch_x(), b.pitch_x(), 1e-6);
    assert_close("pitch y", a.pitch_y(), b.pitch_y(), 1e-6);
    assert_close("pixel period", a.pixel_period(), b.pixel_period(), 1e-6);
    assert_eq!(a.trace_fast(), b.trace_fast());
    assert_eq!(a.slow_direction(), b.slow_direction());
    assert!((a.scan_angle() - b.scan_angle()).abs() < 1e-6);
    assert_close("offset x", a.offset().0, b.offset().0, 1e-6);
    assert_close("offset y", a.offset().1, b.offset().1, 1e-6);
    assert_eq!(b.scale_source(), ValueSource::Stated);
    assert_eq!(b.timing_source(), ValueSource::Stated);
}

fn assert_same_image(want: &ImageChannel, got: &ImageChannel) {
    assert_eq!(want.name, got.name);
    assert_eq!(want.unit, got.unit);
    assert_eq!(want.z.dim(), got.z.dim());
    let tolerance = tolerance(want);
    for ((index, a), b) in want.z.indexed_iter().zip(got.z.iter()) {
        if a.is_finite() {
            assert!(
                (a - b).abs() <= tolerance,
                "{index:?}: {a} vs {b} (tolerance {tolerance})"
            );
        } else {
            assert!(b.is_nan(), "{index:?}: {a} became {b}");
        }
    }
}

fn assert_round_trip(file: &ScanFile) -> ScanFile {
    let bytes = to_bytes(file);
    assert_eq!(dhct_sm4_io::detect_format(&bytes), Some(FileFormat::RhkSm4));
    let back = sm4::read(&bytes).unwrap();
    assert_eq!(back.format, FileFormat::RhkSm4);
    assert_eq!(back.pairs.len(), file.pairs.len());
    for (want, got) in file.pairs.iter().zip(&back.pairs) {
        assert_same_geometry(want.geometry(), got.geometry());
        for pass in ScanPass::BOTH {
            match (want.image(pass), got.image(pass)) {
                (Some(a), Some(b)) => assert_same_image(a, b),
                (None, None) => {}
                (a, b) => panic!("{pass:?}: wrote {:?}, read {:?}", a.is_some(), b.is_some()),
            }
        }
    }
    back
}

#[test]
fn round_trip_all_direction_combinations_square_and_not() {
    for (fast, slow) in [
        (Right, Down),
        (Right, Up),
        (Left, Down),
        (Left, Up),
        (Up, Left),
        (Up, Right),
        (Down, Left),
        (Down, Right),
    ] {
        for (columns, rows) in [(16, 16), (23, 9), (5, 31), (1, 1)] {
            assert_round_trip(&scan_file(vec![pair(columns, rows, fast, slow)]));
        }
    }
}

#[test]
fn round_trip_keeps_metadata_and_several_channels() {
    let g = geometry(12, 10, Right, Down);
    let current = ScanPair::new(
        g.clone(),
        ImageChannel::new("Current", "A", surface(10, 12, 3).mapv(|v| v * 1e-1)),
        Some(ImageChannel::new(
            "Current",
            "A",
            surface(10, 12, 4).mapv(|v| v * 1e-1),
        )),
    )
    .unwrap();
    let file = scan_file(vec![pair(12, 10, Right, Down), current]);
    let back = assert_round_trip(&file);
    assert_eq!(back.pairs[1].name(), "Current");
    let m = &back.metadata;
    assert_eq!(m.get("date").map(String::as_str), Some("2023-06-03"));
    assert_eq!(m.get("time").map(String::as_str), Some("19:50:21"));
    assert_eq!(m.get("bias").map(String::as_str), Some("-2 V"));
    assert_eq!(m.get("current").map(String::as_str), Some("4e-10 A"));
    assert_eq!(
        m.get("user text").map(String::as_str),
        Some("written by the dhct tests")
    );
}

#[test]
fn constant_zero_and_huge_offset_images_survive() {
    for value in [0.0, 1e-9, -3.3e-7, 12.5] {
        let g = geometry(4, 3, Right, Down);
        let z = Array2::from_elem((3, 4), value);
        let file = scan_file(vec![
            ScanPair::new(g, ImageChannel::new("Z", "m", z), None).unwrap(),
        ]);
        assert_round_trip(&file);
    }
    // A tiny corrugation on a large offset keeps its sub-quantum accuracy.
    let g = geometry(8, 8, Right, Down);
    let z = surface(8, 8, 5).mapv(|v| v * 1e-3 + 1e-6);
    assert_round_trip(&scan_file(vec![
        ScanPair::new(g, ImageChannel::new("Z", "m", z), None).unwrap(),
    ]));
}

#[test]
fn nan_pixels_and_unfinished_lines_read_back_as_nan() {
    for slow in [Down, Up] {
        let g = geometry(6, 8, Right, slow);
        let mut z = surface(8, 6, 7);
        z[[2, 3]] = f64::NAN;
        // The last two lines in acquisition order were never scanned.
        let unscanned = if slow == Down { [6, 7] } else { [0, 1] };
        for row in unscanned {
            z.row_mut(row).fill(f64::NAN);
        }
        let file = scan_file(vec![
            ScanPair::new(g, ImageChannel::new("Topography", "m", z), None).unwrap(),
        ]);
        let back = assert_round_trip(&file);
        let got = &back.pairs[0].trace().unwrap().z;
        assert!(got[[2, 3]].is_nan());
        assert_eq!(got.iter().filter(|v| v.is_nan()).count(), 13);
    }
}

#[test]
fn lone_images_keep_their_pass() {
    let g = geometry(7, 5, Right, Down);
    let trace_only = ScanPair::new(
        g.clone(),
        ImageChannel::new("T", "m", surface(5, 7, 1)),
        None,
    )
    .unwrap();
    let retrace_only =
        ScanPair::retrace_only(g, ImageChannel::new("R", "m", surface(5, 7, 2))).unwrap();
    let back = assert_round_trip(&scan_file(vec![trace_only, retrace_only]));
    assert!(back.pairs[0].retrace().is_none());
    assert!(back.pairs[1].trace().is_none());

    // A lone trace running Left cannot be told from a retrace in SM4.
    let g = geometry(7, 5, Left, Down);
    let left_trace = ScanPair::new(g, ImageChannel::new("T", "m", surface(5, 7, 1)), None).unwrap();
    let mut sink = Vec::new();
    assert!(matches!(
        sm4::write(&scan_file(vec![left_trace]), &mut sink),
        Err(WriteError::Unrepresentable { .. })
    ));
}

#[test]
fn written_layout_matches_the_documented_one() {
    let bytes = to_bytes(&scan_file(vec![pair(3, 2, Right, Down)]));
    let u32_at = |at: usize| u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap());
    let f32_at = |at: usize| f32::from_le_bytes(bytes[at..at + 4].try_into().unwrap());
    assert_eq!(&bytes[0..2], &56u16.to_le_bytes());
    let signature: Vec<u8> = "STiMage 005.004 1"
        .encode_utf16()
        .flat_map(u16::to_le_bytes)
        .collect();
    assert_eq!(&bytes[2..2 + signature.len()], signature.as_slice());
    assert_eq!(u32_at(38), 2); // pages
    assert_eq!(u32_at(46), 12); // object field size
    assert_eq!((u32_at(58), u32_at(62), u32_at(66)), (1, 70, 16));
    assert_eq!(u32_at(70), 2); // page index header: pages
    assert_eq!((u32_at(86), u32_at(90), u32_at(94)), (2, 98, 32));
    let first_header = u32_at(98 + 36) as usize;
    assert_eq!(first_header, 98 + 2 * 56);
    assert_eq!(u32_at(first_header + 24), 3); // x size
    assert_eq!(u32_at(first_header + 28), 2); // y size
    assert_eq!(u32_at(first_header + 36), 0); // scan direction: right
    assert!(f32_at(first_header + 56) < 0.0); // x scale
    assert!(f32_at(first_header + 60) < 0.0); // y scale (slow Down)
    let second_header = u32_at(98 + 56 + 36) as usize;
    assert_eq!(u32_at(second_header + 36), 1); // scan direction: left
    // The data end the file.
    let last_data = 98 + 56 + 44;
    assert_eq!(
        u32_at(last_data + 4) + u32_at(last_data + 8),
        bytes.len() as u32
    );
}

// ---------------------------------------------------------------------------------------
// Hostile and damaged input

fn small_file() -> Vec<u8> {
    to_bytes(&scan_file(vec![pair(5, 4, Right, Down)]))
}

fn patch_u32(bytes: &mut [u8], at: usize, value: u32) {
    bytes[at..at + 4].copy_from_slice(&value.to_le_bytes());
}

#[test]
fn every_truncation_is_an_error() {
    let bytes = small_file();
    for cut in 0..bytes.len() {
        assert!(sm4::read(&bytes[..cut]).is_err(), "cut at {cut} read fine");
    }
    assert!(sm4::read(&bytes).is_ok());
}

#[test]
fn hostile_sizes_are_errors_not_panics() {
    let bytes = small_file();
    let header = u32::from_le_bytes(bytes[134..138].try_into().unwrap()) as usize;
    let cases: Vec<(&str, usize, u32)> = vec![
        ("page count 2^31", 70, 1 << 31),
        ("page count max", 70, u32::MAX),
        ("file object count", 42, u32::MAX),
        ("object field size 0", 46, 0),
        ("page index array offset past end", 90, u32::MAX - 8),
        ("page header offset past end", 98 + 36, bytes.len() as u32),
        ("page data size huge", 98 + 52, u32::MAX),
        ("x size huge", header + 24, u32::MAX),
        ("x and y size overflow", header + 24, 1 << 31),
        ("x size zero", header + 24, 0),
        ("page header objects", header + 112, u32::MAX),
        ("string object offset", header + 184, u32::MAX),
        ("string object size", header + 188, u32::MAX),
    ];
    for (what, at, value) in cases {
        let mut hostile = bytes.clone();
        patch_u32(&mut hostile, at, value);
        if what == "x and y size overflow" {
            patch_u32(&mut hostile, header + 28, 1 << 31);
        }
        let result = sm4::read(&hostile);
        assert!(result.is_err(), "{what}: read fine");
    }
}

#[test]
fn pages_sharing_one_large_data_object_hit_the_budget() {
    // Many page index entries pointing at the same image: work stays bounded.
    let file = scan_file(vec![pair(64, 64, Right, Down)]);
    let mut bytes = to_bytes(&file);
    let entry = bytes[98..98 + 56].to_vec();
    let copies = 2000usize;
    // Move everything after the array to make room is complex; instead append copies of
    // the entry at the end and point the array there.
    let array_at = bytes.len() as u32;
    for _ in 0..copies {
        bytes.extend_from_slice(&entry);
    }
    patch_u32(&mut bytes, 90, array_at);
    patch_u32(&mut bytes, 70, copies as u32);
    match sm4::read(&bytes) {
        Err(ReadError::Corrupt { reason, .. }) => assert!(reason.contains("too many times")),
        other => panic!("expected the budget to stop the reader, got {other:?}"),
    }
}

#[test]
fn foreign_and_empty_input_is_rejected() {
    assert!(matches!(sm4::read(b""), Err(ReadError::WrongFormat { .. })));
    assert!(matches!(
        sm4::read(b"hello, this is not an SM4 file at all......"),
        Err(ReadError::WrongFormat { .. })
    ));
    assert!(!sm4::looks_like_sm4(&small_file()[..30]));
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 300, ..ProptestConfig::default() })]

    #[test]
    fn mutated_files_never_panic(
        changes in proptest::collection::vec((any::<usize>(), any::<u8>()), 1..12),
        cut in any::<usize>(),
        truncate in any::<bool>(),
    ) {
        let mut bytes = small_file();
        let len = bytes.len();
        for (at, value) in changes {
            // Bias mutations towards the headers, where the structure lives.
            let at = if at % 2 == 0 { at % 400.min(len) } else { at % len };
            bytes[at] = value;
        }
        if truncate {
            bytes.truncate(cut % (len + 1));
        }
        let _ = sm4::read(&bytes);
    }

    #[test]
    fn random_bytes_with_a_valid_signature_never_panic(
        tail in proptest::collection::vec(any::<u8>(), 0..600),
    ) {
        let mut bytes = small_file()[..38].to_vec();
        bytes.extend_from_slice(&tail);
        prop_assert!(sm4::read(&bytes).is_err());
    }
}

// ---------------------------------------------------------------------------------------
// The real file (not in the repository): DHCT_REAL_DATA=/path/to/directory

#[test]
fn real_pb_pt111_file() {
    let Some(directory) = std::env::var_os("DHCT_REAL_DATA") else {
        eprintln!("note: DHCT_REAL_DATA is not set; skipping the real SM4 file test");
        return;
    };
    let path = Path::new(&directory).join("pb_pt111_2023-06-01-0087.SM4");
    let file = dhct_sm4_io::read_path(&path)
        .unwrap_or_else(|e| panic!("{} must load: {e}", path.display()));
    assert_eq!(file.format, FileFormat::RhkSm4);
    assert_eq!(file.pairs.len(), 1, "one image channel (topography)");
    let topography = file.topography().expect("a topography channel");
    let g = topography.geometry();
    assert_eq!((g.columns(), g.rows()), (512, 512));
    assert!(
        (g.width() / 22.05e-9 - 1.0).abs() < 0.005,
        "width {}",
        g.width()
    );
    assert!(
        (g.height() / 22.05e-9 - 1.0).abs() < 0.005,
        "height {}",
        g.height()
    );
    assert!(
        (g.pixel_period() / 1.51e-3 - 1.0).abs() < 0.01,
        "period {}",
        g.pixel_period()
    );
    assert!((g.line_scan_time() / 0.774 - 1.0).abs() < 0.01);
    assert_eq!(g.scale_source(), ValueSource::Stated);
    assert_eq!(g.timing_source(), ValueSource::Stated);
    let trace = topography.trace().expect("Topography_Forward");
    let retrace = topography.retrace().expect("Topography_Backward");
    assert_eq!(g.fast_direction(ScanPass::Trace), Right);
    assert_eq!(g.fast_direction(ScanPass::Retrace), Left);
    assert_eq!(g.slow_direction(), Down);
    for channel in [trace, retrace] {
        assert_eq!(channel.unit, "m");
        assert_eq!(channel.non_finite_count(), 0);
        let (lo, hi) = channel.finite_range().unwrap();
        assert!(hi - lo > 1e-11 && hi - lo < 100e-9, "z span {}", hi - lo);
        assert!(lo.abs() < 1e-6 && hi.abs() < 1e-6);
    }
    assert_eq!(
        file.metadata.get("date").map(String::as_str),
        Some("2023-06-03")
    );
    assert!(
        file.metadata
            .get("skipped pages")
            .is_some_and(|s| s.contains("0 (line"))
    );

    // Trace and retrace show the same surface: display orientation agrees, with the trace
    // displaced along its (Right) scan direction, as feedback lag does.
    let shift = best_horizontal_shift(&trace.z, &retrace.z, 12);
    assert!(
        (1..=12).contains(&shift),
        "trace is shifted by {shift} px relative to retrace"
    );
    eprintln!(
        "real SM4: {} x {} px, pitch {:.4e} x {:.4e} m, period {:.5e} s, trace {:?}, slow {:?}, \
         offset {:?} m, angle {} rad, trace-retrace shift {shift} px, z span {:.3e} m",
        g.columns(),
        g.rows(),
        g.pitch_x(),
        g.pitch_y(),
        g.pixel_period(),
        g.trace_fast(),
        g.slow_direction(),
        g.offset(),
        g.scan_angle(),
        trace.finite_range().map(|(lo, hi)| hi - lo).unwrap_or(0.0),
    );
    eprintln!(
        "real SM4 metadata: {:?}",
        file.metadata.keys().collect::<Vec<_>>()
    );

    // Writing it and reading it back keeps everything.
    let back = assert_round_trip(&file);
    assert_eq!(back.pairs[0].geometry().offset(), g.offset());
}

/// The horizontal shift `s` maximising the correlation of `a[x + s]` with `b[x]`, after
/// removing each line's mean and slope.
fn best_horizontal_shift(a: &Array2<f64>, b: &Array2<f64>, range: isize) -> isize {
    let flatten = |z: &Array2<f64>| {
        let mut out = z.clone();
        for mut row in out.rows_mut() {
            let n = row.len() as f64;
            let mean = row.sum() / n;
            let xm = (n - 1.0) / 2.0;
            let slope = row
                .iter()
                .enumerate()
                .map(|(i, v)| (i as f64 - xm) * (v - mean))
                .sum::<f64>()
                / row
                    .iter()
                    .enumerate()
                    .map(|(i, _)| (i as f64 - xm).powi(2))
                    .sum::<f64>();
            for (i, v) in row.iter_mut().enumerate() {
                *v -= mean + slope * (i as f64 - xm);
            }
        }
        out
    };
    let (a, b) = (flatten(a), flatten(b));
    let columns = a.ncols() as isize;
    (-range..=range)
        .map(|s| {
            let mut sum = 0.0;
            for (ra, rb) in a.rows().into_iter().zip(b.rows()) {
                for x in range..columns - range {
                    sum += ra[(x + s) as usize] * rb[x as usize];
                }
            }
            (s, sum)
        })
        .max_by(|p, q| p.1.total_cmp(&q.1))
        .map(|(s, _)| s)
        .unwrap_or(0)
}

// ---------------------------------------------------------------------------------------
// Cross-check with spym (a Python SM4 reader written independently of ours)

fn repository_root() -> PathBuf {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    root.canonicalize().unwrap_or(root)
}

#[test]
fn spym_reads_what_we_write() {
    let python = std::env::var("PYTHON").unwrap_or_else(|_| "python3".to_string());
    if Command::new(&python).arg("--version").output().is_err() {
        eprintln!("skipped: {python} is not available");
        return;
    }
    // Square (spym's image reshape assumes x size == y size), Right/Left pages (the
    // directions spym labels), slow Down and Up, and a current channel.
    let down = pair(24, 24, Right, Down);
    let g = geometry(24, 24, Right, Up);
    let up = ScanPair::new(
        g,
        ImageChannel::new("Current", "A", surface(24, 24, 9).mapv(|v| v * 0.1)),
        Some(ImageChannel::new(
            "Current",
            "A",
            surface(24, 24, 10).mapv(|v| v * 0.1),
        )),
    )
    .unwrap();
    let file = scan_file(vec![down, up]);
    let directory = tempfile::tempdir().unwrap();
    let sm4_path = directory.path().join("crosscheck.sm4");
    std::fs::write(&sm4_path, to_bytes(&file)).unwrap();

    let mut pages = Vec::new();
    for pair in &file.pairs {
        let g = pair.geometry();
        for (pass, channel) in pair.images() {
            let direction = match g.fast_direction(pass) {
                Right => "Forward",
                _ => "Backward",
            };
            let y_sign = if g.slow_direction() == Up { 1.0 } else { -1.0 };
            let data: Vec<Vec<Option<f64>>> = channel
                .z
                .rows()
                .into_iter()
                .map(|row| row.iter().map(|v| v.is_finite().then_some(*v)).collect())
                .collect();
            pages.push(serde_json::json!({
                "label": format!("{}_{direction}", channel.name),
                "rows": g.rows(),
                "columns": g.columns(),
                "x_scale": -g.pitch_x(),
                "y_scale": y_sign * g.pitch_y(),
                "period": g.pixel_period(),
                "z_unit": channel.unit,
                "tolerance": tolerance(channel) * 1.001,
                "data": data,
            }));
        }
    }
    let expected_path = directory.path().join("crosscheck.json");
    std::fs::write(
        &expected_path,
        serde_json::to_string(&serde_json::json!({ "pages": pages })).unwrap(),
    )
    .unwrap();

    let venv = Path::new(env!("CARGO_TARGET_TMPDIR")).join("spym-venv");
    let output = Command::new(&python)
        .arg(repository_root().join("scripts/spym_sm4_crosscheck.py"))
        .arg(&sm4_path)
        .arg(&expected_path)
        .arg("--venv")
        .arg(&venv)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&output.stdout);
    let stderr = String::from_utf8_lossy(&output.stderr);
    println!("{stdout}");
    assert!(
        output.status.success(),
        "spym cross-check failed ({}):\n{stdout}\n{stderr}",
        output.status
    );
    assert!(stdout.contains("ok: spym"), "{stdout}");
}

// ---------------------------------------------------------------------------------------
// SM3, built from the layout Gwyddion's reader documents (no real SM3 file is available)

struct Sm3Page<'a> {
    data_type: u32,
    scan_dir: u32,
    x_size: u32,
    y_size: u32,
    x_scale: f32,
    y_scale: f32,
    label: &'a str,
    raw: Vec<i32>,
}

fn sm3_bytes(pages: &[Sm3Page<'_>]) -> Vec<u8> {
    let mut out = Vec::new();
    for page in pages {
        let start = out.len();
        out.extend_from_slice(&158u16.to_le_bytes()); // param size: fields up to the page id
        let mut signature: Vec<u16> = "STiMage 004.003 1".encode_utf16().collect();
        signature.resize(18, 0);
        for unit in signature {
            out.extend_from_slice(&unit.to_le_bytes());
        }
        out.extend_from_slice(&12u16.to_le_bytes()); // string count
        let u32s = [
            page.data_type,
            1, // page type: topographic
            0,
            0,
            0,
            0,
            page.x_size,
            page.y_size,
            0,
            0,
            page.scan_dir,
            7,
            4 * page.x_size * page.y_size,
            0,
            0,
        ];
        for v in u32s {
            out.extend_from_slice(&v.to_le_bytes());
        }
        let f32s = [
            page.x_scale,
            page.y_scale,
            1e-12,
            0.0,
            1e-9,
            2e-9,
            5e-9,
            1e-3,
            -2.0,
            1e-10,
            0.0,
        ];
        for v in f32s {
            out.extend_from_slice(&v.to_le_bytes());
        }
        out.extend_from_slice(&[0xab; 16]); // page id
        assert_eq!(out.len() - start, 160);
        let strings = [
            page.label, "", "", "", "", "06/03/23", "19:50:21", "m", "m", "m", "", "",
        ];
        for s in strings {
            let units: Vec<u16> = s.encode_utf16().collect();
            out.extend_from_slice(&(units.len() as u16).to_le_bytes());
            for unit in units {
                out.extend_from_slice(&unit.to_le_bytes());
            }
        }
        for v in &page.raw {
            out.extend_from_slice(&v.to_le_bytes());
        }
        if page.data_type == 0 {
            out.extend_from_slice(&4u16.to_le_bytes());
            out.extend_from_slice(&[0; 4]);
        }
    }
    out
}

fn sm3_example() -> Vec<u8> {
    let raw: Vec<i32> = (0..12).collect();
    sm3_bytes(&[
        Sm3Page {
            data_type: 1, // a spectrum, skipped
            scan_dir: 0,
            x_size: 3,
            y_size: 1,
            x_scale: 0.01,
            y_scale: 1.0,
            label: "dI/dU",
            raw: vec![1, 2, 3],
        },
        Sm3Page {
            data_type: 0,
            scan_dir: 0,
            x_size: 4,
            y_size: 3,
            x_scale: -2e-10,
            y_scale: -3e-10,
            label: "Topography",
            raw: raw.clone(),
        },
        Sm3Page {
            data_type: 0,
            scan_dir: 1,
            x_size: 4,
            y_size: 3,
            x_scale: -2e-10,
            y_scale: -3e-10,
            label: "Topography",
            raw: raw.iter().map(|v| -v).collect(),
        },
    ])
}

#[test]
fn sm3_pages_pair_and_orient_like_sm4() {
    let bytes = sm3_example();
    assert!(sm4::sm3::looks_like_sm3(&bytes));
    assert!(!sm4::looks_like_sm4(&bytes));
    let file = sm4::sm3::read(&bytes).unwrap();
    assert_eq!(file.format, dhct_scan::FileFormat::RhkSm3);
    // Detected by content.
    assert_eq!(dhct_sm4_io::read_bytes(&bytes).unwrap(), file);
    assert_eq!(file.pairs.len(), 1);
    let pair = &file.pairs[0];
    let g = pair.geometry();
    assert_eq!((g.columns(), g.rows()), (4, 3));
    assert_close("pitch x", g.pitch_x(), 2e-10, 1e-6);
    assert_close("pitch y", g.pitch_y(), 3e-10, 1e-6);
    assert_close("period", g.pixel_period(), 1e-3, 1e-6);
    assert_eq!((g.trace_fast(), g.slow_direction()), (Right, Down));
    let trace = &pair.trace().unwrap().z;
    // Negative x scale: stored column 0 is the rightmost; negative y: stored row 0 on top.
    // (z offset 5e-9 m and z scale 1e-12 m are f32 in the file.)
    let near = |a: f64, b: f64| (a - b).abs() < 1e-15;
    assert!(near(trace[[0, 3]], 5e-9));
    assert!(near(trace[[0, 0]], 5e-9 + 3e-12));
    assert!(near(trace[[2, 0]], 5e-9 + 11e-12));
    assert!(near(pair.retrace().unwrap().z[[2, 0]], 5e-9 - 11e-12));
    assert_eq!(
        file.metadata.get("date").map(String::as_str),
        Some("2023-06-03")
    );
    assert!(file.metadata.contains_key("skipped pages"));
}

#[test]
fn sm3_truncations_and_mutations_are_errors_not_panics() {
    let bytes = sm3_example();
    // An SM3 file is a bare sequence of pages, so a cut exactly between two pages is a valid
    // (shorter) file; every other cut is an error.
    let page_starts: Vec<usize> = (0..bytes.len())
        .filter(|&at| sm4::sm3::looks_like_sm3(&bytes[at..]))
        .collect();
    assert_eq!(page_starts.len(), 3);
    for cut in 0..bytes.len() {
        let result = sm4::sm3::read(&bytes[..cut]);
        if !page_starts.contains(&cut) {
            assert!(result.is_err(), "cut at {cut} read fine");
        }
    }
    let mut state = 12345u64;
    for _ in 0..3000 {
        let mut mutated = bytes.clone();
        for _ in 0..4 {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let at = (state >> 33) as usize % mutated.len();
            mutated[at] = (state >> 20) as u8;
        }
        let _ = sm4::sm3::read(&mutated);
    }
}

// ---------------------------------------------------------------------------------------
// Unusable or disagreeing pixel periods: reported, never silent, and the retrace is kept

fn patch_f32(bytes: &mut [u8], at: usize, value: f32) {
    bytes[at..at + 4].copy_from_slice(&value.to_le_bytes());
}

/// A trace/retrace file whose two page headers state `trace` and `retrace` seconds per pixel.
fn file_with_periods(trace: f32, retrace: f32) -> Vec<u8> {
    let mut bytes = small_file();
    let u32_at =
        |bytes: &[u8], at: usize| u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap());
    let first_header = u32_at(&bytes, 98 + 36) as usize;
    let second_header = u32_at(&bytes, 98 + 56 + 36) as usize;
    patch_f32(&mut bytes, first_header + 84, trace);
    patch_f32(&mut bytes, second_header + 84, retrace);
    bytes
}

#[test]
fn unusable_or_disagreeing_periods_are_reported_and_keep_the_retrace() {
    let good = 1.51e-3_f32;
    let cases: [(f32, f32, f64); 7] = [
        (f32::NAN, f32::NAN, dhct_sm4_io::ASSUMED_PIXEL_PERIOD),
        (0.0, 0.0, dhct_sm4_io::ASSUMED_PIXEL_PERIOD),
        (-1e-3, -1e-3, dhct_sm4_io::ASSUMED_PIXEL_PERIOD),
        (1e30, 1e30, dhct_sm4_io::ASSUMED_PIXEL_PERIOD),
        (good, f32::NAN, f64::from(good)),
        (f32::NAN, good, f64::from(good)),
        (good, 10.0 * good, f64::from(good)),
    ];
    for (trace, retrace, expected) in cases {
        let file = sm4::read(&file_with_periods(trace, retrace)).expect("still readable");
        assert_eq!(file.pairs.len(), 1, "{trace} / {retrace}: pages not paired");
        let pair = &file.pairs[0];
        assert!(
            pair.retrace().is_some(),
            "{trace} / {retrace}: retrace dropped"
        );
        let g = pair.geometry();
        assert_eq!(
            g.timing_source(),
            ValueSource::Assumed,
            "{trace} / {retrace}"
        );
        assert_close("period", g.pixel_period(), expected, 1e-6);
        let note = &file.metadata[dhct_sm4_io::ASSUMED_TIMING_KEY];
        assert!(note.contains("s per pixel"), "{note}");
        let warnings = dhct_sm4_io::assumption_warnings(Some(&file), g);
        assert!(
            warnings
                .iter()
                .any(|w| w.contains("timing") && w.contains(note)),
            "{warnings:?}"
        );
    }
    // Agreeing, usable periods: stated, no warning.
    let file = sm4::read(&file_with_periods(good, good)).unwrap();
    let g = file.pairs[0].geometry();
    assert_eq!(g.timing_source(), ValueSource::Stated);
    assert!(dhct_sm4_io::assumption_warnings(Some(&file), g).is_empty());
    // A user-given period replaces the assumption and its note.
    let overrides = dhct_sm4_io::GeometryOverrides {
        pixel_period: Some(2e-3),
        ..Default::default()
    };
    let file = overrides
        .apply_to_file(sm4::read(&file_with_periods(f32::NAN, f32::NAN)).unwrap())
        .unwrap();
    let g = file.pairs[0].geometry();
    assert_eq!(g.timing_source(), ValueSource::Stated);
    assert!(dhct_sm4_io::assumption_warnings(Some(&file), g).is_empty());
}
