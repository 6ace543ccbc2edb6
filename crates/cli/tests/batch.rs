//! `dhct batch` at facility scale, run as a user would: a folder tree with stems colliding
//! across folders and formats, a file that is no scan and a broken scan; globs; `--jobs`;
//! shards merged by `dhct summarize`.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn example() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/data/simulated_graphite.sm4")
}

fn dhct(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_dhct"))
        .current_dir(dir)
        .args(args)
        .output()
        .unwrap()
}

/// in/a/x.sm4, in/a/x.tif (an SM4 named .tif: read by content), in/b/x.sm4,
/// in/b/deeper/y.gsf.sm4, in/notes.sm4 (text: no scan), in/b/broken.sm4 (a truncated SM4),
/// in/.hidden/z.sm4 (hidden: not searched).
fn tree(root: &Path) {
    let bytes = std::fs::read(example()).unwrap();
    let put = |name: &str, content: &[u8]| {
        let path = root.join("in").join(name);
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(path, content).unwrap();
    };
    for name in [
        "a/x.sm4",
        "a/x.tif",
        "b/x.sm4",
        "b/deeper/y.gsf.sm4",
        ".hidden/z.sm4",
    ] {
        put(name, &bytes);
    }
    put("notes.sm4", b"measured on Tuesday\n");
    put("b/broken.sm4", &bytes[..bytes.len() / 3]);
}

/// summary.csv as rows of column -> cell.
fn table(path: &Path) -> Vec<BTreeMap<String, String>> {
    let mut reader = csv::Reader::from_path(path).unwrap();
    let header: Vec<String> = reader.headers().unwrap().iter().map(String::from).collect();
    reader
        .records()
        .map(|r| {
            let r = r.unwrap();
            header
                .iter()
                .cloned()
                .zip(r.iter().map(String::from))
                .collect()
        })
        .collect()
}

fn by_status<'a>(rows: &'a [BTreeMap<String, String>], status: &str) -> Vec<&'a str> {
    let mut inputs: Vec<&str> = rows
        .iter()
        .filter(|r| r["status"] == status)
        .map(|r| r["input"].as_str())
        .collect();
    inputs.sort();
    inputs
}

#[test]
fn a_folder_tree_gives_one_folder_per_scan_and_a_summary_table() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    tree(d);
    let out = dhct(d, &["batch", "in", "-o", "out", "--jobs", "2", "--quiet"]);
    let (stdout, stderr) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    // One file failed: exit 1, everything else written.
    assert_eq!(out.status.code(), Some(1), "{stdout}\n{stderr}");
    assert!(stderr.contains("1 of 5 files failed"), "{stderr}");
    assert!(
        stderr.contains("note: skipping in/notes.sm4: not a scan file"),
        "{stderr}"
    );
    // Per-file warnings, each naming its file.
    assert!(stderr.contains("warning: in/a/x.sm4: "), "{stderr}");
    for folder in ["a/x_sm4", "a/x_tif", "b/x", "b/deeper/y.gsf"] {
        let report = d.join("out").join(folder).join("report.html");
        assert!(report.is_file(), "missing {folder}: {stdout}");
    }
    assert!(!d.join("out/.hidden").exists() && !d.join("out/z").exists());
    let rows = table(&d.join("out/summary.csv"));
    assert_eq!(
        by_status(&rows, "ok"),
        [
            "in/a/x.sm4",
            "in/a/x.tif",
            "in/b/deeper/y.gsf.sm4",
            "in/b/x.sm4"
        ]
    );
    assert_eq!(by_status(&rows, "failed"), ["in/b/broken.sm4"]);
    assert_eq!(by_status(&rows, "skipped"), ["in/notes.sm4"]);
    let ok = rows.iter().find(|r| r["input"] == "in/a/x.sm4").unwrap();
    let a: f64 = ok["lattice_constant_x_m"].parse().unwrap();
    assert!((a - 2.46e-10).abs() < 0.05e-10, "{a}");
    let v_x: f64 = ok["v_x [m/s]"].parse().unwrap();
    assert!(v_x.is_finite() && !ok["v_x sigma [m/s]"].is_empty());
    assert!(ok["warnings"].contains("degenerate_parameters"), "{ok:?}");
    assert_eq!(ok["output"], "a/x_sm4");
    let failed = rows.iter().find(|r| r["status"] == "failed").unwrap();
    assert!(failed["error"].contains("broken.sm4"), "{failed:?}");
    // The same files in one job give the same parameters (the order of work is no input).
    let serial = dhct(
        d,
        &["batch", "in", "-o", "serial", "--jobs", "1", "--quiet"],
    );
    assert_eq!(serial.status.code(), Some(1));
    let serial_rows = table(&d.join("serial/summary.csv"));
    let serial_ok = serial_rows
        .iter()
        .find(|r| r["input"] == "in/a/x.sm4")
        .unwrap();
    assert_eq!(serial_ok["v_x [m/s]"], ok["v_x [m/s]"]);
}

