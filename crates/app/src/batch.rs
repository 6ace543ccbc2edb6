//! `dhct batch INPUTS... -o OUTDIR`: `correct` on every scan file of folders (searched
//! recursively), glob patterns and files, `--jobs N` at once, with one `summary.csv`; a file
//! that fails is reported and the others go on; `--shard i/n` takes every n-th file for
//! scheduler arrays, and `dhct summarize` merges the shards' tables.
//!
//! Files are recognised by their content (not their extension); anything else is skipped
//! with a note. Each input gets the folder named by its stem, under the same relative
//! folder as it was found in; inputs sharing a stem (`a.sm4`, `a.npy`) get their whole file
//! name instead (`a_sm4`, `a_npy`), so no two write into one folder. The whole OUTDIR is
//! written through a staging folder and moved into place at the end (see
//! [`crate::output_dir`]).

pub mod inputs;
mod table;

use std::collections::{HashMap, HashSet};
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use rayon::prelude::*;

use crate::correct::{self, CorrectConfig, CorrectRequest, RunSummary};
use crate::output_dir::StagedOutput;

pub use inputs::{Found, Input, Skipped, find};
pub use table::{Row, Status, summarize, write_table};

/// The summary table's name in OUTDIR.
pub const SUMMARY_FILE: &str = "summary.csv";

/// One of `count` parts of the sorted file list: the files at positions `index`,
/// `index + count`, ... (0 ≤ index < count).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shard {
    /// This part's number, from 0.
    pub index: usize,
    /// Number of parts.
    pub count: usize,
}

impl std::str::FromStr for Shard {
    type Err = String;
    /// `i/n` with 0 ≤ i < n, e.g. `$SLURM_ARRAY_TASK_ID/$SLURM_ARRAY_TASK_COUNT`.
    fn from_str(text: &str) -> Result<Shard, String> {
        let bad = || format!("'{text}' is not a shard: use i/n with 0 <= i < n, e.g. 3/10");
        let (i, n) = text.split_once('/').ok_or_else(bad)?;
        let index: usize = i.trim().parse().map_err(|_| bad())?;
        let count: usize = n.trim().parse().map_err(|_| bad())?;
        if count == 0 || index >= count {
            return Err(bad());
        }
        Ok(Shard { index, count })
    }
}

/// What `dhct batch` was asked to do.
pub struct BatchRequest<'a> {
    /// Folders (searched recursively), glob patterns and files.
    pub inputs: &'a [String],
    /// The output folder: one folder per corrected file and the summary table.
    pub output: &'a Path,
    /// The settings every file is corrected with.
    pub config: &'a CorrectConfig,
    /// Files corrected at once (threads in all); default: the number of CPUs.
    pub jobs: Option<usize>,
    /// Correct only this part of the sorted file list.
    pub shard: Option<Shard>,
    /// Print the rows as JSON instead of text.
    pub json: bool,
    /// Show progress on stderr (only when it is a terminal).
    pub progress: bool,
}

