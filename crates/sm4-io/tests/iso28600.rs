//! ISO 28600 reader: the vendored real HOPG file, synthetic single- and multi-channel maps,
//! and hostile inputs.

use dhct_scan::{FileFormat, ScanDirection, ValueSource};
use dhct_sm4_io::{ReadError, iso28600, read_path};
use proptest::prelude::*;

const REAL_FILE: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../tests/data/hopg_graphiteterrace.spm"
);

#[test]
fn real_hopg_file_reads_with_stated_scale_and_assumed_timing() {
    let scan = read_path(REAL_FILE.as_ref()).unwrap_or_else(|e| panic!("{REAL_FILE}: {e}"));
    assert_eq!(scan.format, FileFormat::Iso28600);
    assert_eq!(scan.pairs.len(), 1);
    let pair = scan.topography().unwrap();
    let channel = pair.trace().unwrap();
    assert_eq!(channel.name, "Z (Forward)");
    assert_eq!(channel.unit, "m");
    assert!(pair.retrace().is_none());
    let g = pair.geometry();
    assert_eq!((g.columns(), g.rows()), (512, 512));
    assert!(
        (g.width() / 11.48e-9 - 1.0).abs() < 0.001,
        "width {}",
        g.width()
    );
    assert!(
        (g.height() / 11.48e-9 - 1.0).abs() < 0.001,
        "height {}",
        g.height()
    );
    assert!(
        (g.width() / 1.14807e-8 - 1.0).abs() < 1e-12,
        "field of view as stated"
    );
    assert_eq!(g.scale_source(), ValueSource::Stated);
    assert_eq!(g.timing_source(), ValueSource::Assumed);
    assert_eq!(g.pixel_period(), dhct_sm4_io::ASSUMED_PIXEL_PERIOD);
    assert_eq!(g.trace_fast(), ScanDirection::Right, "\"left to right\"");
    assert_eq!(g.slow_direction(), ScanDirection::Down, "\"top to bottom\"");
    // First values of the file fill the top row from the left; the last is bottom-right.
    assert_eq!(channel.z[[0, 0]], 1.5579461e-10);
    assert_eq!(channel.z[[0, 1]], 1.8331518e-10);
    assert_eq!(channel.z[[511, 511]], 9.3093692e-10);
    assert_eq!(channel.non_finite_count(), 0);
    assert_eq!(
        scan.metadata.get("data treatment").map(String::as_str),
        Some("post-treated data")
    );
    assert!(scan.metadata.get("comment").unwrap().contains("Bogus"));
}

/// A 128-line header with sensible defaults, `overrides` replacing lines (1-based).
fn header(overrides: &[(usize, &str)]) -> Vec<String> {
    let mut lines = vec![String::new(); 128];
    let defaults: [(usize, &str); 34] = [
        (1, "ISO/TC 201 SPM data transfer format"),
        (2, "general information"),
        (8, "MAP_SC"),
        (9, "2024"),
        (10, "5"),
        (11, "17"),
        (12, "13"),
        (13, "45"),
        (14, "7"),
        (15, "-1"),
        (16, "scan information"),
        (17, "REGULAR MAPPING"),
        (20, "X"),
        (21, "left to right"),
        (22, "Y"),
        (23, "top to bottom"),
        (24, "4"),
        (25, "3"),
        (26, "nm"),
        (27, "nm"),
        (28, "0.8"),
        (29, "0.9"),
        (48, "environment description"),
        (54, "probe description"),
        (64, "sample description"),
        (68, "single-channel mapping description"),
        (69, "Topography"),
        (70, "nm"),
        (72, "spectroscopy description"),
        (87, "data treatment description"),
        (88, "raw data"),
        (93, "multi-channel mapping description"),
        (94, "1"),
        (128, "end of header"),
    ];
    for (line, text) in defaults.iter().chain(overrides) {
        lines[line - 1] = text.to_string();
    }
    lines
}

fn file(header: &[String], data: &[&str], eol: &str) -> Vec<u8> {
    let mut text = String::new();
    for line in header
        .iter()
        .map(String::as_str)
        .chain(data.iter().copied())
        .chain(["end of experiment"])
    {
        text.push_str(line);
        text.push_str(eol);
    }
    text.into_bytes()
}

fn twelve_values() -> Vec<String> {
    (0..12).map(|i| format!("{}", i as f64 * 0.5)).collect()
}

fn small_file() -> Vec<u8> {
    let values = twelve_values();
    let data: Vec<&str> = values.iter().map(String::as_str).collect();
    file(&header(&[]), &data, "\n")
}

