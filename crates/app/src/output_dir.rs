//! Output folders that are written whole or not at all.
//!
//! A run takes a lock beside its output folder (`.NAME.dhct-lock`, holding its process id;
//! created exclusively, so a second run into the same `-o` stops with an error naming the
//! first), writes everything into a fresh staging folder beside it
//! (`.NAME.dhct-staging-PID`) and renames that into place when it is done. A folder that
//! already exists is replaced only if it is empty, or, with `--overwrite`, if it holds an
//! earlier dhct run (it has the [`MARKER`] file or one of dhct's result files); a folder
//! holding anything else is never touched. Staging folders and locks left by killed runs
//! (their process is gone) are removed the next time the same output is used; a run that
//! fails removes its own.

use std::fs;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};

/// File written into every output folder: marks it as a dhct run that `--overwrite` may
/// replace.
pub const MARKER: &str = ".dhct-output";

/// Files that mark folders written before [`MARKER`] existed.
const RESULT_FILES: [&str; 4] = [
    "model.json",
    "diagnosis.json",
    "batch_summary.csv",
    "validation.json",
];

/// An output folder being written: the staging folder and the lock, released on drop (the
/// staging folder is removed unless [`StagedOutput::commit`] moved it into place).
#[derive(Debug)]
pub struct StagedOutput {
    target: PathBuf,
    staging: PathBuf,
    lock: PathBuf,
    overwrite: bool,
    committed: bool,
}

/// `NAME`'s sibling `.NAME.SUFFIX`.
fn sibling(target: &Path, suffix: &str) -> Result<PathBuf> {
    let name = target
        .file_name()
        .with_context(|| format!("output {} has no folder name", target.display()))?;
    let parent = match target.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    Ok(parent.join(format!(".{}.{suffix}", name.to_string_lossy())))
}

/// Whether process `pid` is a running dhct (on Linux, from `/proc`; elsewhere any pid
/// counts as running, so nothing of a live run is ever removed).
fn dhct_running(pid: u32) -> bool {
    if pid == std::process::id() {
        return true;
    }
    let proc = Path::new("/proc");
    if !proc.is_dir() {
        return true;
    }
    match fs::read(proc.join(pid.to_string()).join("cmdline")) {
        Ok(cmdline) => String::from_utf8_lossy(&cmdline).contains("dhct"),
        Err(_) => false,
    }
}

impl StagedOutput {
    /// Locks `target`, checks it may be (re)placed, removes what killed runs left beside it,
    /// and creates a fresh staging folder. Fails before any analysis is done when the folder
    /// holds foreign files, or an earlier run's without `overwrite`, or another run holds
    /// the lock.
    pub fn prepare(target: &Path, overwrite: bool) -> Result<StagedOutput> {
        // `-o .` or `-o ..` name a folder only once resolved.
        let resolved;
        let target = if target.file_name().is_none() {
            resolved = fs::canonicalize(target)
                .with_context(|| format!("cannot resolve the output {}", target.display()))?;
            resolved.as_path()
        } else {
            target
        };
        check_replaceable(target, overwrite)?;
        let lock = take_lock(target)?;
        let staged = StagedOutput {
            target: target.to_path_buf(),
            staging: sibling(target, &format!("dhct-staging-{}", std::process::id()))?,
            lock,
            overwrite,
            committed: false,
        };
        remove_stale_staging(target)?;
        if staged.staging.exists() {
            fs::remove_dir_all(&staged.staging).with_context(|| {
                format!("cannot remove old staging {}", staged.staging.display())
            })?;
        }
        fs::create_dir_all(&staged.staging)
            .with_context(|| format!("cannot create output folder {}", staged.staging.display()))?;
        let marker = format!(
            "written by dhct {} (process {})\n",
            env!("CARGO_PKG_VERSION"),
            std::process::id()
        );
        fs::write(staged.staging.join(MARKER), marker)
            .with_context(|| format!("cannot write into {}", staged.staging.display()))?;
        Ok(staged)
    }

    /// Where to write (the staging folder).
    pub fn path(&self) -> &Path {
        &self.staging
    }

