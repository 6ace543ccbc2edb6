//! (being written by a helper; placeholder so the crate compiles)
use crate::{ReadError, ScanFile};
use dhct_scan::FileFormat;
pub fn read(_bytes: &[u8]) -> Result<ScanFile, ReadError> {
    Err(ReadError::unsupported(FileFormat::Gsf, "reader not written yet"))
}
pub fn looks_like_sm4(bytes: &[u8]) -> bool { let _ = bytes; false }
