//! Issue 18's batch acceptance, measured: a folder tree with 20 scans (SM4 files, SM4 files
//! named `.tif` whose stems collide with them, a GSF whose stem collides too, a truncated
//! SM4) and a note that is no scan → 19 results, `summary.csv` and exit status 1; then
//! `--jobs 2` against `--jobs 1` (best of two runs each, release build).
//!
//! ```sh
//! cargo bench -p dhct-cli --bench batch
//! ```

use std::path::Path;
use std::process::Command;
use std::time::Instant;

fn example() -> Vec<u8> {
    let path =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/data/simulated_graphite.sm4");
    std::fs::read(path).expect("the embedded example")
}

/// The tree: `in/{a,b,c,d}/scan{0..3}.sm4` (14 of them), `in/{a,b}/scan{0,1}.tif` (SM4
/// content), `in/a/scan0.gsf` (the trace as GSF), `in/d/broken.sm4` and `in/notes.txt`.
fn tree(root: &Path) -> usize {
    let bytes = example();
    let put = |name: &str, content: &[u8]| {
        let path = root.join("in").join(name);
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(path, content).unwrap();
    };
    let mut scans = 0;
    for folder in ["a", "b", "c", "d"] {
        for k in 0..4 {
            if folder == "d" && k >= 2 {
                continue;
            }
            put(&format!("{folder}/scan{k}.sm4"), &bytes);
            scans += 1;
        }
    }
    for name in ["a/scan0.tif", "a/scan1.tif", "b/scan0.tif", "b/scan1.tif"] {
        put(name, &bytes);
        scans += 1;
    }
    let file = dhct_sm4_io::read_bytes(&bytes).unwrap();
    let pair = file.topography().unwrap();
    let mut gsf = Vec::new();
    dhct_sm4_io::gsf::write_pass(
        pair.trace().unwrap(),
        pair.geometry(),
        dhct_scan::ScanPass::Trace,
        &mut gsf,
    )
    .unwrap();
    put("a/scan0.gsf", &gsf);
    put("d/broken.sm4", &bytes[..bytes.len() / 3]);
    put("notes.txt", b"sample HOPG, tip W, 4 K\n");
    scans + 2
}

/// Runs `dhct batch in -o OUT --jobs N --quiet` twice; the best wall time, s.
fn best_of_two(root: &Path, jobs: usize) -> f64 {
    (0..2)
        .map(|k| {
            let out = format!("out-{jobs}-{k}");
            let start = Instant::now();
            let status = Command::new(env!("CARGO_BIN_EXE_dhct"))
                .current_dir(root)
                .args([
                    "batch",
                    "in",
                    "-o",
                    &out,
                    "--jobs",
                    &jobs.to_string(),
                    "--quiet",
                ])
                .status()
                .unwrap();
            let seconds = start.elapsed().as_secs_f64();
            assert_eq!(status.code(), Some(1), "one file is broken: exit status 1");
            check_summary(&root.join(&out).join("summary.csv"));
            seconds
        })
        .fold(f64::INFINITY, f64::min)
}

/// 19 `ok`, 1 `failed`, 1 `skipped` rows.
fn check_summary(path: &Path) {
    let mut reader = csv::Reader::from_path(path).unwrap();
    let status = reader
        .headers()
        .unwrap()
        .iter()
        .position(|h| h == "status")
        .unwrap();
    let mut counts = std::collections::BTreeMap::new();
    for record in reader.records() {
        *counts
            .entry(record.unwrap()[status].to_string())
            .or_insert(0) += 1;
    }
    let count = |s: &str| counts.get(s).copied().unwrap_or(0);
    assert_eq!(
        (count("ok"), count("failed"), count("skipped")),
        (19, 1, 1),
        "{counts:?}"
    );
}

fn main() {
    let dir = tempfile::tempdir().unwrap();
    let scans = tree(dir.path());
    println!(
        "batch: {scans} scans (one truncated) and one note, {} CPUs",
        available()
    );
    let serial = best_of_two(dir.path(), 1);
    let parallel = best_of_two(dir.path(), 2);
    let speedup = serial / parallel;
    println!("19 results + summary.csv + exit 1 in every run");
    println!(
        "--jobs 1: {serial:.2} s, --jobs 2: {parallel:.2} s: {speedup:.2}× (target ≥ 1.7×: {})",
        if speedup >= 1.7 { "met" } else { "MISSED" }
    );
}

fn available() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}
