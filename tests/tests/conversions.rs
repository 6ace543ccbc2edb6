//! Every real file we may read goes through every writer and back through content-based
//! detection: data and scales must survive. Files that may not be vendored are read from
//! `DHCT_REAL_DATA` (a set variable with a missing file fails the test).

use std::path::{Path, PathBuf};

use dhct_scan::{FileFormat, ScanFile, ScanPair};
use dhct_sm4_io::{gsf, npy, read_bytes, read_path, sm4, tiff_file};

fn vendored(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("data")
        .join(name)
}

/// The real files available in this run.
fn real_files() -> Vec<PathBuf> {
    let mut files = vec![vendored("hopg_graphiteterrace.spm")];
    match std::env::var_os("DHCT_REAL_DATA") {
        Some(dir) => {
            for name in [
                "pb_pt111_2023-06-01-0087.SM4",
                "tise2_nanonis_generic_5e.sxm",
            ] {
                let path = Path::new(&dir).join(name);
                assert!(
                    path.is_file(),
                    "DHCT_REAL_DATA is set but {} is missing",
                    path.display()
                );
                files.push(path);
            }
        }
        None => eprintln!("DHCT_REAL_DATA is not set: converting only the vendored file"),
    }
    files
}

fn max_difference(a: &ndarray::Array2<f64>, b: &ndarray::Array2<f64>) -> f64 {
    assert_eq!(a.dim(), b.dim());
    a.iter()
        .zip(b.iter())
        .filter(|(x, y)| x.is_finite() || y.is_finite())
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

fn span(pair: &ScanPair) -> f64 {
    let (lo, hi) = pair.trace().unwrap().finite_range().unwrap();
    hi - lo
}

#[test]
fn every_real_file_survives_every_writer() {
    for path in real_files() {
        let file = read_path(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let pair = file.topography().unwrap().clone();
        let trace = pair.trace().unwrap();
        let geometry = pair.geometry();
        let name = path.file_name().unwrap().to_string_lossy().to_string();
        let tolerance_f32 = 1e-6 * span(&pair).max(trace.finite_range().unwrap().1.abs());

        // SM4: the whole pair, native format with timing.
        let mut bytes = Vec::new();
        let single = ScanFile {
            format: FileFormat::RhkSm4,
            pairs: vec![pair.clone()],
            metadata: Default::default(),
        };
        sm4::write(&single, &mut bytes).unwrap();
        let back = read_bytes(&bytes).unwrap();
        assert_eq!(back.format, FileFormat::RhkSm4, "{name}");
        let back_pair = back.topography().unwrap();
        let g = back_pair.geometry();
        assert_eq!(
            (g.columns(), g.rows()),
            (geometry.columns(), geometry.rows()),
            "{name}"
        );
        assert!(
            (g.pitch_x() / geometry.pitch_x() - 1.0).abs() < 1e-6,
            "{name}"
        );
        assert!(
            (g.pixel_period() / geometry.pixel_period() - 1.0).abs() < 1e-6,
            "{name}"
        );
        assert_eq!(g.trace_fast(), geometry.trace_fast(), "{name}");
        assert_eq!(g.slow_direction(), geometry.slow_direction(), "{name}");
        assert_eq!(
            back_pair.retrace().is_some(),
            pair.retrace().is_some(),
            "{name}"
        );
        // i32 quantisation of the full span: 2^-31 relative.
        let quantum = span(&pair) / 2f64.powi(30);
        assert!(
            max_difference(&back_pair.trace().unwrap().z, &trace.z) <= quantum,
            "{name} SM4"
        );

        // GSF: single image with physical size.
        let mut bytes = Vec::new();
        gsf::write(trace, geometry, &mut bytes).unwrap();
        let back = read_bytes(&bytes).unwrap();
        assert_eq!(back.format, FileFormat::Gsf, "{name}");
        let back_pair = back.topography().unwrap();
        assert!(
            (back_pair.geometry().width() / geometry.width() - 1.0).abs() < 1e-6,
            "{name}"
        );
        assert!(
            max_difference(&back_pair.trace().unwrap().z, &trace.z) <= tolerance_f32,
            "{name} GSF"
        );

        // NPY: exact values (f64).
        let mut bytes = Vec::new();
        npy::write(trace, &mut bytes).unwrap();
        let back = read_bytes(&bytes).unwrap();
        assert_eq!(back.format, FileFormat::Npy, "{name}");
        assert_eq!(
            max_difference(&back.topography().unwrap().trace().unwrap().z, &trace.z),
            0.0,
            "{name} NPY"
        );

        // Float TIFF: f32 values.
        let mut bytes = std::io::Cursor::new(Vec::new());
        tiff_file::write_f32(trace, &mut bytes).unwrap();
        let back = read_bytes(bytes.get_ref()).unwrap();
        assert_eq!(back.format, FileFormat::Tiff, "{name}");
        assert!(
            max_difference(&back.topography().unwrap().trace().unwrap().z, &trace.z)
                <= tolerance_f32,
            "{name} TIFF"
        );
    }
}
