//! The outputs asked for beside the default ones: `--displacement` (each pass's
//! displacement field, NPY 2 × rows × columns in metres and a two-page float TIFF, which
//! moves a feature's raw position to its corrected one) and `--channels all` (every other
//! image channel corrected with the one model).

mod common;

use std::path::PathBuf;

use common::correct;

fn example() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/data/simulated_graphite.sm4")
}

/// The `(pages, rows, columns)` array of an NPY stack dhct wrote.
fn read_stack(bytes: &[u8]) -> ((usize, usize, usize), Vec<f64>) {
    let header_len = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
    let header = std::str::from_utf8(&bytes[10..10 + header_len]).unwrap();
    let shape = header.split("'shape': (").nth(1).unwrap();
    let dims: Vec<usize> = shape
        .split(')')
        .next()
        .unwrap()
        .split(',')
        .filter_map(|d| d.trim().parse().ok())
        .collect();
    let data = bytes[10 + header_len..]
        .chunks_exact(8)
        .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
        .collect();
    ((dims[0], dims[1], dims[2]), data)
}

#[test]
fn the_displacement_field_moves_each_feature_to_its_corrected_position() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let output = correct(&example(), &["--displacement"], &out);
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let csv = std::fs::read_to_string(out.join("features.csv")).unwrap();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let (pass, x_px, y_px, x_m, y_m, cx, cy) = (
        col("pass"),
        col("x_px"),
        col("y_px"),
        col("x_m"),
        col("y_m"),
        col("corrected_x_m"),
        col("corrected_y_m"),
    );
    for name in ["trace", "retrace"] {
        assert!(out.join(format!("displacement_{name}.tiff")).exists());
        let bytes = std::fs::read(out.join(format!("displacement_{name}.npy"))).unwrap();
        let ((pages, rows, columns), data) = read_stack(&bytes);
        assert_eq!((pages, rows, columns), (2, 256, 256));
        let at = |page: usize, r: usize, c: usize| data[(page * rows + r) * columns + c];
        let mut checked = 0;
        let mut worst: f64 = 0.0;
        for line in csv.lines().skip(1) {
            let v: Vec<&str> = line.split(',').collect();
            if v[pass] != name || v[cx].is_empty() {
                continue;
            }
            let num = |i: usize| v[i].parse::<f64>().unwrap();
            let (x, y) = (num(x_px), num(y_px));
            if x < 0.0 || y < 0.0 || x >= (columns - 1) as f64 || y >= (rows - 1) as f64 {
                continue;
            }
            // The field interpolated (bilinearly) at the feature's position.
            let (c, r) = (x.floor() as usize, y.floor() as usize);
            let (fx, fy) = (x - c as f64, y - r as f64);
            let field = |page: usize| {
                (1.0 - fy) * ((1.0 - fx) * at(page, r, c) + fx * at(page, r, c + 1))
                    + fy * ((1.0 - fx) * at(page, r + 1, c) + fx * at(page, r + 1, c + 1))
            };
            let ex = num(x_m) + field(0) - num(cx);
            let ey = num(y_m) + field(1) - num(cy);
            worst = worst.max(ex.hypot(ey));
            checked += 1;
        }
        assert!(checked > 100, "{name}: {checked} features");
        assert!(worst < 1e-12, "{name}: worst {worst:e} m");
    }
}

/// `--channels all`: every other image channel of a Nanonis file (current, lock-in, counter)
/// is corrected with the model fitted on the topography: the same pixels are mapped (the
/// same no-data pattern as the corrected topography, pass by pass), the values are the
/// channel's own, and each file keeps the channel's unit.
#[test]
fn every_channel_is_corrected_with_the_one_model() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let input = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/data/real/hbn_defect_nanonis_2nm.sxm");
    let args = [
        "--lattice",
        "hexagonal",
        "--nn",
        "2.504A",
        "--polarity",
        "dark",
        "--channels",
        "all",
    ];
    let output = correct(&input, &args, &out);
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let read = |name: &str| {
        let file = dhct_sm4_io::read_path(&out.join(name)).unwrap();
        file.pairs[0].images().next().unwrap().1.clone()
    };
    let raw = dhct_sm4_io::read_path(&input).unwrap();
    for pass in ["trace", "retrace"] {
        let z = read(&format!("corrected_{pass}.gsf"));
        for channel in ["Current", "LI_Demod_1_X", "LI_Demod_1_Y", "Counter_1"] {
            assert!(
                out.join(format!("corrected_{channel}_{pass}.tiff"))
                    .exists()
            );
            let other = read(&format!("corrected_{channel}_{pass}.gsf"));
            assert_eq!(other.z.dim(), z.z.dim());
            let same_gaps =
                z.z.iter()
                    .zip(other.z.iter())
                    .all(|(a, b)| a.is_nan() == b.is_nan());
            assert!(same_gaps, "{channel} {pass}: not the topography's mapping");
            let source = raw
                .pairs
                .iter()
                .find(|p| p.images().next().unwrap().1.name.replace(' ', "_") == channel)
                .unwrap();
            let values = source.images().next().unwrap().1;
            assert_eq!(other.unit, values.unit, "{channel}");
            let (lo, hi) = values
                .z
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &v| {
                    (l.min(v), h.max(v))
                });
            let span = hi - lo;
            assert!(
                other
                    .z
                    .iter()
                    .filter(|v| v.is_finite())
                    .all(|&v| v >= lo - 0.5 * span && v <= hi + 0.5 * span),
                "{channel} {pass}: values not the channel's"
            );
        }
    }
}

/// `dhct apply MODEL.json FILE`: the model applied to the file it was fitted on writes the
/// same corrected images as `dhct correct`, byte for byte; a file of another scan is
/// refused, naming what differs.
#[test]
fn a_saved_model_applies_to_a_file_of_the_same_scan_only() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    assert!(correct(&example(), &[], &out).status.success());
    let applied = dir.path().join("applied");
    let run = common::dhct()
        .arg("apply")
        .arg(out.join("model.json"))
        .arg(example())
        .arg("-o")
        .arg(&applied)
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    for name in [
        "corrected_trace.gsf",
        "corrected_trace.tiff",
        "corrected_retrace.gsf",
        "corrected_retrace.tiff",
    ] {
        assert_eq!(
            std::fs::read(applied.join(name)).unwrap(),
            std::fs::read(out.join(name)).unwrap(),
            "{name}"
        );
    }
    let other =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/data/hopg_graphiteterrace.spm");
    let refused = common::dhct()
        .arg("apply")
        .arg(out.join("model.json"))
        .arg(other)
        .arg("-o")
        .arg(dir.path().join("refused"))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert_eq!(refused.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("columns is 512") && stderr.contains("256"),
        "{stderr}"
    );
    assert!(!dir.path().join("refused").exists());
}
