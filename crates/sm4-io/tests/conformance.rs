//! The contract every reader keeps, checked on every real and example file we have (the
//! scan files of `tests/data` and `tests/data/real`, and of `DHCT_REAL_DATA` when it is
//! set), whatever its format: one shared test, so a new reader gets it for free. Limits and
//! special files are `mutation_corpus.rs`'s; this is what a file that reads must give.
//!
//! * at least one channel; each pair has an image, every image the geometry's size, a
//!   non-empty name, and at least one finite value;
//! * a finite, positive pixel size and pixel period; the scale and timing marked stated or
//!   assumed;
//! * acquisition times that follow the scan: within a line the fast direction's pixels come
//!   later and later, each line starts after the one before, and a retrace pixel is
//!   recorded after the trace pixel of its line;
//! * a trace and a retrace of one channel share a name.

use std::path::{Path, PathBuf};

use dhct_scan::{ScanDirection, ScanFile, ScanGeometry, ScanPass};

/// Every file of `dir` that is not a licence, a text note or a config.
fn files_in(dir: &Path) -> Vec<PathBuf> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    let mut files: Vec<PathBuf> = entries
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.is_file())
        .filter(|p| {
            let name = p.file_name().unwrap().to_string_lossy().to_lowercase();
            !(name.starts_with("license")
                || name.ends_with(".md")
                || name.ends_with(".toml")
                || name.ends_with(".txt"))
        })
        .collect();
    files.sort();
    files
}

/// The pixel of `geometry` that is recorded `k`-th along the fast axis (display column).
fn fast_column(geometry: &ScanGeometry, pass: ScanPass, k: usize) -> usize {
    let last = geometry.columns() - 1;
    let rightwards = match pass {
        ScanPass::Trace => geometry.trace_fast() == ScanDirection::Right,
        ScanPass::Retrace => geometry.trace_fast() != ScanDirection::Right,
    };
    if rightwards { k } else { last - k }
}

/// The display row recorded `k`-th.
fn slow_row(geometry: &ScanGeometry, k: usize) -> usize {
    match geometry.slow_direction() {
        ScanDirection::Up => geometry.rows() - 1 - k,
        _ => k,
    }
}

/// What breaks the contract in `file`, if anything.
fn violations(file: &ScanFile) -> Vec<String> {
    let mut found = Vec::new();
    if file.pairs.is_empty() {
        found.push("no channel".into());
    }
    for pair in &file.pairs {
        let g = pair.geometry();
        let images: Vec<_> = pair.images().collect();
        if images.is_empty() {
            found.push("a pair without an image".into());
        }
        for (pass, image) in &images {
            let label = format!("{} {pass}", image.name);
            if image.z.dim() != (g.rows(), g.columns()) {
                found.push(format!(
                    "{label}: {:?} px, geometry {}×{}",
                    image.z.dim(),
                    g.rows(),
                    g.columns()
                ));
            }
            // The unit may be empty: a dimensionless field (a GWY without `si_unit_z`).
            if image.name.trim().is_empty() {
                found.push(format!("{label}: empty name"));
            }
            if !image.z.iter().any(|v| v.is_finite()) {
                found.push(format!("{label}: no finite value"));
            }
        }
        if let [(_, a), (_, b)] = images.as_slice()
            && a.name != b.name
        {
            found.push(format!(
                "trace {} and retrace {} differ in name",
                a.name, b.name
            ));
        }
        let positive = |v: f64| v.is_finite() && v > 0.0;
        if !(positive(g.pitch_x()) && positive(g.pitch_y()) && positive(g.pixel_period())) {
            found.push(format!(
                "pixel size {} × {} m, pixel period {} s",
                g.pitch_x(),
                g.pitch_y(),
                g.pixel_period()
            ));
            continue;
        }
        found.extend(time_violations(
            g,
            &images.iter().map(|(p, _)| *p).collect::<Vec<_>>(),
        ));
    }
    found
}

/// Acquisition times against the scan order, on a few lines and pixels.
fn time_violations(g: &ScanGeometry, passes: &[ScanPass]) -> Vec<String> {
    let mut found = Vec::new();
    let (columns, rows) = (g.columns(), g.rows());
    let lines = [0, rows / 2, rows.saturating_sub(1)];
    let t = |pass, c: usize, r: usize| {
        g.acquisition_time(pass, c as f64, r as f64)
            .since_frame_start
    };
    for &pass in passes {
        for &k in &lines {
            let r = slow_row(g, k);
            let (first, last) = (fast_column(g, pass, 0), fast_column(g, pass, columns - 1));
            if columns > 1 && t(pass, last, r) <= t(pass, first, r) {
                found.push(format!(
                    "{pass} line {r}: the fast direction's last pixel is not later"
                ));
            }
        }
        if rows > 1 {
            let (r0, r1) = (slow_row(g, 0), slow_row(g, 1));
            let c = fast_column(g, pass, 0);
            if t(pass, c, r1) <= t(pass, c, r0) {
                found.push(format!("{pass}: line {r1} does not start after line {r0}"));
            }
        }
    }
    if passes.contains(&ScanPass::Trace) && passes.contains(&ScanPass::Retrace) {
        let r = slow_row(g, 0);
        let c = fast_column(g, ScanPass::Trace, 0);
        if t(ScanPass::Retrace, c, r) <= t(ScanPass::Trace, c, r) {
            found.push("a retrace pixel is not recorded after its line's trace pixel".into());
        }
    }
    found
}

#[test]
fn every_file_that_reads_keeps_the_reader_contract() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/data");
    let mut files = files_in(&root);
    files.extend(files_in(&root.join("real")));
    if let Some(dir) = std::env::var_os("DHCT_REAL_DATA") {
        files.extend(files_in(Path::new(&dir)));
    }
    let mut read = 0;
    let mut failures = Vec::new();
    for path in &files {
        // A MATRIX parameter file is read through its image file.
        if path.extension().is_some_and(|e| e == "mtrx") {
            continue;
        }
        let Ok(file) = dhct_sm4_io::read_path(path) else {
            continue;
        };
        read += 1;
        let broken = violations(&file);
        if !broken.is_empty() {
            failures.push(format!(
                "{} ({:?}): {}",
                path.display(),
                file.format,
                broken.join("; ")
            ));
        }
    }
    assert!(read >= 15, "only {read} files read");
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