    /// Moves the staging folder into place (replacing an empty folder, or with `overwrite`
    /// an earlier run's) and releases the lock.
    pub fn commit(mut self) -> Result<()> {
        check_replaceable(&self.target, self.overwrite)?;
        let previous = sibling(&self.target, &format!("dhct-old-{}", std::process::id()))?;
        let replaced = if self.target.exists() {
            fs::rename(&self.target, &previous)
                .with_context(|| format!("cannot move the old {} aside", self.target.display()))?;
            true
        } else {
            false
        };
        fs::rename(&self.staging, &self.target).with_context(|| {
            format!(
                "cannot move {} into place as {}",
                self.staging.display(),
                self.target.display()
            )
        })?;
        self.committed = true;
        if replaced {
            fs::remove_dir_all(&previous)
                .with_context(|| format!("cannot remove the old output {}", previous.display()))?;
        }
        Ok(())
    }
}

impl Drop for StagedOutput {
    fn drop(&mut self) {
        if !self.committed {
            let _ = fs::remove_dir_all(&self.staging);
        }
        let _ = fs::remove_file(&self.lock);
    }
}

/// Whether `target` may be replaced: it does not exist, is an empty folder, or (with
/// `overwrite`) holds an earlier dhct run.
fn check_replaceable(target: &Path, overwrite: bool) -> Result<()> {
    let metadata = match fs::symlink_metadata(target) {
        Ok(m) => m,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        Err(e) => return Err(e).with_context(|| format!("cannot inspect {}", target.display())),
    };
    if !metadata.is_dir() {
        bail!(
            "output {} exists and is not a folder; choose another -o",
            target.display()
        );
    }
    let entries: Vec<String> = fs::read_dir(target)
        .with_context(|| format!("cannot list {}", target.display()))?
        .filter_map(|e| e.ok().map(|e| e.file_name().to_string_lossy().into_owned()))
        .collect();
    if entries.is_empty() {
        return Ok(());
    }
    let ours = entries
        .iter()
        .any(|e| e == MARKER || RESULT_FILES.contains(&e.as_str()));
    let example = entries
        .iter()
        .find(|e| !e.starts_with('.'))
        .or(entries.first())
        .cloned()
        .unwrap_or_default();
    match (ours, overwrite) {
        (true, true) => Ok(()),
        (true, false) => bail!(
            "output folder {} already holds an earlier dhct run ({} entries, e.g. {example}); \
             give --overwrite to replace it, or choose another -o",
            target.display(),
            entries.len()
        ),
        (false, _) => bail!(
            "output folder {} is not empty and holds files dhct did not write (e.g. {example}); \
             choose another -o (dhct replaces only empty folders and, with --overwrite, its \
             own earlier runs)",
            target.display()
        ),
    }
}

/// Creates the lock file exclusively; a lock whose process is gone is stale and taken over.
fn take_lock(target: &Path) -> Result<PathBuf> {
    let lock = sibling(target, "dhct-lock")?;
    if let Some(parent) = lock.parent() {
        fs::create_dir_all(parent)
            .with_context(|| format!("cannot create the folder {}", parent.display()))?;
    }
    for _ in 0..2 {
        match fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&lock)
        {
            Ok(mut file) => {
                use std::io::Write as _;
                writeln!(file, "{}", std::process::id())
                    .with_context(|| format!("cannot write the lock {}", lock.display()))?;
                return Ok(lock);
            }
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
                let holder = fs::read_to_string(&lock)
                    .ok()
                    .and_then(|t| t.trim().parse::<u32>().ok());
                match holder {
                    Some(pid) if dhct_running(pid) => bail!(
                        "another dhct run (process {pid}) is writing {}; wait for it or \
                         choose another -o",
                        target.display()
                    ),
                    _ => {
                        // A killed run's lock (or one being written this instant: retried).
                        let _ = fs::remove_file(&lock);
                    }
                }
            }
            Err(e) => {
                return Err(e)
                    .with_context(|| format!("cannot create the lock {}", lock.display()));
            }
        }
    }
    bail!(
        "cannot take the lock {} (another run keeps taking it)",
        lock.display()
    )
}

