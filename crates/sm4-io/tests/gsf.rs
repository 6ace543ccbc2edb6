//! GSF reader and writer: round trips (geometry included), Gwyddion-style files without dhct
//! keys, and hostile inputs.

use dhct_scan::{FileFormat, ImageChannel, ScanDirection, ScanGeometry, ScanPass, ValueSource};
use dhct_sm4_io::{ReadError, gsf, read_bytes};
use ndarray::Array2;
use proptest::prelude::*;

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-12 * a.abs().max(b.abs())
}

/// A non-square image with a NaN, and a geometry with every field set.
fn sample() -> (ImageChannel, ScanGeometry) {
    let mut z = Array2::from_shape_fn((6, 9), |(r, c)| {
        1e-10 * (r as f64 * 0.7 - c as f64 * 0.3).sin()
    });
    z[[2, 5]] = f64::NAN;
    let channel = ImageChannel::new("Topography\nforward", "m", z);
    let geometry = ScanGeometry::new(
        9,
        6,
        0.21e-9,
        0.23e-9,
        1.51e-3,
        ScanDirection::Left,
        ScanDirection::Up,
    )
    .unwrap()
    .with_turnaround(4e-3)
    .unwrap()
    .with_scan_angle(0.25)
    .unwrap()
    .with_offset(-2.35e-7, 1.27e-7)
    .unwrap()
    .with_timing_source(ValueSource::Stated);
    (channel, geometry)
}

#[test]
fn round_trip_preserves_values_and_geometry() {
    let (channel, geometry) = sample();
    let mut bytes = Vec::new();
    gsf::write(&channel, &geometry, &mut bytes).unwrap();
    assert!(bytes.starts_with(b"Gwyddion Simple Field 1.0\n"));
    let data_start = bytes.len() - 6 * 9 * 4;
    assert_eq!(data_start % 4, 0);
    assert_eq!(bytes[data_start - 1], 0);

    let scan = read_bytes(&bytes).unwrap();
    assert_eq!(scan.format, FileFormat::Gsf);
    let pair = &scan.pairs[0];
    assert!(pair.retrace().is_none());
    let back = pair.trace().unwrap();
    assert_eq!(
        back.name, "Topography forward",
        "control characters become spaces"
    );
    assert_eq!(back.unit, "m");
    assert_eq!(back.z.dim(), (6, 9));
    for (a, b) in back.z.iter().zip(channel.z.iter()) {
        let expected = f64::from(*b as f32);
        assert!(a.to_bits() == expected.to_bits(), "{a} vs {expected}");
    }
    let g = pair.geometry();
    assert_eq!((g.columns(), g.rows()), (9, 6));
    assert!(close(g.pitch_x(), 0.21e-9) && close(g.pitch_y(), 0.23e-9));
    assert_eq!(g.pixel_period(), 1.51e-3);
    assert_eq!(g.turnaround_time(), 4e-3);
    assert_eq!(g.trace_fast(), ScanDirection::Left);
    assert_eq!(g.slow_direction(), ScanDirection::Up);
    assert_eq!(g.scan_angle(), 0.25);
    assert_eq!(g.offset(), (-2.35e-7, 1.27e-7));
    assert_eq!(g.scale_source(), ValueSource::Stated);
    assert_eq!(g.timing_source(), ValueSource::Stated);
}

#[test]
fn round_trip_keeps_retrace_pass_and_assumed_sources() {
    let (channel, geometry) = sample();
    let geometry = geometry
        .with_scale_source(ValueSource::Assumed)
        .with_timing_source(ValueSource::Assumed);
    let mut bytes = Vec::new();
    gsf::write_pass(&channel, &geometry, ScanPass::Retrace, &mut bytes).unwrap();
    let scan = gsf::read(&bytes).unwrap();
    let pair = &scan.pairs[0];
    assert!(pair.trace().is_none() && pair.retrace().is_some());
    assert_eq!(pair.geometry().scale_source(), ValueSource::Assumed);
    assert_eq!(pair.geometry().timing_source(), ValueSource::Assumed);
}

#[test]
fn writer_rejects_a_geometry_of_another_size() {
    let (channel, _) = sample();
    let other = ScanGeometry::new(
        6,
        9,
        1e-10,
        1e-10,
        1e-3,
        ScanDirection::Right,
        ScanDirection::Down,
    )
    .unwrap();
    assert!(gsf::write(&channel, &other, &mut Vec::new()).is_err());
}

