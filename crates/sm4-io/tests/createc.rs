//! Createc `.dat` reader: the real file in `tests/data/real`, synthetic files that pin the
//! layout (leading dummy value, channel order, aborted scans) and hostile inputs.

use std::io::Write as _;
use std::path::PathBuf;

use dhct_scan::{FileFormat, ScanDirection, ScanPass, ValueSource};
use dhct_sm4_io::{ReadError, ReadLimits, read_bytes, read_bytes_limited, read_path};

fn real_file() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/data/real/createc_atomic_11nm.dat")
}

#[test]
fn the_real_file_reads_with_its_size_channels_directions_and_timing() {
    let file = read_path(&real_file()).unwrap();
    assert_eq!(file.format, FileFormat::CreatecDat);
    let names: Vec<&str> = file.pairs.iter().map(|p| p.name()).collect();
    assert_eq!(names, ["Z", "Current"]);
    let z = file.topography().unwrap();
    assert_eq!(z.name(), "Z");
    let g = z.geometry();
    assert_eq!((g.columns(), g.rows()), (512, 512));
    let pitch = 112.5034e-10 / 512.0;
    assert!((g.pitch_x() / pitch - 1.0).abs() < 1e-12 && (g.pitch_y() / pitch - 1.0).abs() < 1e-12);
    assert!((g.pixel_period() / (0.328 / 512.0) - 1.0).abs() < 1e-12);
    assert_eq!(g.fast_direction(ScanPass::Trace), ScanDirection::Right);
    assert_eq!(g.fast_direction(ScanPass::Retrace), ScanDirection::Left);
    assert_eq!(g.slow_direction(), ScanDirection::Down);
    assert_eq!(g.scale_source(), ValueSource::Stated);
    assert_eq!(g.timing_source(), ValueSource::Stated);
    for pair in &file.pairs {
        assert!(pair.trace().is_some() && pair.retrace().is_some());
    }
    // Topography in metres: a sub-nanometre corrugation, no NaN.
    let trace = z.trace().unwrap();
    assert_eq!(trace.unit, "m");
    assert_eq!(trace.non_finite_count(), 0);
    let (lo, hi) = trace.finite_range().unwrap();
    assert!(hi - lo > 1e-11 && hi - lo < 2e-9, "z span {}", hi - lo);
    // The current calibration puts the mean |current| at the 300 pA setpoint.
    let current = file.pairs[1].trace().unwrap();
    assert_eq!(current.unit, "A");
    let mean = current.z.iter().map(|v| v.abs()).sum::<f64>() / current.z.len() as f64;
    assert!((mean / 3.0e-10 - 1.0).abs() < 0.05, "mean |I| = {mean:e} A");
    // The backward image is stored in display orientation: after removing each line's mean
    // it correlates with the forward image as stored, and not once mirrored.
    let retrace = z.retrace().unwrap().z.clone();
    let levelled = |z: &ndarray::Array2<f64>| {
        let mut z = z.clone();
        for mut row in z.rows_mut() {
            let mean = row.mean().unwrap();
            row.mapv_inplace(|v| v - mean);
        }
        z
    };
    let forward = levelled(&trace.z);
    let correlation = |other: &ndarray::Array2<f64>| {
        let other = levelled(other);
        (&forward * &other).sum() / ((&forward * &forward).sum() * (&other * &other).sum()).sqrt()
    };
    let as_stored = correlation(&retrace);
    let mirrored_lr = correlation(&retrace.slice(ndarray::s![.., ..;-1]).to_owned());
    let mirrored_ud = correlation(&retrace.slice(ndarray::s![..;-1, ..]).to_owned());
    assert!(
        as_stored > 0.4 && as_stored > mirrored_lr && as_stored > mirrored_ud,
        "{as_stored} vs {mirrored_lr}, {mirrored_ud}"
    );
}

/// A synthetic `[Paramco32]` file: `channels` images of `columns × rows`, value
/// `1000·image + 10·row + column` (counts), after one dummy value.
fn synthetic(columns: usize, rows: usize, channels: usize, select: u32, extra: &str) -> Vec<u8> {
    let mut header = String::from("[Paramco32]\r\nDAC-Type=20bit\r\n");
    header.push_str(&format!(
        "Num.X / Num.X={columns}\r\nNum.Y / Num.Y={rows}\r\nGainZ / GainZ=10\r\n\
         Gainpreamp / GainPre 10^=9\r\nChannels / Channels={channels}\r\n\
         Channelselectval / Channelselectval={select}\r\nZPiezoconst / ZPiezoconst= 19.20\r\n\
         Dacto[A]z=0.00037\r\nLength x[A]=20.0\r\nLength y[A]=30.0\r\nSec/line:=0.5\r\n{extra}"
    ));
    let mut out = header.into_bytes();
    out.extend_from_slice(b"\0\0\0\nDATA");
    let mut values = vec![0f32];
    for image in 0..channels {
        for r in 0..rows {
            for c in 0..columns {
                values.push((1000 * image + 10 * r + c) as f32 + 1.0);
            }
        }
    }
    values.extend([0f32; 7]);
    let mut encoder = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::fast());
    for v in values {
        encoder.write_all(&v.to_le_bytes()).unwrap();
    }
    out.extend(encoder.finish().unwrap());
    out
}

