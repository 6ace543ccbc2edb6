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

/// Columns `names` of a CSV text, as text rows.
fn csv_columns(text: &str, names: &[&str]) -> Vec<Vec<String>> {
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let at: Vec<usize> = names
        .iter()
        .map(|n| {
            header
                .iter()
                .position(|h| h == n)
                .unwrap_or_else(|| panic!("{n}"))
        })
        .collect();
    lines
        .map(|l| {
            let cells: Vec<&str> = l.split(',').collect();
            at.iter().map(|&k| cells[k].to_string()).collect()
        })
        .collect()
}

/// `dhct apply MODEL.json --points POINTS.csv`: features' raw positions given as points
/// (in pixels, in metres, with and without their acquisition time) land on the features'
/// corrected positions within 0.01 px, with a finite 1σ; a point off the frame and a file
/// without position columns are refused, naming the row and the columns.
#[test]
fn points_map_onto_the_corrected_features() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    assert!(correct(&example(), &[], &out).status.success());
    let features = std::fs::read_to_string(out.join("features.csv")).unwrap();
    let names = ["pass", "x_px", "y_px", "x_m", "y_m", "time_s"];
    let rows: Vec<Vec<String>> = csv_columns(&features, &names)
        .into_iter()
        .chain(csv_columns(&features, &["corrected_x_m", "corrected_y_m"]))
        .collect();
    let half = rows.len() / 2;
    let (raw, corrected) = rows.split_at(half);
    let pitch = raw[1][3].parse::<f64>().unwrap() / raw[1][1].parse::<f64>().unwrap();
    let picked: Vec<usize> = (0..half).step_by(half / 60).collect();
    let apply = |points: &str, name: &str| {
        let path = dir.path().join(format!("{name}.csv"));
        std::fs::write(&path, points).unwrap();
        let folder = dir.path().join(name);
        let run = common::dhct()
            .arg("apply")
            .arg(out.join("model.json"))
            .arg("--points")
            .arg(&path)
            .arg("-o")
            .arg(&folder)
            .output()
            .unwrap();
        (run, folder)
    };
    for (form, header) in [
        ("pixels", "label,pass,x_px,y_px"),
        ("metres", "label,pass,x_m,y_m"),
        ("timed", "label,pass,x_px,y_px,t_s"),
    ] {
        let mut text = format!("{header}\n");
        for &k in &picked {
            let r = &raw[k];
            let (x, y) = match form {
                "metres" => (&r[3], &r[4]),
                _ => (&r[1], &r[2]),
            };
            let time = if form == "timed" {
                format!(",{}", r[5])
            } else {
                String::new()
            };
            text.push_str(&format!("p{k},{},{x},{y}{time}\n", r[0]));
        }
        let (run, folder) = apply(&text, form);
        assert!(
            run.status.success(),
            "{}",
            String::from_utf8_lossy(&run.stderr)
        );
        let mapped = std::fs::read_to_string(folder.join("points_corrected.csv")).unwrap();
        let columns = [
            "label",
            "corrected_x_m",
            "corrected_y_m",
            "sigma_x_m",
            "sigma_y_m",
        ];
        let mapped = csv_columns(&mapped, &columns);
        assert_eq!(mapped.len(), picked.len());
        for (row, &k) in mapped.iter().zip(&picked) {
            assert_eq!(row[0], format!("p{k}"));
            let value = |s: &String| s.parse::<f64>().unwrap();
            for axis in 0..2 {
                let miss = (value(&row[1 + axis]) - value(&corrected[k][axis])).abs() / pitch;
                assert!(miss < 0.01, "{form} p{k}: {miss} px");
                let sigma = value(&row[3 + axis]) / pitch;
                assert!(
                    sigma.is_finite() && sigma > 0.0 && sigma < 1.0,
                    "{form}: σ {sigma} px"
                );
            }
        }
    }
    let (off, folder) = apply("x_px,y_px\n10,10\n9999,3\n", "off");
    let stderr = String::from_utf8_lossy(&off.stderr);
    assert_eq!(off.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("row 2") && stderr.contains("outside"),
        "{stderr}"
    );
    assert!(!folder.exists());
    let (unnamed, _) = apply("a,b\n10,10\n", "unnamed");
    let stderr = String::from_utf8_lossy(&unnamed.stderr);
    assert!(
        stderr.contains("x_px") && stderr.contains("its columns are a, b"),
        "{stderr}"
    );
}

