use std::path::PathBuf;

use dhct_scan::{FileFormat, GeometryError};
use thiserror::Error;

/// Why a file could not be read. Every reader returns this; none panics on bad input.
#[derive(Debug, Error)]
pub enum ReadError {
    /// Reading failed, with no path to name.
    #[error("cannot read the file")]
    Io(#[source] std::io::Error),
    /// A file could not be opened or read.
    #[error("cannot open {path}", path = .path.display())]
    Open {
        /// The file that could not be read.
        path: PathBuf,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
    /// The path names a directory, pipe or device rather than a regular file.
    #[error(
        "{path} is {kind}, not a regular file: dhct reads only regular files",
        path = .path.display()
    )]
    NotRegularFile {
        /// The path given.
        path: PathBuf,
        /// What it is instead, e.g. "a directory".
        kind: &'static str,
    },
    /// The file is larger than [`ReadLimits::max_bytes`](crate::ReadLimits::max_bytes).
    #[error(
        "{}{bytes} bytes exceed the read limit of {limit} bytes (raise ReadLimits::max_bytes for a truly huge file)",
        .path.as_ref().map(|p| format!("{} holds ", p.display())).unwrap_or_else(|| "the file's ".into())
    )]
    FileTooLarge {
        /// The file, when it was read from a path.
        path: Option<PathBuf>,
        /// Its size, bytes.
        bytes: u64,
        /// The read limit, bytes.
        limit: u64,
    },
    /// The images a header declares need more pixels or memory than the
    /// [`ReadLimits`](crate::ReadLimits) allow; refused before anything is allocated.
    #[error(
        "{format} file: {what} need {needed} {unit}, more than the read limit of {limit} {unit} \
         (raise ReadLimits for a truly huge scan)",
        format = .format.name(),
        needed = .needed.map(|n| n.to_string()).unwrap_or_else(|| "more than 2^64".into())
    )]
    OverBudget {
        /// The format being read.
        format: FileFormat,
        /// The images that were charged, e.g. "2 image(s) of 512 x 512 px".
        what: String,
        /// What they need, in `unit`; `None` when the count overflows `u64`.
        needed: Option<u64>,
        /// The read limit, in `unit`.
        limit: u64,
        /// "pixels" or "bytes".
        unit: &'static str,
    },
    /// A block the file points to runs past its end.
    #[error(
        "{format} file is truncated: {what} needs bytes {offset}..{end} but the file has only {len} bytes",
        format = .format.name(), end = .offset.saturating_add(*.needed)
    )]
    Truncated {
        /// The format being read.
        format: FileFormat,
        /// The block that is cut off.
        what: String,
        /// Where the block starts, bytes from the start of the file.
        offset: u64,
        /// The block's length, bytes.
        needed: u64,
        /// The file's length, bytes.
        len: u64,
    },
    /// The content is not of the format it was read as.
    #[error("not a {format} file: {reason}", format = .format.name())]
    WrongFormat {
        /// The format it was read as.
        format: FileFormat,
        /// Why not.
        reason: String,
    },
    /// The file is of the format but inconsistent.
    #[error("corrupt {format} file: {reason}", format = .format.name())]
    Corrupt {
        /// The format it was read as.
        format: FileFormat,
        /// What is inconsistent.
        reason: String,
    },
    /// The file is valid but uses a feature dhct does not read.
    #[error("unsupported {format} file: {reason}", format = .format.name())]
    Unsupported {
        /// The format it was read as.
        format: FileFormat,
        /// The feature.
        reason: String,
    },
    /// The file holds no image dhct can use (e.g. only spectra).
    #[error("{format} file holds no image that dhct can use: {reason}", format = .format.name())]
    NoImage {
        /// The format it was read as.
        format: FileFormat,
        /// Why not.
        reason: String,
    },
    /// The content matches no supported format.
    #[error(
        "unrecognised file format: expected the content of one of {formats}",
        formats = FileFormat::read_list()
    )]
    UnknownFormat,
    /// A file that the format reads together with this one is missing.
    #[error(
        "{format} file needs its {what} {path}, which does not exist",
        format = .format.name(), path = .path.display()
    )]
    MissingCompanion {
        /// The format being read.
        format: FileFormat,
        /// Where the companion file was looked for.
        path: PathBuf,
        /// What the companion is, e.g. "parameter file".
        what: &'static str,
    },
    /// A geometry override is out of range.
    #[error("invalid scan geometry option: {0}")]
    BadOverride(OverrideRangeError),
    /// The header describes a scan geometry that is not valid.
    #[error("{format} file describes an invalid scan: {source}", format = .format.name())]
    Geometry {
        /// The format being read.
        format: FileFormat,
        /// What is wrong with the geometry.
        #[source]
        source: GeometryError,
    },
}

impl ReadError {
    /// Shorthand for [`ReadError::Corrupt`].
    pub fn corrupt(format: FileFormat, reason: impl Into<String>) -> ReadError {
        ReadError::Corrupt {
            format,
            reason: reason.into(),
        }
    }

    /// Shorthand for [`ReadError::WrongFormat`].
    pub fn wrong_format(format: FileFormat, reason: impl Into<String>) -> ReadError {
        ReadError::WrongFormat {
            format,
            reason: reason.into(),
        }
    }

    /// Shorthand for [`ReadError::Unsupported`].
    pub fn unsupported(format: FileFormat, reason: impl Into<String>) -> ReadError {
        ReadError::Unsupported {
            format,
            reason: reason.into(),
        }
    }

    /// Wraps a geometry error found while building the scan from `format`'s header.
    pub fn geometry(format: FileFormat, source: GeometryError) -> ReadError {
        ReadError::Geometry { format, source }
    }
}

/// Why a file could not be written.
#[derive(Debug, Error)]
pub enum WriteError {
    /// The file could not be created, written or moved into place.
    #[error("cannot write {path}")]
    Io {
        /// The file that could not be written.
        path: PathBuf,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
    /// Writing to the output stream failed.
    #[error("write failed: {0}")]
    Stream(#[from] std::io::Error),
    /// The data cannot be stored in the format.
    #[error("cannot write {format}: {reason}", format = .format.name())]
    Unrepresentable {
        /// The format being written.
        format: FileFormat,
        /// Why it cannot hold the data.
        reason: String,
    },
    /// The format's encoder failed.
    #[error("{format} encoder failed: {reason}", format = .format.name())]
    Encoder {
        /// The format being written.
        format: FileFormat,
        /// The encoder's error.
        reason: String,
    },
}

/// An override outside its plausible range.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{key} = {value:e} {unit} is outside the accepted range {low:e}..={high:e} {unit}")]
pub struct OverrideRangeError {
    /// The option's name (`pitch_x`, `pixel_period`, ...).
    pub key: &'static str,
    /// The value given.
    pub value: f64,
    /// Its unit.
    pub unit: &'static str,
    /// Smallest accepted value.
    pub low: f64,
    /// Largest accepted value.
    pub high: f64,
}
