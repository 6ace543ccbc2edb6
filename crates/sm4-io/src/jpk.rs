//! JPK Instruments image reader (`.jpk`, `.jpk-qi-image`). Work in progress: see the
//! helper's implementation.

use dhct_scan::FileFormat;

use crate::limits::ReadLimits;
use crate::{ReadError, ScanFile};

const FORMAT: FileFormat = FileFormat::Jpk;

/// True when `bytes` are a TIFF whose first directory carries JPK's own tags.
pub fn looks_like_jpk(_bytes: &[u8]) -> bool {
    false
}

/// Reads a JPK image file.
pub fn read(bytes: &[u8]) -> Result<ScanFile, ReadError> {
    read_limited(bytes, &ReadLimits::default())
}

/// [`read`] under `limits` (see [`crate::limits`]).
pub fn read_limited(_bytes: &[u8], _limits: &ReadLimits) -> Result<ScanFile, ReadError> {
    Err(ReadError::unsupported(FORMAT, "not yet read"))
}