#[test]
fn single_channel_map_with_prefixed_units() {
    let scan = iso28600::read(&small_file()).unwrap();
    let pair = &scan.pairs[0];
    let channel = pair.trace().unwrap();
    assert_eq!(channel.name, "Topography");
    assert_eq!(channel.unit, "m");
    assert_eq!(channel.z.dim(), (3, 4));
    assert!((channel.z[[0, 1]] - 0.5e-9).abs() < 1e-24);
    assert!((channel.z[[2, 3]] - 5.5e-9).abs() < 1e-24);
    let g = pair.geometry();
    assert!((g.pitch_x() - 0.2e-9).abs() < 1e-24 && (g.pitch_y() - 0.3e-9).abs() < 1e-24);
    assert_eq!(g.scale_source(), ValueSource::Stated);
    assert_eq!(g.timing_source(), ValueSource::Assumed, "no scan speed");
    assert_eq!(
        scan.metadata.get("date").map(String::as_str),
        Some("2024-05-17 13:45:07")
    );
}

#[test]
fn multi_channel_map_with_integers_reals_commas_and_crlf() {
    let h = header(&[
        (8, "MAP_MC"),
        (94, "2"),
        (95, "Height"),
        (96, "pm"),
        (98, "Current"),
        (99, "nA"),
        (24, "2"),
        (25, "3"),
    ]);
    let data = ["1, 0.5", "2,1.5e0", "3 , -2", "4\t7", "  5 ,  8.25", "6,9"];
    let scan = iso28600::read(&file(&h, &data, "\r\n")).unwrap();
    assert_eq!(scan.pairs.len(), 2);
    let height = scan.pairs[0].trace().unwrap();
    let current = scan.pairs[1].trace().unwrap();
    assert_eq!(
        (height.name.as_str(), height.unit.as_str()),
        ("Height", "m")
    );
    assert_eq!(
        (current.name.as_str(), current.unit.as_str()),
        ("Current", "A")
    );
    assert_eq!(height.z.dim(), (3, 2));
    let expect_height = [[1.0, 2.0], [3.0, 4.0], [5.0, 6.0]];
    let expect_current = [[0.5, 1.5], [-2.0, 7.0], [8.25, 9.0]];
    for r in 0..3 {
        for c in 0..2 {
            assert!((height.z[[r, c]] - expect_height[r][c] * 1e-12).abs() < 1e-24);
            assert!((current.z[[r, c]] - expect_current[r][c] * 1e-9).abs() < 1e-21);
        }
    }
}

#[test]
fn stated_scan_speed_on_raw_data_gives_stated_timing() {
    let h = header(&[(28, "0.4"), (29, "0.3"), (35, "nm/s"), (36, "200")]);
    let values = twelve_values();
    let data: Vec<&str> = values.iter().map(String::as_str).collect();
    let g = iso28600::read(&file(&h, &data, "\n")).unwrap().pairs[0]
        .geometry()
        .clone();
    assert_eq!(g.timing_source(), ValueSource::Stated);
    // pitch 0.1 nm at 200 nm/s: 0.5 ms per pixel.
    assert!((g.pixel_period() - 0.5e-3).abs() < 1e-15);

    let post = header(&[(35, "nm/s"), (36, "200"), (88, "post-treated data")]);
    let g = iso28600::read(&file(&post, &data, "\n")).unwrap().pairs[0]
        .geometry()
        .clone();
    assert_eq!(g.timing_source(), ValueSource::Assumed);
}

#[test]
fn vertical_fast_axis_and_reversed_directions() {
    let h = header(&[
        (20, "Y"),
        (21, "bottom to top"),
        (22, "X"),
        (23, "right to left"),
    ]);
    let values = twelve_values();
    let data: Vec<&str> = values.iter().map(String::as_str).collect();
    let g = iso28600::read(&file(&h, &data, "\n")).unwrap().pairs[0]
        .geometry()
        .clone();
    assert_eq!(g.trace_fast(), ScanDirection::Up);
    assert_eq!(g.slow_direction(), ScanDirection::Left);
}

