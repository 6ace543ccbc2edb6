//! Which files `dhct batch` corrects: folders (recursively), glob patterns and files,
//! each file recognised by its content (not its extension); anything else is skipped with
//! a note.

use std::collections::BTreeMap;
use std::io::Read;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use dhct_sm4_io::{FileFormat, detect_format_of_length, limits::open_regular_file};

use crate::output_dir::MARKER;

/// Bytes read to recognise a file's format.
const SNIFF_BYTES: u64 = 4096;

/// One scan file to correct.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Input {
    /// The file.
    pub path: PathBuf,
    /// Its folder relative to the folder or pattern base it was found under (empty for a
    /// file named directly): its output folder goes to the same place under OUTDIR.
    pub relative_dir: PathBuf,
}

/// A file that is not corrected, and why.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Skipped {
    /// The file.
    pub path: PathBuf,
    /// Why it is not corrected.
    pub note: String,
}

/// What the inputs hold: scan files (sorted by path, each once) and skipped files.
#[derive(Debug, Default)]
pub struct Found {
    /// Scan files to correct, sorted by path.
    pub scans: Vec<Input>,
    /// Files that are not corrected.
    pub skipped: Vec<Skipped>,
}

/// Whether `text` is a glob pattern rather than a path.
fn is_pattern(text: &str) -> bool {
    text.contains(['*', '?', '['])
}

/// The folder a pattern's matches are taken relative to: its components before the first
/// one with a wildcard.
fn pattern_base(pattern: &str) -> PathBuf {
    let mut base = PathBuf::new();
    for part in Path::new(pattern).components() {
        if is_pattern(&part.as_os_str().to_string_lossy()) {
            break;
        }
        base.push(part);
    }
    base
}

/// Why `path` is not a scan, or `None` when it is one (recognised by its first bytes; a
/// FIFO or device is never opened for reading).
fn not_a_scan(path: &Path) -> Option<String> {
    let (file, length) = match open_regular_file(path) {
        Ok(opened) => opened,
        Err(e) => return Some(e.to_string()),
    };
    let mut head = Vec::new();
    if let Err(e) = file.take(SNIFF_BYTES).read_to_end(&mut head) {
        return Some(format!("cannot read: {e}"));
    }
    let npy_beside = path.with_extension("npy");
    match detect_format_of_length(&head, length) {
        None if path.extension().is_some_and(|e| e == "json") && npy_beside.is_file() => {
            Some(format!(
                "the JSON sidecar of {} (read with it)",
                npy_beside.display()
            ))
        }
        None => Some("not a scan file (its content is no format dhct reads)".into()),
        Some(FileFormat::Png) => {
            Some("a PNG picture (a mask?), not a scan: name it to dhct correct to use it".into())
        }
        Some(FileFormat::OmicronMatrix) if !dhct_sm4_io::matrix::is_data_file(&head) => Some(
            "an Omicron MATRIX parameter file: it is read with the session's *_mtrx data files"
                .into(),
        ),
        Some(_) => None,
    }
}

/// Whether a folder is to be left out: hidden (staging folders, `.git`), or one dhct wrote.
fn skip_folder(dir: &Path) -> bool {
    let hidden = dir
        .file_name()
        .is_some_and(|n| n.to_string_lossy().starts_with('.'));
    hidden || dir.join(MARKER).exists()
}

impl Found {
    /// Leaves out an NPY retrace whose trace (paired through their sidecars) is among the
    /// scans: it is corrected with that trace, not on its own a second time.
    fn leave_out_paired_retraces(&mut self) {
        let canonical = |p: &Path| p.canonicalize().unwrap_or_else(|_| p.to_path_buf());
        let scans: std::collections::BTreeSet<PathBuf> =
            self.scans.iter().map(|s| canonical(&s.path)).collect();
        let mut kept = Vec::with_capacity(self.scans.len());
        for scan in std::mem::take(&mut self.scans) {
            match dhct_sm4_io::npy_sidecar::paired_trace(&scan.path) {
                Some(trace) if scans.contains(&canonical(&trace)) => self.skipped.push(Skipped {
                    note: format!(
                        "the retrace of {} (their sidecars pair them): corrected with it",
                        trace.display()
                    ),
                    path: scan.path,
                }),
                _ => kept.push(scan),
            }
        }
        self.scans = kept;
    }

    fn add_file(&mut self, path: PathBuf, relative_dir: PathBuf) {
        match not_a_scan(&path) {
            None => self.scans.push(Input { path, relative_dir }),
            Some(note) => self.skipped.push(Skipped { path, note }),
        }
    }

