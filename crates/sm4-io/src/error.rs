use std::path::PathBuf;

use dhct_scan::{FileFormat, GeometryError};
use thiserror::Error;

/// Why a file could not be read. Every reader returns this; none panics on bad input.
#[derive(Debug, Error)]
pub enum ReadError {
    #[error("cannot read the file")]
    Io(#[source] std::io::Error),
    #[error("cannot open {path}", path = .path.display())]
    Open {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error(
        "{path} is {kind}, not a regular file: dhct reads only regular files",
        path = .path.display()
    )]
    NotRegularFile { path: PathBuf, kind: &'static str },
    #[error(
        "{}{bytes} bytes exceed the read limit of {limit} bytes (raise ReadLimits::max_bytes for a truly huge file)",
        .path.as_ref().map(|p| format!("{} holds ", p.display())).unwrap_or_else(|| "the file's ".into())
    )]
    FileTooLarge {
        path: Option<PathBuf>,
        bytes: u64,
        limit: u64,
    },
    #[error(
        "{format} file: {what} need {needed} {unit}, more than the read limit of {limit} {unit} \
         (raise ReadLimits for a truly huge scan)",
        format = .format.name(),
        needed = .needed.map(|n| n.to_string()).unwrap_or_else(|| "more than 2^64".into())
    )]
    OverBudget {
        format: FileFormat,
        what: String,
        needed: Option<u64>,
        limit: u64,
        unit: &'static str,
    },
    #[error(
        "{format} file is truncated: {what} needs bytes {offset}..{end} but the file has only {len} bytes",
        format = .format.name(), end = .offset.saturating_add(*.needed)
    )]
    Truncated {
        format: FileFormat,
        what: String,
        offset: u64,
        needed: u64,
        len: u64,
    },
    #[error("not a {format} file: {reason}", format = .format.name())]
    WrongFormat { format: FileFormat, reason: String },
    #[error("corrupt {format} file: {reason}", format = .format.name())]
    Corrupt { format: FileFormat, reason: String },
    #[error("unsupported {format} file: {reason}", format = .format.name())]
    Unsupported { format: FileFormat, reason: String },
    #[error("{format} file holds no image that dhct can use: {reason}", format = .format.name())]
    NoImage { format: FileFormat, reason: String },
    #[error(
        "unrecognised file format: expected RHK SM4 or SM3, Nanonis SXM, ISO 28600, Gwyddion GSF or GWY, Nanosurf NID, Bruker Nanoscope, Createc DAT, Omicron MATRIX, WSxM, NumPy NPY or TIFF content"
    )]
    UnknownFormat,
    #[error(
        "{format} file needs its {what} {path}, which does not exist",
        format = .format.name(), path = .path.display()
    )]
    MissingCompanion {
        format: FileFormat,
        path: PathBuf,
        what: &'static str,
    },
    #[error("invalid scan geometry option: {0}")]
    BadOverride(crate::overrides::OverrideRangeError),
    #[error("{format} file describes an invalid scan: {source}", format = .format.name())]
    Geometry {
        format: FileFormat,
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
    #[error("cannot write {path}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("write failed: {0}")]
    Stream(#[from] std::io::Error),
    #[error("cannot write {format}: {reason}", format = .format.name())]
    Unrepresentable { format: FileFormat, reason: String },
    #[error("{format} encoder failed: {reason}", format = .format.name())]
    Encoder { format: FileFormat, reason: String },
}
