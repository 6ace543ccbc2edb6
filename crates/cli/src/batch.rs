//! `dhct batch DIR -o OUTDIR`: `correct` on every image file of a directory, in parallel,
//! with one summary table; a file that fails is reported and the others go on.
//!
//! Each input gets the folder named by its stem; inputs sharing a stem (`a.sm4`, `a.npy`)
//! get their whole file name instead (`a_sm4`, `a_npy`), so no two write into one folder.
//! The whole OUTDIR is written through a staging folder and moved into place at the end
//! (see [`crate::output_dir`]).

use std::collections::{HashMap, HashSet};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use dhct_sm4_io::write_atomically;
use rayon::prelude::*;
use serde::Serialize;

use crate::correct::{self, CorrectConfig, CorrectRequest};
use crate::output_dir::StagedOutput;

/// The output folder (under `root`) of each of `files`, in order: the stem when it is
/// unique, else the file name with dots as underscores; a number is appended should that
/// still collide.
fn output_folders(root: &Path, files: &[PathBuf]) -> Vec<PathBuf> {
    let stem = |f: &PathBuf| correct::batch_output(root, f);
    let mut counts: HashMap<PathBuf, usize> = HashMap::new();
    for file in files {
        *counts.entry(stem(file)).or_default() += 1;
    }
    let mut taken = HashSet::new();
    files
        .iter()
        .map(|file| {
            let by_stem = stem(file);
            let base = if counts.get(&by_stem) == Some(&1) {
                by_stem
            } else {
                let name = file
                    .file_name()
                    .map(|n| n.to_string_lossy().replace('.', "_"))
                    .unwrap_or_else(|| "input".into());
                root.join(name)
            };
            let mut candidate = base.clone();
            let mut k = 2;
            while !taken.insert(candidate.clone()) {
                candidate = PathBuf::from(format!("{}-{k}", base.display()));
                k += 1;
            }
            candidate
        })
        .collect()
}

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
    let staged = StagedOutput::prepare(output, config.overwrite)?;
    let folders = output_folders(staged.path(), &files);
    let bar = if progress && std::io::IsTerminal::is_terminal(&std::io::stderr()) {
        indicatif::ProgressBar::new(files.len() as u64)
    } else {
        indicatif::ProgressBar::hidden()
    };
    let rows: Vec<BatchRow> = files
        .par_iter()
        .zip(&folders)
        .map(|(file, out)| {
            let start = std::time::Instant::now();
            let result = correct::run(CorrectRequest {
                input: file,
                retrace: None,
                output: out,
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
                        report: out.file_name().map(|name| {
                            output.join(name).join("report.html").display().to_string()
                        }),
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
    write_atomically(&staged.path().join("batch_summary.csv"), |w| {
        std::io::Write::write_all(w, csv.as_bytes()).map_err(Into::into)
    })?;
    staged.commit()?;
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inputs_sharing_a_stem_get_folders_named_with_their_extension() {
        let root = Path::new("out");
        let files: Vec<PathBuf> = ["a.sm4", "a.npy", "b.sxm", "a_sm4.gsf", "c.tar.gz"]
            .iter()
            .map(|f| Path::new("in").join(f))
            .collect();
        let folders = output_folders(root, &files);
        let names: Vec<String> = folders
            .iter()
            .map(|f| f.strip_prefix(root).unwrap().display().to_string())
            .collect();
        assert_eq!(names, ["a_sm4", "a_npy", "b", "a_sm4-2", "c.tar"]);
        let unique: HashSet<_> = folders.iter().collect();
        assert_eq!(unique.len(), folders.len());
    }
}
