//! Opening files safely and reading them under a memory budget.
//!
//! [`open_regular_file`] checks what a path is *before* opening it: only regular files are
//! read, so a named pipe (FIFO) can never block a reader, and `/dev/zero`, `/dev/urandom`
//! or a directory are refused with an error that names the path. The file's size is
//! compared with [`ReadLimits::max_bytes`] before a byte is read, and reading stops at that
//! limit even if the file grows meanwhile.
//!
//! Every reader then derives its pixel counts from the header and charges them to a
//! [`Budget`] before allocating: the pixels of all images of a file may not exceed
//! [`ReadLimits::max_pixels`], and the file's bytes plus every decoded buffer (the `f64`
//! images, 8 bytes per pixel, and for compressed TIFF the decoder's own buffer) may not
//! exceed [`ReadLimits::max_bytes`]. The defaults (2 GiB, 2^28 pixels) admit any real STM
//! scan; raise them for truly huge files.

use std::fs::{File, Metadata};
use std::io::Read;
use std::path::Path;

use dhct_scan::FileFormat;
use serde::{Deserialize, Serialize};

use crate::ReadError;

/// How much reading one file may take.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ReadLimits {
    /// Bytes: the file itself plus every buffer decoded from it (the `f64` images at 8 bytes
    /// per pixel, a TIFF decoder's buffer). Default [`ReadLimits::DEFAULT_MAX_BYTES`].
    pub max_bytes: u64,
    /// Pixels of all images of the file together (trace, retrace, every channel).
    /// Default [`ReadLimits::DEFAULT_MAX_PIXELS`].
    pub max_pixels: u64,
}

impl ReadLimits {
    /// 2 GiB.
    pub const DEFAULT_MAX_BYTES: u64 = 2 << 30;
    /// 2^28 pixels (e.g. four 8192 × 8192 images).
    pub const DEFAULT_MAX_PIXELS: u64 = 1 << 28;
}

impl Default for ReadLimits {
    fn default() -> Self {
        ReadLimits {
            max_bytes: Self::DEFAULT_MAX_BYTES,
            max_pixels: Self::DEFAULT_MAX_PIXELS,
        }
    }
}

/// What is left of a [`ReadLimits`] while one file is decoded.
#[derive(Debug, Clone)]
pub struct Budget {
    limits: ReadLimits,
    bytes_left: u64,
    pixels_left: u64,
}

impl Budget {
    /// The budget for decoding a file of `file_len` bytes (already in memory, so counted).
    pub fn new(limits: &ReadLimits, file_len: usize) -> Result<Budget, ReadError> {
        let file_len = file_len as u64;
        let bytes_left = limits
            .max_bytes
            .checked_sub(file_len)
            .ok_or(ReadError::FileTooLarge {
                path: None,
                bytes: file_len,
                limit: limits.max_bytes,
            })?;
        Ok(Budget {
            limits: *limits,
            bytes_left,
            pixels_left: limits.max_pixels,
        })
    }

    /// The limits this budget started from.
    pub fn limits(&self) -> &ReadLimits {
        &self.limits
    }

    /// Charges `count` images of `columns × rows` pixels, each held as `f64` plus
    /// `extra_bytes_per_pixel` bytes of intermediate buffer. Fails, before anything is
    /// allocated, when the file's pixels or bytes would exceed the limits.
    pub fn charge_images(
        &mut self,
        format: FileFormat,
        columns: u64,
        rows: u64,
        count: u64,
        extra_bytes_per_pixel: u64,
    ) -> Result<(), ReadError> {
        let over = |needed: Option<u64>, limit: u64, unit: &'static str| ReadError::OverBudget {
            format,
            what: format!("{count} image(s) of {columns} x {rows} px"),
            needed,
            limit,
            unit,
        };
        let pixels = columns.checked_mul(rows).and_then(|p| p.checked_mul(count));
        let Some(pixels) = pixels.filter(|p| *p <= self.pixels_left) else {
            return Err(over(pixels, self.limits.max_pixels, "pixels"));
        };
        let bytes = pixels.checked_mul(8u64.saturating_add(extra_bytes_per_pixel));
        let Some(bytes) = bytes.filter(|b| *b <= self.bytes_left) else {
            return Err(over(bytes, self.limits.max_bytes, "bytes"));
        };
        self.pixels_left -= pixels;
        self.bytes_left -= bytes;
        Ok(())
    }

    /// Bytes still available, for decoders that take an allocation limit.
    pub fn bytes_left(&self) -> u64 {
        self.bytes_left
    }
}

/// What a non-regular file is, for error messages.
fn special_kind(metadata: &Metadata) -> Option<&'static str> {
    let kind = metadata.file_type();
    if kind.is_file() {
        return None;
    }
    if kind.is_dir() {
        return Some("a directory");
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if kind.is_fifo() {
            return Some("a named pipe (FIFO)");
        }
        if kind.is_char_device() {
            return Some("a character device");
        }
        if kind.is_block_device() {
            return Some("a block device");
        }
        if kind.is_socket() {
            return Some("a socket");
        }
    }
    Some("not a regular file")
}