#[test]
fn forward_then_backward_images_pair_by_signal_after_the_dummy_value() {
    let file = read_bytes(&synthetic(4, 3, 4, 3, "")).unwrap();
    let z_count = 20.0 / 2f64.powi(20) * 19.2 * 10.0 * 1e-10;
    let i_count = 20.0 / 2f64.powi(20) / 1e9;
    let (z, current) = (&file.pairs[0], &file.pairs[1]);
    assert_eq!((z.name(), current.name()), ("Z", "Current"));
    let expect = |image: usize, r: usize, c: usize| (1000 * image + 10 * r + c) as f64 + 1.0;
    for r in 0..3 {
        for c in 0..4 {
            let close = |a: f64, b: f64| (a / b - 1.0).abs() < 1e-12;
            assert!(close(
                z.trace().unwrap().z[[r, c]],
                expect(0, r, c) * z_count
            ));
            assert!(close(
                current.trace().unwrap().z[[r, c]],
                expect(1, r, c) * i_count
            ));
            assert!(close(
                z.retrace().unwrap().z[[r, c]],
                expect(2, r, c) * z_count
            ));
            assert!(close(
                current.retrace().unwrap().z[[r, c]],
                expect(3, r, c) * i_count
            ));
        }
    }
    let g = z.geometry();
    assert!((g.pitch_x() - 5e-10).abs() < 1e-20 && (g.pitch_y() - 1e-9).abs() < 1e-20);
    assert!((g.line_scan_time() - 0.5).abs() < 1e-12);
}

#[test]
fn forward_only_files_and_auxiliary_signals_are_read() {
    let file = read_bytes(&synthetic(3, 2, 3, 0b101, "")).unwrap_err();
    assert!(file.to_string().contains("Channels=3"), "{file}");
    let file = read_bytes(&synthetic(3, 2, 2, 0b101, "")).unwrap();
    assert_eq!(file.pairs.len(), 2);
    assert_eq!(file.pairs[1].name(), "Aux1");
    assert_eq!(file.pairs[1].trace().unwrap().unit, "DAC");
    assert_eq!(
        file.pairs[1].trace().unwrap().z[[1, 2]],
        1000.0 + 12.0 + 1.0
    );
    assert!(file.pairs[0].retrace().is_none());
}

#[test]
fn lines_never_acquired_become_nan_and_are_reported() {
    let mut bytes = synthetic(3, 4, 2, 1, "");
    // Rebuild with the last two rows zero in both images.
    let start = bytes.windows(5).position(|w| w == b"\nDATA").unwrap() + 5;
    let mut values = vec![0f32];
    for image in 0..2 {
        for r in 0..4 {
            for c in 0..3 {
                values.push(if r < 2 {
                    (image * 100 + r * 3 + c + 1) as f32
                } else {
                    0.0
                });
            }
        }
    }
    let mut encoder = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::fast());
    for v in values {
        encoder.write_all(&v.to_le_bytes()).unwrap();
    }
    bytes.truncate(start);
    bytes.extend(encoder.finish().unwrap());
    let file = read_bytes(&bytes).unwrap();
    let z = file.pairs[0].trace().unwrap();
    assert_eq!(z.non_finite_count(), 6);
    assert!(z.z[[1, 2]].is_finite() && z.z[[2, 0]].is_nan());
    assert!(file.metadata["incomplete scan"].contains("2 of 4"));
}

#[test]
fn hostile_and_foreign_headers_give_typed_errors() {
    let cases: [(&str, Vec<u8>); 6] = [
        ("old variant", b"[Paramet32]\r\nNum.X=2\r\n".to_vec()),
        ("no DATA", b"[Paramco32]\r\nNum.X=2\r\n".to_vec()),
        (
            "huge",
            synthetic(2, 2, 2, 1, "").replace_first(b"Num.X / Num.X=2", b"Num.X / Num.X=65536"),
        ),
        (
            "bad Dacto",
            synthetic(2, 2, 2, 1, "").replace_first(b"Dacto[A]z=0.00037", b"Dacto[A]z=0.00100"),
        ),
        ("cut stream", {
            let b = synthetic(8, 8, 2, 1, "");
            b[..b.len() - 40].to_vec()
        }),
        (
            "no DAC type",
            synthetic(2, 2, 2, 1, "").replace_first(b"DAC-Type=20bit", b"DAC-Type=lots"),
        ),
    ];
    for (what, bytes) in cases {
        let error = read_bytes(&bytes).expect_err(what);
        assert!(
            matches!(
                error,
                ReadError::Unsupported { .. }
                    | ReadError::Truncated { .. }
                    | ReadError::Corrupt { .. }
                    | ReadError::OverBudget { .. }
            ),
            "{what}: {error}"
        );
    }
    // A header claiming many large channels hits the budget before anything is inflated.
    let bytes = synthetic(2, 2, 2, 1, "")
        .replace_first(b"Num.X / Num.X=2", b"Num.X / Num.X=60000")
        .replace_first(b"Num.Y / Num.Y=2", b"Num.Y / Num.Y=60000");
    let error = read_bytes_limited(&bytes, &ReadLimits::default()).unwrap_err();
    assert!(matches!(error, ReadError::OverBudget { .. }), "{error}");
}

trait ReplaceFirst {
    fn replace_first(&self, from: &[u8], to: &[u8]) -> Vec<u8>;
}

impl ReplaceFirst for Vec<u8> {
    fn replace_first(&self, from: &[u8], to: &[u8]) -> Vec<u8> {
        let at = self
            .windows(from.len())
            .position(|w| w == from)
            .expect("pattern present");
        let mut out = self[..at].to_vec();
        out.extend_from_slice(to);
        out.extend_from_slice(&self[at + from.len()..]);
        out
    }
}