/// A GSF file as Gwyddion writes it (no dhct keys).
fn gwyddion_file(header_lines: &str, values: &[f32]) -> Vec<u8> {
    let mut out = b"Gwyddion Simple Field 1.0\n".to_vec();
    out.extend_from_slice(header_lines.as_bytes());
    let padding = 4 - out.len() % 4;
    out.extend(std::iter::repeat_n(0u8, padding));
    for v in values {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out
}

#[test]
fn gwyddion_file_without_dhct_keys_gets_assumed_timing() {
    let values: Vec<f32> = (0..12).map(|i| i as f32).collect();
    let file = gwyddion_file(
        "XRes = 4\nYRes = 3\nXReal = 2e-09\nYReal = 1.5e-09\nXYUnits = m\nZUnits = m\nTitle = Height\nXOffset = 1e-9\n",
        &values,
    );
    let scan = gsf::read(&file).unwrap();
    let pair = &scan.pairs[0];
    let z = &pair.trace().unwrap().z;
    assert_eq!(z.dim(), (3, 4));
    assert_eq!(z[[0, 0]], 0.0);
    assert_eq!(z[[0, 3]], 3.0, "row-major: first row holds values 0..3");
    assert_eq!(z[[2, 0]], 8.0);
    let g = pair.geometry();
    assert!(close(g.pitch_x(), 0.5e-9) && close(g.pitch_y(), 0.5e-9));
    assert_eq!(g.scale_source(), ValueSource::Stated);
    assert_eq!(g.timing_source(), ValueSource::Assumed);
    assert_eq!(g.pixel_period(), dhct_sm4_io::ASSUMED_PIXEL_PERIOD);
    assert_eq!(g.trace_fast(), ScanDirection::Right);
    assert_eq!(g.slow_direction(), ScanDirection::Down);
    assert_eq!(pair.name(), "Height");
    assert_eq!(
        scan.metadata.get("XOffset").map(String::as_str),
        Some("1e-9")
    );
}

#[test]
fn unit_prefixes_fold_into_values_and_missing_scale_is_assumed() {
    let file = gwyddion_file(
        "XRes=2\nYRes=1\nXReal=4\nYReal=2\nXYUnits=nm\nZUnits=pA\n",
        &[1.5, -2.0],
    );
    let scan = gsf::read(&file).unwrap();
    let pair = &scan.pairs[0];
    let channel = pair.trace().unwrap();
    assert_eq!(channel.unit, "A");
    assert!(close(channel.z[[0, 0]], 1.5e-12) && close(channel.z[[0, 1]], -2.0e-12));
    assert!(close(pair.geometry().pitch_x(), 2e-9));
    assert!(close(pair.geometry().pitch_y(), 2e-9));
    assert_eq!(pair.name(), gsf::DEFAULT_TITLE);

    let bare = gwyddion_file("XRes = 2\nYRes = 1\n", &[1.0, 2.0]);
    let scan = gsf::read(&bare).unwrap();
    assert_eq!(
        scan.pairs[0].geometry().scale_source(),
        ValueSource::Assumed
    );
    assert_eq!(
        scan.pairs[0].geometry().pitch_x(),
        dhct_sm4_io::ASSUMED_PITCH
    );

    let volts = gwyddion_file(
        "XRes = 2\nYRes = 1\nXReal = 1\nYReal = 1\nXYUnits = V\n",
        &[1.0, 2.0],
    );
    assert_eq!(
        gsf::read(&volts).unwrap().pairs[0]
            .geometry()
            .scale_source(),
        ValueSource::Assumed
    );
}

#[test]
fn malformed_headers_are_errors() {
    let cases = [
        "YRes = 1\n",
        "XRes = 0\nYRes = 1\n",
        "XRes = -3\nYRes = 1\n",
        "XRes = two\nYRes = 1\n",
        "XRes = 2\nYRes = 1\nthis line has no equals sign\n",
        "XRes = 2\nYRes = 1\nDHCT_PixelPeriod = soon\n",
        "XRes = 2\nYRes = 1\nDHCT_TraceFast = sideways\n",
        "XRes = 2\nYRes = 1\nDHCT_Pass = both\n",
        "XRes = 2\nYRes = 1\nDHCT_PixelPeriod = -1\n",
    ];
    for header in cases {
        let file = gwyddion_file(header, &[1.0, 2.0]);
        assert!(gsf::read(&file).is_err(), "{header:?}");
    }
    // Padding that is not NUL.
    let mut file = gwyddion_file("XRes = 2\nYRes = 1\n", &[1.0, 2.0]);
    let nul = file.iter().position(|&b| b == 0).unwrap();
    if nul + 1 < file.len() - 8 {
        file[nul + 1] = b'x';
        assert!(gsf::read(&file).is_err());
    }
}

#[test]
fn hostile_sizes_fail_without_allocating() {
    for header in [
        "XRes = 2147483648\nYRes = 2147483648\n",
        "XRes = 18446744073709551615\nYRes = 18446744073709551615\n",
        "XRes = 99999999999999999999999\nYRes = 1\n",
        "XRes = 1000000\nYRes = 1000000\n",
    ] {
        let file = gwyddion_file(header, &[0.0; 16]);
        assert!(gsf::read(&file).is_err(), "{header:?}");
    }
}

#[test]
fn truncation_at_every_cut_point_is_an_error() {
    let (channel, geometry) = sample();
    let mut bytes = Vec::new();
    gsf::write(&channel, &geometry, &mut bytes).unwrap();
    for cut in 0..bytes.len() {
        assert!(gsf::read(&bytes[..cut]).is_err(), "cut at {cut}");
    }
}

#[test]
fn random_bytes_are_rejected() {
    let mut state = 0x9E3779B97F4A7C15u64;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state as u8
    };
    for len in [0usize, 3, 26, 27, 100, 1000] {
        for _ in 0..20 {
            let mut bytes: Vec<u8> = (0..len).map(|_| next()).collect();
            assert!(gsf::read(&bytes).is_err());
            if bytes.len() > 40 {
                bytes[..26].copy_from_slice(b"Gwyddion Simple Field 1.0\n");
                let _ = gsf::read(&bytes);
            }
        }
    }
    assert!(matches!(
        gsf::read(b"Gwyddion Simple Field 2.0\n"),
        Err(ReadError::WrongFormat { .. })
    ));
}