/// Checks that `path` is a regular file (following symbolic links) without opening it, and
/// returns its metadata. Directories, FIFOs, devices and sockets give
/// [`ReadError::NotRegularFile`] naming the path.
pub fn check_regular_file(path: &Path) -> Result<Metadata, ReadError> {
    let metadata = std::fs::metadata(path).map_err(|source| ReadError::Open {
        path: path.to_path_buf(),
        source,
    })?;
    match special_kind(&metadata) {
        None => Ok(metadata),
        Some(kind) => Err(ReadError::NotRegularFile {
            path: path.to_path_buf(),
            kind,
        }),
    }
}

/// Opens `path` for reading only if it is a regular file (checked before opening, so a FIFO
/// never blocks; on Linux the file is also opened non-blocking and checked again, so a file
/// swapped for a FIFO in between cannot block either). Returns the file and its size.
pub fn open_regular_file(path: &Path) -> Result<(File, u64), ReadError> {
    check_regular_file(path)?;
    let open_error = |source| ReadError::Open {
        path: path.to_path_buf(),
        source,
    };
    let mut options = std::fs::OpenOptions::new();
    options.read(true);
    #[cfg(target_os = "linux")]
    {
        use std::os::unix::fs::OpenOptionsExt;
        const O_NONBLOCK: i32 = 0o4000;
        options.custom_flags(O_NONBLOCK);
    }
    let file = options.open(path).map_err(open_error)?;
    let metadata = file.metadata().map_err(open_error)?;
    if let Some(kind) = special_kind(&metadata) {
        return Err(ReadError::NotRegularFile {
            path: path.to_path_buf(),
            kind,
        });
    }
    Ok((file, metadata.len()))
}

/// Reads the whole regular file `path`, refusing it before reading when it is larger than
/// `max_bytes` (and stopping at `max_bytes` should it grow while being read).
pub fn read_regular_file(path: &Path, max_bytes: u64) -> Result<Vec<u8>, ReadError> {
    let (file, len) = open_regular_file(path)?;
    let too_large = |bytes| ReadError::FileTooLarge {
        path: Some(path.to_path_buf()),
        bytes,
        limit: max_bytes,
    };
    if len > max_bytes {
        return Err(too_large(len));
    }
    let mut bytes = Vec::with_capacity(usize::try_from(len).unwrap_or(0));
    file.take(max_bytes.saturating_add(1))
        .read_to_end(&mut bytes)
        .map_err(|source| ReadError::Open {
            path: path.to_path_buf(),
            source,
        })?;
    if bytes.len() as u64 > max_bytes {
        return Err(too_large(bytes.len() as u64));
    }
    Ok(bytes)
}

/// Reads the regular text file `path` (UTF-8) of at most `max_bytes` bytes: for configs,
/// lattice and simulator files, which are small.
pub fn read_regular_text(path: &Path, max_bytes: u64) -> Result<String, ReadError> {
    let bytes = read_regular_file(path, max_bytes)?;
    String::from_utf8(bytes).map_err(|_| ReadError::Open {
        path: path.to_path_buf(),
        source: std::io::Error::new(std::io::ErrorKind::InvalidData, "not UTF-8 text"),
    })
}

/// Largest config, lattice or simulator file read: 16 MiB.
pub const MAX_TEXT_FILE_BYTES: u64 = 16 << 20;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn budget_counts_pixels_and_bytes_of_all_images() {
        let limits = ReadLimits {
            max_bytes: 1000,
            max_pixels: 100,
        };
        let mut budget = Budget::new(&limits, 100).unwrap();
        budget
            .charge_images(FileFormat::Npy, 5, 5, 2, 0)
            .expect("50 px, 400 bytes");
        assert_eq!(budget.bytes_left(), 500);
        let error = budget
            .charge_images(FileFormat::Npy, 10, 6, 1, 0)
            .unwrap_err();
        assert!(error.to_string().contains("pixels"), "{error}");
        let error = budget
            .charge_images(FileFormat::Npy, 5, 5, 1, 20)
            .unwrap_err();
        assert!(error.to_string().contains("bytes"), "{error}");
        assert!(
            budget
                .charge_images(FileFormat::Npy, u64::MAX, 2, 1, 0)
                .is_err()
        );
        assert!(Budget::new(&limits, 1001).is_err());
    }

    #[test]
    fn special_files_are_refused_before_opening() {
        let dir = tempfile::tempdir().unwrap();
        let error = read_regular_file(dir.path(), 1 << 20).unwrap_err();
        assert!(
            error.to_string().contains("directory")
                && error
                    .to_string()
                    .contains(&dir.path().display().to_string()),
            "{error}"
        );
        #[cfg(unix)]
        for device in ["/dev/zero", "/dev/urandom", "/dev/null"] {
            if Path::new(device).exists() {
                let error = read_regular_file(Path::new(device), 1 << 20).unwrap_err();
                assert!(error.to_string().contains("character device"), "{error}");
            }
        }
        let file = dir.path().join("big.bin");
        std::fs::write(&file, vec![0u8; 2000]).unwrap();
        let error = read_regular_file(&file, 1000).unwrap_err();
        assert!(error.to_string().contains("2000"), "{error}");
        assert_eq!(read_regular_file(&file, 2000).unwrap().len(), 2000);
    }
}