#[test]
fn globs_shards_and_summarize() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    tree(d);
    // A pattern takes only what it matches; folders it names mirror below its base.
    let out = dhct(d, &["batch", "in/*/x.*", "-o", "glob", "--quiet"]);
    assert_eq!(out.status.code(), Some(0), "{out:?}");
    let rows = table(&d.join("glob/summary.csv"));
    assert_eq!(
        by_status(&rows, "ok"),
        ["in/a/x.sm4", "in/a/x.tif", "in/b/x.sm4"]
    );
    assert!(d.join("glob/a/x_tif/model.json").is_file());
    // Two shards cover every file once; merged they equal one run.
    for shard in ["0/2", "1/2"] {
        let o = format!("shard{}", &shard[..1]);
        let run = dhct(d, &["batch", "in", "-o", &o, "--shard", shard, "--quiet"]);
        assert!(run.status.code().is_some(), "{run:?}");
    }
    let s0 = table(&d.join("shard0/summary.csv"));
    let s1 = table(&d.join("shard1/summary.csv"));
    assert!(!s0.is_empty() && !s1.is_empty());
    let merged = dhct(
        d,
        &["summarize", "shard0", "shard1/summary.csv", "-o", "all.csv"],
    );
    let text = String::from_utf8_lossy(&merged.stdout);
    assert_eq!(merged.status.code(), Some(0), "{merged:?}");
    assert!(
        text.contains("6 files: 4 ok, 1 failed, 1 skipped"),
        "{text}"
    );
    let all = table(&d.join("all.csv"));
    assert_eq!(by_status(&all, "ok").len(), 4);
    assert_eq!(by_status(&all, "failed"), ["in/b/broken.sm4"]);
    // Bad shards and inputs are refused with the reason.
    let bad = dhct(d, &["batch", "in", "-o", "x", "--shard", "2/2"]);
    assert_eq!(bad.status.code(), Some(2));
    let none = dhct(d, &["batch", "in/*.none", "-o", "x"]);
    assert!(String::from_utf8_lossy(&none.stderr).contains("matches no file"));
    let not_table = dhct(d, &["summarize", "in/notes.sm4", "-o", "y.csv"]);
    assert_eq!(not_table.status.code(), Some(1));
}

#[test]
fn an_npy_pair_with_sidecars_is_one_scan() {
    // trace.npy + retrace.npy with the sidecars dhct writes: corrected once, as a pair.
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let file = dhct_sm4_io::read_path(&example()).unwrap();
    let pair = file.topography().unwrap();
    std::fs::create_dir_all(d.join("in")).unwrap();
    for (pass, image) in pair.images() {
        let mut bytes = Vec::new();
        dhct_sm4_io::npy::write(image, &mut bytes).unwrap();
        std::fs::write(d.join(format!("in/{pass}.npy")), bytes).unwrap();
        let sidecar = dhct_sm4_io::npy::Sidecar::new(image, pair.geometry(), pass, Vec::new());
        std::fs::write(
            d.join(format!("in/{pass}.json")),
            serde_json::to_string(&sidecar).unwrap(),
        )
        .unwrap();
    }
    let out = dhct(d, &["batch", "in", "-o", "out", "--quiet"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    let rows = table(&d.join("out/summary.csv"));
    assert_eq!(by_status(&rows, "ok"), ["in/trace.npy"]);
    assert_eq!(
        by_status(&rows, "skipped"),
        ["in/retrace.json", "in/retrace.npy", "in/trace.json"]
    );
    assert!(stderr.contains("the retrace of in/trace.npy"), "{stderr}");
    assert!(
        stderr.contains("the JSON sidecar of in/trace.npy"),
        "{stderr}"
    );
    // The same result as the SM4 the arrays came from: both passes, the same geometry.
    std::fs::create_dir_all(d.join("sm4")).unwrap();
    std::fs::copy(example(), d.join("sm4/example.sm4")).unwrap();
    let sm4 = dhct(d, &["batch", "sm4", "-o", "out-sm4", "--quiet"]);
    assert_eq!(sm4.status.code(), Some(0));
    let sm4_rows = table(&d.join("out-sm4/summary.csv"));
    let ok = rows.iter().find(|r| r["status"] == "ok").unwrap();
    for column in ["features", "indexed", "v_x [m/s]", "lattice_constant_x_m"] {
        assert_eq!(ok[column], sm4_rows[0][column], "{column}");
    }
    // `correct` names the file the retrace came from.
    let single = dhct(d, &["correct", "in/trace.npy", "-o", "single", "--quiet"]);
    assert_eq!(single.status.code(), Some(0));
    let model: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("single/model.json")).unwrap())
            .unwrap();
    assert_eq!(model["retrace_input"], "in/retrace.npy");
}