fn small_valid_file() -> Vec<u8> {
    let (channel, geometry) = sample();
    let mut bytes = Vec::new();
    gsf::write(&channel, &geometry, &mut bytes).unwrap();
    bytes
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    #[test]
    fn mutated_files_never_panic(
        edits in prop::collection::vec((0usize..800, any::<u8>()), 1..8),
        cut in 0usize..800,
    ) {
        let mut bytes = small_valid_file();
        for (position, value) in edits {
            let len = bytes.len();
            bytes[position % len] = value;
        }
        let cut = cut.min(bytes.len());
        for candidate in [&bytes[..], &bytes[..cut]] {
            if let Ok(scan) = gsf::read(candidate) {
                let z = &scan.pairs[0].images().next().unwrap().1.z;
                prop_assert!(z.len() * 4 <= candidate.len());
            }
        }
    }
}

#[test]
fn corrupt_sizes_are_errors_and_missing_ones_reported_assumptions() {
    // A present but corrupt XReal/YReal must not silently become 1 Å per pixel.
    let base = "XRes = 2\nYRes = 1\n";
    for (lines, key) in [
        ("XReal = garbage\nYReal = 1e-9\n", "XReal"),
        ("XReal = nan\nYReal = 1e-9\n", "XReal"),
        ("XReal = 0\nYReal = 1e-9\n", "XReal"),
        ("XReal = 1e300\nYReal = 1e-9\n", "XReal"),
        ("XReal = 2e-9\nYReal = inf\n", "YReal"),
        ("XReal = 2e-9\n", "XReal"),
        (
            "XReal = 2e-9\nYReal = 1e-9\nDHCT_PixelPeriod = 1e30\n",
            "DHCT_PixelPeriod",
        ),
        (
            "XReal = 2e-9\nYReal = 1e-9\nDHCT_ScanAngle = 1e300\n",
            "DHCT_ScanAngle",
        ),
        (
            "XReal = 2e-9\nYReal = 1e-9\nDHCT_TurnaroundTime = 1e9\n",
            "DHCT_TurnaroundTime",
        ),
    ] {
        let header = format!("{base}{lines}");
        let file = gwyddion_file(&header, &[1.0, 2.0]);
        let error = gsf::read(&file).expect_err(&header).to_string();
        assert!(error.contains(key), "{header:?}: {error}");
    }
    // Missing sizes are assumed, and the assumption is recorded and reported.
    let scan = gsf::read(&gwyddion_file("XRes = 2\nYRes = 1\n", &[1.0, 2.0])).unwrap();
    let g = scan.pairs[0].geometry();
    assert_eq!(g.scale_source(), ValueSource::Assumed);
    assert!(scan.metadata[dhct_sm4_io::ASSUMED_SCALE_KEY].contains("XReal"));
    let warnings = dhct_sm4_io::assumption_warnings(Some(&scan), g);
    assert!(
        warnings
            .iter()
            .any(|w| w.contains("pitch") && w.contains("XReal")),
        "{warnings:?}"
    );
    assert!(
        warnings.iter().any(|w| w.contains("timing")),
        "{warnings:?}"
    );
}