    /// Every file under `dir` (recursively; symbolic links to folders are not followed, so
    /// a link loop cannot trap the walk), relative to `base`.
    fn add_folder(&mut self, dir: &Path, base: &Path, output: &Path) -> Result<()> {
        let mut entries: Vec<PathBuf> = std::fs::read_dir(dir)
            .with_context(|| format!("cannot list {}", dir.display()))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .collect();
        entries.sort();
        for path in entries {
            let hidden = path
                .file_name()
                .is_some_and(|n| n.to_string_lossy().starts_with('.'));
            let Ok(meta) = std::fs::symlink_metadata(&path) else {
                continue;
            };
            if meta.is_dir() {
                if !skip_folder(&path) && !same_file(&path, output) {
                    self.add_folder(&path, base, output)?;
                }
            } else if !hidden && !path.is_dir() {
                let relative = dir
                    .strip_prefix(base)
                    .unwrap_or(Path::new(""))
                    .to_path_buf();
                self.add_file(path, relative);
            }
        }
        Ok(())
    }

    /// One command-line input: a folder, a file or a glob pattern.
    fn add(&mut self, input: &str, output: &Path) -> Result<()> {
        if is_pattern(input) {
            let base = pattern_base(input);
            let matches = glob::glob(input).with_context(|| format!("bad pattern {input}"))?;
            let mut any = false;
            for path in matches.filter_map(Result::ok) {
                any = true;
                let relative = path
                    .parent()
                    .and_then(|p| p.strip_prefix(&base).ok())
                    .unwrap_or(Path::new(""))
                    .to_path_buf();
                if path.is_dir() {
                    if !skip_folder(&path) && !same_file(&path, output) {
                        self.add_folder(&path, &base, output)?;
                    }
                } else {
                    self.add_file(path, relative);
                }
            }
            if !any {
                bail!("the pattern {input} matches no file");
            }
            return Ok(());
        }
        let path = PathBuf::from(input);
        if path.is_dir() {
            self.add_folder(&path, &path, output)
        } else if path.exists() || std::fs::symlink_metadata(&path).is_ok() {
            self.add_file(path, PathBuf::new());
            Ok(())
        } else {
            bail!("{input}: no such file or folder")
        }
    }
}

fn same_file(a: &Path, b: &Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(a), Ok(b)) => a == b,
        _ => false,
    }
}

/// The scan files of `inputs` (folders searched recursively, glob patterns, files), each
/// once, sorted by path; `output` (and any folder dhct wrote) is not searched.
pub fn find(inputs: &[String], output: &Path) -> Result<Found> {
    let mut found = Found::default();
    for input in inputs {
        found.add(input, output)?;
    }
    // Each file once (inputs may overlap), in path order.
    let mut unique: BTreeMap<PathBuf, Input> = BTreeMap::new();
    for scan in found.scans {
        let key = scan
            .path
            .canonicalize()
            .unwrap_or_else(|_| scan.path.clone());
        unique.entry(key).or_insert(scan);
    }
    found.scans = unique.into_values().collect();
    found.scans.sort_by(|a, b| a.path.cmp(&b.path));
    found.leave_out_paired_retraces();
    found.skipped.sort_by(|a, b| a.path.cmp(&b.path));
    found.skipped.dedup();
    Ok(found)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pattern_base_is_the_part_before_the_first_wildcard() {
        assert_eq!(
            pattern_base("data/2024/*/scan?.sm4"),
            Path::new("data/2024")
        );
        assert_eq!(pattern_base("**/*.sxm"), Path::new(""));
        assert!(is_pattern("a/[ab].sm4") && !is_pattern("a/b.sm4"));
    }

    #[test]
    fn files_are_recognised_by_content_not_extension() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        std::fs::write(d.join("notes.sm4"), "just text\n").unwrap();
        std::fs::write(d.join("array.txt"), b"\x93NUMPY\x01\x00").unwrap();
        std::fs::create_dir(d.join("sub")).unwrap();
        std::fs::write(d.join("sub/scan.bin"), "Gwyddion Simple Field 1.0\n").unwrap();
        std::fs::write(d.join("sub/.hidden.gsf"), "Gwyddion Simple Field 1.0\n").unwrap();
        std::fs::create_dir(d.join("old_run")).unwrap();
        std::fs::write(d.join("old_run").join(MARKER), "").unwrap();
        std::fs::write(
            d.join("old_run/corrected.gsf"),
            "Gwyddion Simple Field 1.0\n",
        )
        .unwrap();
        let found = find(&[d.display().to_string()], &d.join("out")).unwrap();
        let scans: Vec<_> = found.scans.iter().map(|s| s.path.clone()).collect();
        assert_eq!(scans, [d.join("array.txt"), d.join("sub/scan.bin")]);
        assert_eq!(found.scans[1].relative_dir, Path::new("sub"));
        assert_eq!(found.skipped.len(), 1);
        assert!(
            found.skipped[0].note.contains("not a scan"),
            "{:?}",
            found.skipped
        );
        // A pattern and an overlapping folder give each file once.
        let pattern = format!("{}/*.txt", d.display());
        let found = find(&[pattern, d.display().to_string()], &d.join("out")).unwrap();
        assert_eq!(found.scans.len(), 2);
        assert!(find(&[format!("{}/*.none", d.display())], d).is_err());
    }
}