#[test]
fn malformed_files_give_typed_errors() {
    let values = twelve_values();
    let data: Vec<&str> = values.iter().map(String::as_str).collect();
    let read = |h: Vec<String>, d: &[&str]| iso28600::read(&file(&h, d, "\n"));

    assert!(matches!(
        read(header(&[(8, "SPEC_SC")]), &data),
        Err(ReadError::Unsupported { .. })
    ));
    assert!(matches!(
        read(header(&[(17, "IRREGULAR MAPPING")]), &data),
        Err(ReadError::Unsupported { .. })
    ));
    assert!(matches!(
        read(header(&[(8, "MOVIE")]), &data),
        Err(ReadError::Corrupt { .. })
    ));
    assert!(matches!(
        read(header(&[(54, "probe")]), &data),
        Err(ReadError::Corrupt { .. })
    ));
    assert!(matches!(
        read(header(&[(8, "MAP_MC"), (94, "9")]), &data),
        Err(ReadError::Corrupt { .. })
    ));
    assert!(matches!(
        read(header(&[(24, "four")]), &data),
        Err(ReadError::Corrupt { .. })
    ));
    assert!(matches!(
        read(header(&[(24, "0")]), &data),
        Err(ReadError::NoImage { .. })
    ));
    assert!(matches!(
        read(header(&[(24, "-4")]), &data),
        Err(ReadError::Corrupt { .. })
    ));
    // Too few, too many and non-numeric points; two values on a single-channel line.
    assert!(read(header(&[]), &data[..11]).is_err());
    let mut more = data.clone();
    more.push("6.0");
    assert!(read(header(&[]), &more).is_err());
    let mut bad = data.clone();
    bad[5] = "five";
    assert!(read(header(&[]), &bad).is_err());
    bad[5] = "5, 6";
    assert!(read(header(&[]), &bad).is_err());
    // No end marker at all.
    let mut no_end = small_file();
    no_end.truncate(no_end.len() - "end of experiment\n".len());
    assert!(matches!(
        iso28600::read(&no_end),
        Err(ReadError::Truncated { .. })
    ));
    // Not ISO 28600.
    assert!(matches!(
        iso28600::read(b"ISO/TC 201 something else\n"),
        Err(ReadError::WrongFormat { .. })
    ));
}

#[test]
fn hostile_sizes_fail_without_allocating() {
    let values = twelve_values();
    let data: Vec<&str> = values.iter().map(String::as_str).collect();
    for (x, y) in [
        ("2147483648", "2147483648"),
        ("18446744073709551615", "18446744073709551615"),
        ("99999999999999999999999", "1"),
        ("100000", "100000"),
    ] {
        let h = header(&[(24, x), (25, y)]);
        assert!(iso28600::read(&file(&h, &data, "\n")).is_err(), "{x} x {y}");
    }
}

#[test]
fn truncation_before_the_end_marker_is_always_an_error() {
    let bytes = small_file();
    let marker_end = bytes
        .windows(17)
        .rposition(|w| w == b"end of experiment")
        .unwrap()
        + 17;
    for cut in 0..marker_end {
        assert!(iso28600::read(&bytes[..cut]).is_err(), "cut at {cut}");
    }
    assert!(iso28600::read(&bytes[..marker_end]).is_ok());

    // A few cuts of the real file, inside the header and inside the data.
    let real = std::fs::read(REAL_FILE).unwrap();
    for cut in [
        0,
        40,
        1000,
        5000,
        real.len() / 2,
        real.len() - 30,
        real.len() - 19,
    ] {
        assert!(
            iso28600::read(&real[..cut]).is_err(),
            "real file cut at {cut}"
        );
    }
}

#[test]
fn random_bytes_are_rejected() {
    let mut state = 0xA0761D6478BD642Fu64;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state as u8
    };
    for len in [0usize, 10, 36, 100, 3000] {
        for _ in 0..20 {
            let mut bytes: Vec<u8> = (0..len).map(|_| next()).collect();
            assert!(iso28600::read(&bytes).is_err());
            if bytes.len() > 40 {
                bytes[..36].copy_from_slice(b"ISO/TC 201 SPM data transfer format\n");
                assert!(iso28600::read(&bytes).is_err());
            }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    #[test]
    fn mutated_files_never_panic(
        edits in prop::collection::vec((0usize..1200, any::<u8>()), 1..8),
        cut in 0usize..1200,
    ) {
        let mut bytes = small_file();
        for (position, value) in edits {
            let len = bytes.len();
            bytes[position % len] = value;
        }
        let cut = cut.min(bytes.len());
        for candidate in [&bytes[..], &bytes[..cut]] {
            if let Ok(scan) = iso28600::read(candidate) {
                for pair in &scan.pairs {
                    prop_assert!(pair.trace().unwrap().z.len() * 2 <= candidate.len());
                }
            }
        }
    }
}
