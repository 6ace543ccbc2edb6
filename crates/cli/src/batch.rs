//! `dhct batch DIR -o OUTDIR`: `correct` on every image file of a directory, in parallel,
//! with one summary table; a file that fails is reported and the others go on.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use dhct_sm4_io::write_atomically;
use rayon::prelude::*;
use serde::Serialize;

use crate::correct::{self, CorrectConfig, CorrectRequest};

/// One input's outcome.
#[derive(Serialize)]
struct BatchRow {
    input: String,
    ok: bool,
    error: Option<String>,
    features: usize,
    lattice_constant_x_m: Option<f64>,
    lattice_constant_y_m: Option<f64>,
    rms_deviation_m: Option<f64>,
    ellipse_major_m: Option<f64>,
    ellipse_minor_m: Option<f64>,
    seconds: f64,
    report: Option<String>,
}

/// Files of `dir` (not recursive) that look like scan files, sorted by name; hidden files
/// and our own outputs are skipped.
fn inputs(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("cannot list {}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file())
        .filter(|p| {
            let name = p
                .file_name()
                .map(|n| n.to_string_lossy().to_lowercase())
                .unwrap_or_default();
            !name.starts_with('.')
                && [
                    ".sm4", ".spm", ".sxm", ".txt", ".gsf", ".npy", ".tif", ".tiff", ".sm3", ".iso",
                ]
                .iter()
                .any(|ext| name.ends_with(ext))
        })
        .collect();
    files.sort();
    Ok(files)
}

pub fn run(
    dir: &Path,
    output: &Path,
    config: &CorrectConfig,
    json: bool,
    progress: bool,
) -> Result<()> {
    let files = inputs(dir)?;
    if files.is_empty() {
        bail!(
            "{} holds no scan files (.sm4, .spm, .sxm, .gsf, .npy, .tif, ...)",
            dir.display()
        );
    }
    std::fs::create_dir_all(output)
        .with_context(|| format!("cannot create {}", output.display()))?;
    let bar = if progress && std::io::IsTerminal::is_terminal(&std::io::stderr()) {
        indicatif::ProgressBar::new(files.len() as u64)
    } else {
        indicatif::ProgressBar::hidden()
    };
    let rows: Vec<BatchRow> = files
        .par_iter()
        .map(|file| {
            let start = std::time::Instant::now();
            let out = correct::batch_output(output, file);
            let result = correct::run(CorrectRequest {
                input: file,
                retrace: None,
                output: &out,
                config: config.clone(),
                progress: false,
                diagnose: false,
            });
            bar.inc(1);
            let seconds = start.elapsed().as_secs_f64();
            match result {
                Ok(s) => {
                    let r = s.regions.first();
                    BatchRow {
                        input: file.display().to_string(),
                        ok: true,
                        error: None,
                        features: s.passes.iter().map(|p| p.features).sum(),
                        lattice_constant_x_m: r.map(|r| r.lattice_constant_m[0]),
                        lattice_constant_y_m: r.map(|r| r.lattice_constant_m[1]),
                        rms_deviation_m: r.map(|r| r.rms_deviation_m),
                        ellipse_major_m: r.map(|r| r.whole_ellipse.sigma_major_m),
                        ellipse_minor_m: r.map(|r| r.whole_ellipse.sigma_minor_m),
                        seconds,
                        report: Some(out.join("report.html").display().to_string()),
                    }
                }
                Err(e) => BatchRow {
                    input: file.display().to_string(),
                    ok: false,
                    error: Some(format!("{e:#}")),
                    features: 0,
                    lattice_constant_x_m: None,
                    lattice_constant_y_m: None,
                    rms_deviation_m: None,
                    ellipse_major_m: None,
                    ellipse_minor_m: None,
                    seconds,
                    report: None,
                },
            }
        })
        .collect();
    bar.finish_and_clear();

    let opt = |v: Option<f64>| v.map(|v| format!("{v:e}")).unwrap_or_default();
    let mut csv = String::from(
        "input,ok,features,lattice_constant_x_m,lattice_constant_y_m,rms_deviation_m,ellipse_major_m,ellipse_minor_m,seconds,error\n",
    );
    for r in &rows {
        let _ = writeln!(
            csv,
            "\"{}\",{},{},{},{},{},{},{},{:.3},\"{}\"",
            r.input.replace('"', "\"\""),
            r.ok,
            r.features,
            opt(r.lattice_constant_x_m),
            opt(r.lattice_constant_y_m),
            opt(r.rms_deviation_m),
            opt(r.ellipse_major_m),
            opt(r.ellipse_minor_m),
            r.seconds,
            r.error
                .as_deref()
                .unwrap_or("")
                .replace('"', "\"\"")
                .replace('\n', " ")
        );
    }
    write_atomically(&output.join("batch_summary.csv"), |w| {
        std::io::Write::write_all(w, csv.as_bytes()).map_err(Into::into)
    })?;
    if json {
        println!("{}", serde_json::to_string_pretty(&rows)?);
    } else {
        for r in &rows {
            match (&r.error, r.lattice_constant_x_m, r.lattice_constant_y_m) {
                (Some(e), _, _) => println!("FAILED {}: {}", r.input, e.replace('\n', " ")),
                (None, Some(ax), Some(ay)) => println!(
                    "ok     {}: {} features, a = {:.4} x {:.4} Å, {:.2} s",
                    r.input,
                    r.features,
                    ax * 1e10,
                    ay * 1e10,
                    r.seconds
                ),
                _ => println!("ok     {}: {} features", r.input, r.features),
            }
        }
        println!("summary: {}", output.join("batch_summary.csv").display());
    }
    let failed = rows.iter().filter(|r| !r.ok).count();
    if failed > 0 {
        bail!(
            "{failed} of {} files failed (see above); the others were written",
            rows.len()
        );
    }
    Ok(())
}