/// Removes staging and set-aside folders of `target` left by runs that are gone.
fn remove_stale_staging(target: &Path) -> Result<()> {
    let prefix = sibling(target, "dhct-")?;
    let (Some(parent), Some(prefix)) = (prefix.parent(), prefix.file_name()) else {
        return Ok(());
    };
    let prefix = prefix.to_string_lossy().into_owned();
    let Ok(entries) = fs::read_dir(parent) else {
        return Ok(());
    };
    for entry in entries.filter_map(|e| e.ok()) {
        let name = entry.file_name().to_string_lossy().into_owned();
        let Some(rest) = name.strip_prefix(&prefix) else {
            continue;
        };
        let pid = rest
            .strip_prefix("staging-")
            .or_else(|| rest.strip_prefix("old-"))
            .and_then(|p| p.parse::<u32>().ok());
        if let Some(pid) = pid
            && !dhct_running(pid)
        {
            fs::remove_dir_all(entry.path()).with_context(|| {
                format!("cannot remove a killed run's {}", entry.path().display())
            })?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write_run(staged: &StagedOutput, file: &str) {
        fs::write(staged.path().join(file), "x").unwrap();
    }

    #[test]
    fn a_run_appears_whole_and_only_when_committed() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("out");
        let staged = StagedOutput::prepare(&out, false).unwrap();
        write_run(&staged, "model.json");
        assert!(!out.exists(), "nothing is visible before the commit");
        staged.commit().unwrap();
        assert!(out.join("model.json").is_file() && out.join(MARKER).is_file());
        // Nothing is left beside it.
        let names: Vec<_> = fs::read_dir(dir.path()).unwrap().collect();
        assert_eq!(names.len(), 1, "{names:?}");
        // A failed run (dropped without commit) leaves nothing.
        let other = dir.path().join("failed");
        let staged = StagedOutput::prepare(&other, false).unwrap();
        write_run(&staged, "model.json");
        drop(staged);
        assert!(!other.exists());
        assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 1);
    }

    #[test]
    fn earlier_runs_need_overwrite_and_foreign_folders_are_never_replaced() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("out");
        let staged = StagedOutput::prepare(&out, false).unwrap();
        write_run(&staged, "old_only.csv");
        staged.commit().unwrap();
        let error = StagedOutput::prepare(&out, false).unwrap_err().to_string();
        assert!(error.contains("--overwrite"), "{error}");
        let staged = StagedOutput::prepare(&out, true).unwrap();
        write_run(&staged, "model.json");
        staged.commit().unwrap();
        assert!(out.join("model.json").is_file());
        assert!(!out.join("old_only.csv").exists(), "stale files are gone");
        // A folder of someone else's files.
        let foreign = dir.path().join("photos");
        fs::create_dir(&foreign).unwrap();
        fs::write(foreign.join("holiday.jpg"), "x").unwrap();
        for overwrite in [false, true] {
            let error = StagedOutput::prepare(&foreign, overwrite)
                .unwrap_err()
                .to_string();
            assert!(error.contains("did not write"), "{error}");
        }
        assert!(foreign.join("holiday.jpg").is_file());
        // An empty folder is simply filled.
        let empty = dir.path().join("empty");
        fs::create_dir(&empty).unwrap();
        let staged = StagedOutput::prepare(&empty, false).unwrap();
        write_run(&staged, "model.json");
        staged.commit().unwrap();
        assert!(empty.join("model.json").is_file());
    }

    #[test]
    fn a_live_lock_stops_a_second_run_and_killed_runs_leave_nothing_behind() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("out");
        let first = StagedOutput::prepare(&out, false).unwrap();
        let error = StagedOutput::prepare(&out, false).unwrap_err().to_string();
        assert!(error.contains("another dhct run"), "{error}");
        drop(first);
        // A killed run: its lock and staging folder name a process that is gone.
        let dead = u32::MAX - 7;
        fs::write(dir.path().join(".out.dhct-lock"), format!("{dead}\n")).unwrap();
        let stale = dir.path().join(format!(".out.dhct-staging-{dead}"));
        fs::create_dir(&stale).unwrap();
        fs::write(stale.join(".model.json.123.tmp"), "partial").unwrap();
        let staged = StagedOutput::prepare(&out, false).unwrap();
        assert!(
            !stale.exists(),
            "the killed run's staging folder is removed"
        );
        write_run(&staged, "model.json");
        staged.commit().unwrap();
        let names: Vec<String> = fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        assert_eq!(names, ["out"]);
        // The current folder (here holding only `out`, not dhct's marker) is never replaced.
        let error = StagedOutput::prepare(&dir.path().join("."), true)
            .unwrap_err()
            .to_string();
        assert!(error.contains("did not write"), "{error}");
        // The output is a file: refused.
        let file = dir.path().join("file");
        fs::write(&file, "x").unwrap();
        assert!(StagedOutput::prepare(&file, true).is_err());
    }
}