/// A GSF header's value of `key`.
fn gsf_number(bytes: &[u8], key: &str) -> f64 {
    let text = String::from_utf8_lossy(&bytes[..bytes.len().min(4096)]).into_owned();
    text.lines()
        .find_map(|l| l.strip_prefix(&format!("{key} = ")))
        .unwrap_or_else(|| panic!("{key} missing"))
        .trim()
        .parse()
        .unwrap()
}

/// `--extent full`: the corrected GSF holds every corrected pixel on a grid of the same
/// pitch, its origin in XOffset/YOffset; where it overlaps the frame it holds the frame's
/// values, it holds pixels the frame crops, and every feature's corrected position lies on
/// it; `dhct apply --extent full` writes the same file.
#[test]
fn the_full_extent_keeps_every_corrected_pixel() {
    let dir = tempfile::tempdir().unwrap();
    let (frame, full) = (dir.path().join("frame"), dir.path().join("full"));
    assert!(correct(&example(), &[], &frame).status.success());
    let run = correct(&example(), &["--extent", "full"], &full);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let read = |dir: &std::path::Path| {
        let bytes = std::fs::read(dir.join("corrected_trace.gsf")).unwrap();
        let file = dhct_sm4_io::gsf::read(&bytes).unwrap();
        (bytes, file.pairs[0].trace().unwrap().z.clone())
    };
    let ((_, z_frame), (bytes, z_full)) = (read(&frame), read(&full));
    let pitch = gsf_number(&bytes, "XReal") / gsf_number(&bytes, "XRes");
    let origin = [
        (gsf_number(&bytes, "XOffset") / pitch).round() as i64,
        (gsf_number(&bytes, "YOffset") / pitch).round() as i64,
    ];
    let finite = |z: &ndarray::Array2<f64>| z.iter().filter(|v| v.is_finite()).count();
    assert!(finite(&z_full) > finite(&z_frame));
    for ((r, c), v) in z_frame.indexed_iter() {
        let (rf, cf) = (r as i64 - origin[1], c as i64 - origin[0]);
        if rf < 0 || cf < 0 || rf >= z_full.nrows() as i64 || cf >= z_full.ncols() as i64 {
            assert!(v.is_nan(), "({r}, {c}) is data off the full grid");
            continue;
        }
        let w = z_full[[rf as usize, cf as usize]];
        assert!(
            (v.is_nan() && w.is_nan()) || (v - w).abs() <= 1e-6 * v.abs(),
            "({r}, {c})"
        );
    }
    let features = std::fs::read_to_string(full.join("features.csv")).unwrap();
    let positions = csv_columns(&features, &["corrected_x_m", "corrected_y_m"]);
    let size = [z_full.ncols() as f64, z_full.nrows() as f64];
    for row in &positions {
        let p: Vec<f64> = row
            .iter()
            .map(|v| v.parse::<f64>().unwrap() / pitch)
            .collect();
        let on_grid = (0..2).all(|k| (-0.5..size[k] - 0.5).contains(&(p[k] - origin[k] as f64)));
        assert!(on_grid, "{p:?} off the full grid at {origin:?} {size:?}");
    }
    // `dhct apply --extent full` with the saved model writes the same full grid.
    let applied = dir.path().join("applied");
    let run = common::dhct()
        .args(["apply", "--extent", "full", "-o"])
        .arg(&applied)
        .arg(full.join("model.json"))
        .arg(example())
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    assert_eq!(
        std::fs::read(applied.join("corrected_trace.gsf")).unwrap(),
        bytes,
        "apply --extent full writes what correct --extent full wrote"
    );
}
