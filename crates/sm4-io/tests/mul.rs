//! The SPECS/Aarhus `.mul` reader against independent readers on real files: Gwyddion 2.62
//! for `.mul` (values converted with `gwyddion --convert-to-gwy`), matkrin/mulfile 0.4.0 for
//! the index-less `.flm` film, which Gwyddion cannot open (its rows flipped into Gwyddion's
//! display orientation). Expected values: min, max, mean and the corners (top-left,
//! top-right, bottom-left) in display orientation, metres.

use std::path::{Path, PathBuf};

use dhct_scan::{FileFormat, ScanDirection, ScanFile, ValueSource};
use dhct_sm4_io::{ReadError, read_bytes, read_path};

fn real(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/data/real")
        .join(name)
}

/// One image as the independent reader gives it.
struct Expected {
    side_m: f64,
    min: f64,
    max: f64,
    mean: f64,
    corners: [f64; 3],
    duration_s: f64,
}

fn check(file: &ScanFile, expected: &[Expected], what: &str) {
    assert_eq!(file.format, FileFormat::AarhusMul, "{what}");
    assert_eq!(file.pairs.len(), expected.len(), "{what}: number of images");
    for (k, (pair, e)) in file.pairs.iter().zip(expected).enumerate() {
        let what = format!("{what} image {}", k + 1);
        let g = pair.geometry();
        assert_eq!((g.columns(), g.rows()), (512, 512), "{what}");
        assert_eq!(g.frame(), k, "{what}: each image is its own frame");
        assert!(pair.retrace().is_none(), "{what}: forward only");
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * b.abs().max(1e-12);
        assert!(
            close(g.width(), e.side_m) && close(g.height(), e.side_m),
            "{what}"
        );
        assert_eq!(g.scale_source(), ValueSource::Stated, "{what}");
        assert_eq!(g.slow_direction(), ScanDirection::Up, "{what}");
        assert_eq!(
            g.timing_source(),
            ValueSource::Assumed,
            "{what}: slow direction"
        );
        // Trace and retrace of each line take the image's duration together.
        let duration = g.frame_duration();
        assert!(close(duration, e.duration_s), "{what}: {duration} s");
        let z = &pair.trace().unwrap().z;
        assert_eq!(pair.trace().unwrap().unit, "m", "{what}");
        let min = z.iter().copied().fold(f64::INFINITY, f64::min);
        let max = z.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let mean = z.sum() / z.len() as f64;
        assert!(
            close(min, e.min) && close(max, e.max),
            "{what}: {min} {max}"
        );
        assert!((mean / e.mean - 1.0).abs() < 1e-9, "{what}: mean {mean}");
        let corners = [z[[0, 0]], z[[0, 511]], z[[511, 0]]];
        for (ours, theirs) in corners.iter().zip(e.corners) {
            assert!(close(*ours, theirs), "{what}: corners {corners:?}");
        }
    }
}

#[test]
fn a_mul_file_reads_as_gwyddion_reads_it() {
    let file = read_path(&real("specs_aarhus_100nm.mul")).unwrap();
    #[rustfmt::skip]
    let expected = [
        Expected { side_m: 1e-7, min: -1.980808823529412e-08, max: -1.4590441176470588e-08,
            mean: -1.7320157541948206e-08, duration_s: 77.32,
            corners: [-1.8396323529411764e-08, -1.9778676470588236e-08, -1.4753676470588235e-08] },
        Expected { side_m: 1e-7, min: -1.7793382352941178e-08, max: -1.3551470588235294e-08,
            mean: -1.6205544704549452e-08, duration_s: 82.82,
            corners: [-1.4363970588235294e-08, -1.6186764705882353e-08, -1.581764705882353e-08] },
        Expected { side_m: 1e-7, min: -1.4422058823529411e-08, max: -1.0093382352941176e-08,
            mean: -1.2225732146992402e-08, duration_s: 123.12,
            corners: [-1.0238970588235293e-08, -1.1703676470588235e-08, -1.2507352941176471e-08] },
        Expected { side_m: 1e-7, min: -1.4155147058823529e-08, max: -9.269117647058822e-09,
            mean: -1.165909062834347e-08, duration_s: 129.34,
            corners: [-9.302205882352941e-09, -1.1425735294117647e-08, -1.2751470588235294e-08] },
    ];
    check(&file, &expected, "specs_aarhus_100nm.mul");
    assert_eq!(
        file.metadata.get("image 1: date").map(String::as_str),
        Some("2021-03-12 13:03:29")
    );
    assert_eq!(file.pairs[0].name(), "image 1 height");
    assert_eq!(file.topography().unwrap().name(), "image 1 height");
}