/// The output folder (under `root`, in the input's relative folder) of each of `files`, in
/// order: the stem when it is unique, else the file name with dots as underscores; a number
/// is appended should that still collide.
fn output_folders(root: &Path, files: &[Input]) -> Vec<PathBuf> {
    let stem = |f: &Input| correct::batch_output(&root.join(&f.relative_dir), &f.path);
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
                    .path
                    .file_name()
                    .map(|n| n.to_string_lossy().replace('.', "_"))
                    .unwrap_or_else(|| "input".into());
                root.join(&file.relative_dir).join(name)
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

/// Runs `correct` on one file into `folder`; the row of the summary table.
fn run_one(file: &Input, folder: &Path, root: &Path, config: &CorrectConfig) -> Row {
    let start = Instant::now();
    let result = correct::run(CorrectRequest {
        input: &file.path,
        retrace: None,
        output: folder,
        config: config.clone(),
        progress: false,
        diagnose: false,
    });
    let seconds = start.elapsed().as_secs_f64();
    let relative = folder.strip_prefix(root).unwrap_or(folder);
    let row = match &result {
        Ok(summary) => Row::ok(&file.path, relative, summary, seconds),
        Err(e) => Row::failed(&file.path, format!("{e:#}"), seconds),
    };
    if let Ok(summary) = &result {
        print_warnings(&file.path, summary);
    }
    row
}

/// The file's warnings on stderr, one line each, prefixed with the file.
fn print_warnings(path: &Path, summary: &RunSummary) {
    let text: String = summary
        .warnings
        .iter()
        .map(|w| {
            let line = crate::flags::warning_line(w);
            format!("warning: {}: {line}\n", path.display())
        })
        .collect();
    let _ = std::io::stderr().lock().write_all(text.as_bytes());
}

/// The files of this shard (all without `--shard`), and the notes of skipped files.
fn select(request: &BatchRequest) -> Result<(Vec<Input>, Vec<Skipped>)> {
    let Found { scans, skipped } = find(request.inputs, request.output)?;
    if scans.is_empty() {
        let names = request.inputs.join(", ");
        bail!("{names} holds no scan files (SM4, SXM, ISO 28600, GSF, NPY, TIFF, ...)");
    }
    Ok(match request.shard {
        None => (scans, skipped),
        Some(Shard { index, count }) => (
            scans.into_iter().skip(index).step_by(count).collect(),
            // Each shard lists the skipped files once: the first.
            if index == 0 { skipped } else { Vec::new() },
        ),
    })
}

/// Runs `dhct batch`: every scan of the request into its folder under OUTDIR and
/// `summary.csv`; fails (after writing everything) when any file failed.
pub fn run(request: &BatchRequest) -> Result<()> {
    let (all, skipped) = select(request)?;
    for s in &skipped {
        eprintln!("note: skipping {}: {}", s.path.display(), s.note);
    }
    let staged = StagedOutput::prepare(request.output, request.config.overwrite)?;
    let root = staged.path().to_path_buf();
    let folders = output_folders(&root, &all);
    let jobs = request
        .jobs
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(jobs.max(1))
        .build()
        .context("cannot start the worker threads")?;
    let bar = if request.progress && std::io::IsTerminal::is_terminal(&std::io::stderr()) {
        indicatif::ProgressBar::new(all.len() as u64)
    } else {
        indicatif::ProgressBar::hidden()
    };
    let mut rows: Vec<Row> = pool.install(|| {
        all.par_iter()
            .zip(&folders)
            .map(|(file, folder)| {
                let row = run_one(file, folder, &root, request.config);
                bar.inc(1);
                row
            })
            .collect()
    });
    bar.finish_and_clear();
    rows.extend(skipped.iter().map(Row::skipped));
    write_table(&root.join(SUMMARY_FILE), &rows)?;
    staged.commit()?;
    report(request, &rows)
}

/// Prints the rows (text or JSON) and fails when any file failed.
fn report(request: &BatchRequest, rows: &[Row]) -> Result<()> {
    let mut out = String::new();
    if request.json {
        out = serde_json::to_string_pretty(rows)? + "\n";
    } else {
        for r in rows {
            out.push_str(&r.line());
            out.push('\n');
        }
        out.push_str(&format!(
            "summary: {}\n",
            request.output.join(SUMMARY_FILE).display()
        ));
    }
    crate::diagnose::write_stdout(&out)?;
    let failed = rows.iter().filter(|r| r.status == Status::Failed).count();
    if failed > 0 {
        let total = rows.iter().filter(|r| r.status != Status::Skipped).count();
        bail!("{failed} of {total} files failed (see above); the others were written");
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inputs_sharing_a_stem_get_folders_named_with_their_extension() {
        let root = Path::new("out");
        let files: Vec<Input> = ["a.sm4", "a.npy", "b.sxm", "a_sm4.gsf", "c.tar.gz"]
            .iter()
            .map(|f| Input {
                path: Path::new("in").join(f),
                relative_dir: PathBuf::new(),
            })
            .collect();
        let folders = output_folders(root, &files);
        let names: Vec<String> = folders
            .iter()
            .map(|f| f.strip_prefix(root).unwrap().display().to_string())
            .collect();
        assert_eq!(names, ["a_sm4", "a_npy", "b", "a_sm4-2", "c.tar"]);
        let unique: HashSet<_> = folders.iter().collect();
        assert_eq!(unique.len(), folders.len());
        // Files found in sub-folders keep them; the same stem in two folders is no clash.
        let nested: Vec<Input> = ["x/a.sm4", "y/a.sm4"]
            .iter()
            .map(|f| Input {
                path: Path::new("in").join(f),
                relative_dir: Path::new(f).parent().unwrap().to_path_buf(),
            })
            .collect();
        let folders = output_folders(root, &nested);
        assert_eq!(folders, [root.join("x/a"), root.join("y/a")]);
    }

    #[test]
    fn shards_parse_and_refuse_nonsense() {
        assert_eq!(
            "3/10".parse(),
            Ok(Shard {
                index: 3,
                count: 10
            })
        );
        for bad in ["10/10", "1/0", "a/b", "3", "-1/4"] {
            assert!(bad.parse::<Shard>().is_err(), "{bad}");
        }
    }
}
