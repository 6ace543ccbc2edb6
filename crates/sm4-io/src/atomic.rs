//! Atomic file output: write to a temporary file beside the target, then rename.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use crate::WriteError;

/// Writes `path` atomically: `write` fills a temporary file in the same directory, which is
/// flushed, synced and renamed over `path` only if `write` succeeds. On failure the
/// temporary file is removed and `path` is left as it was.
pub fn write_atomically<F>(path: &Path, write: F) -> Result<(), WriteError>
where
    F: FnOnce(&mut BufWriter<File>) -> Result<(), WriteError>,
{
    let mut file = AtomicFile::create(path)?;
    write(file.writer())?;
    file.commit()
}

/// A file being written atomically over a longer stretch of work (pages appended as they are
/// made): it is a temporary file beside `path` until [`AtomicFile::commit`] flushes, syncs
/// and renames it; dropped uncommitted, the temporary file is removed and `path` is left as
/// it was.
pub struct AtomicFile {
    path: PathBuf,
    temporary: PathBuf,
    writer: Option<BufWriter<File>>,
}

impl AtomicFile {
    /// Creates the temporary file for `path`.
    pub fn create(path: &Path) -> Result<AtomicFile, WriteError> {
        let io_error = |source| WriteError::Io {
            path: path.to_path_buf(),
            source,
        };
        let directory = match path.parent() {
            Some(parent) if !parent.as_os_str().is_empty() => parent.to_path_buf(),
            _ => std::env::current_dir().map_err(io_error)?,
        };
        let file_name = path
            .file_name()
            .ok_or_else(|| io_error(std::io::Error::other("path has no file name")))?;
        let temporary = directory.join(format!(
            ".{}.{}.tmp",
            file_name.to_string_lossy(),
            std::process::id()
        ));
        let file = File::create(&temporary).map_err(io_error)?;
        Ok(AtomicFile {
            path: path.to_path_buf(),
            temporary,
            writer: Some(BufWriter::new(file)),
        })
    }

    /// The buffered writer of the temporary file (it also seeks).
    pub fn writer(&mut self) -> &mut BufWriter<File> {
        self.writer
            .as_mut()
            .expect("the writer is taken only by commit, which consumes the file")
    }

    /// Flushes, syncs and renames the temporary file over `path`.
    pub fn commit(mut self) -> Result<(), WriteError> {
        let io_error = |source| WriteError::Io {
            path: self.path.clone(),
            source,
        };
        let mut writer = self
            .writer
            .take()
            .expect("the writer is taken only here, once");
        writer.flush().map_err(io_error)?;
        let file = writer.into_inner().map_err(|e| io_error(e.into_error()))?;
        file.sync_all().map_err(io_error)?;
        std::fs::rename(&self.temporary, &self.path).map_err(io_error)
    }
}

impl Drop for AtomicFile {
    /// Removes the temporary file unless it was renamed into place.
    fn drop(&mut self) {
        if self.temporary.exists() {
            let _ = std::fs::remove_file(&self.temporary);
        }
    }
}