#[test]
fn a_film_without_index_reads_as_mulfile_reads_it() {
    let file = read_path(&real("specs_aarhus_film_100nm.flm")).unwrap();
    let durations = [38.52, 38.54, 38.53, 38.53, 38.53];
    #[rustfmt::skip]
    let values: [[f64; 6]; 5] = [
        [-1.630698529411765e-08, 5.14889705882353e-09, -8.0318620485418e-09,
         -1.0841911764705885e-08, -1.0498161764705885e-08, -5.724264705882354e-09],
        [-1.5976102941176473e-08, 2.2775735294117652e-09, -9.059719632653631e-09,
         -2.689338235294118e-09, -1.6672794117647062e-09, -1.1954044117647061e-08],
        [-1.5753676470588238e-08, -5.389705882352942e-09, -1.0763364076614382e-08,
         -1.3231617647058826e-08, -1.0612132352941179e-08, -5.389705882352942e-09],
        [-1.921507352941177e-08, -1.0216911764705884e-08, -1.449705291495604e-08,
         -1.2869485294117649e-08, -1.1060661764705884e-08, -1.4568014705882356e-08],
        [-1.8948529411764707e-08, -4.71139705882353e-09, -1.4793831292320703e-08,
         -6.792279411764707e-09, -8.487132352941178e-09, -1.407904411764706e-08],
    ];
    let expected: Vec<Expected> = values
        .iter()
        .zip(durations)
        .map(|(v, duration_s)| Expected {
            side_m: 1e-7,
            min: v[0],
            max: v[1],
            mean: v[2],
            corners: [v[3], v[4], v[5]],
            duration_s,
        })
        .collect();
    check(&file, &expected, "specs_aarhus_film_100nm.flm");
    let angle = file.pairs[0].geometry().scan_angle().to_degrees();
    assert!(
        (angle - 51.0).abs() < 1e-9,
        "tilt 51° is the scan rotation: {angle}"
    );
    assert_eq!(
        file.metadata.get("image 5: date").map(String::as_str),
        Some("2021-03-18 13:57:59")
    );
}

/// The GPL-licensed Aarhus file with an atomic lattice (matkrin/proespm-py3
/// `tests/testdata/stm-aarhus-mul-b.mul`), read from `DHCT_REAL_DATA` when it is there.
#[test]
fn a_mul_file_with_frames_of_two_sizes_reads_as_gwyddion_reads_it() {
    let Some(path) = std::env::var_os("DHCT_REAL_DATA")
        .map(|dir| Path::new(&dir).join("stm-aarhus-mul-b.mul"))
        .filter(|p| p.is_file())
    else {
        eprintln!("note: stm-aarhus-mul-b.mul is not in DHCT_REAL_DATA; not checked");
        return;
    };
    let file = read_path(&path).unwrap();
    #[rustfmt::skip]
    let expected = [
        Expected { side_m: 2e-8, min: -3.6222426470588234e-08, max: -3.414889705882353e-08,
            mean: -3.523363464018878e-08, duration_s: 85.72,
            corners: [-3.415992647058824e-08, -3.5318014705882355e-08, -3.5306985294117644e-08] },
        Expected { side_m: 5e-8, min: -8.304779411764705e-08, max: -7.832794117647059e-08,
            mean: -8.07964670265422e-08, duration_s: 246.34,
            corners: [-7.900735294117647e-08, -8.073161764705882e-08, -8.1725e-08] },
        Expected { side_m: 2e-8, min: -8.158088235294118e-08, max: -7.931617647058824e-08,
            mean: -8.045998785355511e-08, duration_s: 151.41,
            corners: [-7.940882352941176e-08, -8.047426470588235e-08, -8.060808823529411e-08] },
        Expected { side_m: 2e-8, min: -8.143676470588235e-08, max: -7.907941176470588e-08,
            mean: -8.014854137476752e-08, duration_s: 151.42,
            corners: [-7.917205882352941e-08, -8.005735294117647e-08, -8.029411764705882e-08] },
        Expected { side_m: 2e-8, min: -8.029926470588235e-08, max: -7.784411764705882e-08,
            mean: -7.904077191072351e-08, duration_s: 181.53,
            corners: [-7.80860294117647e-08, -7.889926470588235e-08, -7.906397058823529e-08] },
        Expected { side_m: 2e-8, min: -7.56e-08, max: -7.310367647058823e-08,
            mean: -7.420308699046865e-08, duration_s: 181.51,
            corners: [-7.33764705882353e-08, -7.425661764705882e-08, -7.431838235294117e-08] },
    ];
    check(&file, &expected, "stm-aarhus-mul-b.mul");
}

#[test]
fn cut_or_garbled_mul_files_are_refused_with_a_reason() {
    let bytes = std::fs::read(real("specs_aarhus_100nm.mul")).unwrap();
    // Cut inside the first image: not whole blocks.
    let cut = read_bytes(&bytes[..100_000]).unwrap_err();
    assert!(matches!(cut, ReadError::UnknownFormat), "{cut}");
    let cut = dhct_sm4_io::mul::read(&bytes[..100_000]).unwrap_err();
    assert!(cut.to_string().contains("128-byte blocks"), "{cut}");
    // Cut at a block boundary inside the first image: the label no longer fits.
    let cut = dhct_sm4_io::mul::read(&bytes[..128 * 1000]).unwrap_err();
    assert!(!cut.to_string().is_empty());
    // An index entry pointing outside the file.
    let mut bad = bytes.clone();
    bad[8..12].copy_from_slice(&1_000_000i32.to_le_bytes());
    let err = read_bytes(&bad).unwrap_err();
    assert!(err.to_string().contains("outside the file"), "{err}");
    // A label claiming more pixels than its record holds.
    let mut bad = bytes.clone();
    bad[3 * 128 + 4..3 * 128 + 6].copy_from_slice(&4000i16.to_le_bytes());
    assert!(read_bytes(&bad).is_err());
    // Blocks of zeros are not a film.
    assert!(matches!(
        read_bytes(&vec![0u8; 128 * 8]).unwrap_err(),
        ReadError::UnknownFormat
    ));
}
