//! Reading and writing STM image files into the [`dhct_scan`] data model.
//!
//! | format | read | write | module |
//! |---|---|---|---|
//! | RHK SM4 | yes | yes | [`sm4`] |
//! | RHK SM3 (not validated on a real file) | yes | — | [`sm4::sm3`] |
//! | Nanonis SXM | yes | — | [`sxm`] |
//! | ISO 28600 SPM transfer format | yes | — | [`iso28600`] |
//! | Gwyddion Simple Field (.gsf) | yes | yes | [`gsf`] |
//! | NumPy .npy | yes | yes | [`npy`] |
//! | float32 / 16-bit TIFF | yes | yes | [`tiff_file`] |
//! | Createc `.dat` (`[Paramco32]`) | yes | — | [`createc`] |
//! | Omicron MATRIX (`*_mtrx` + `_0001.mtrx`, by path) | yes | — | [`matrix`] |
//! | WSxM image (`.top`, `.stp`) | yes | — | [`wsxm`] |
//! | 16-bit grey and colour-mapped PNG | — | yes | [`png_file`] |
//! | Gwyddion native (.gwy) | yes | — | [`gwy`] |
//! | Nanosurf NID | yes | — | [`nid`] |
//! | Bruker/Veeco Nanoscope (.spm, .001, …) | yes | — | [`nanoscope`] |
//!
//! Formats are detected by content ([`detect_format`]), not by extension. Every reader takes
//! the whole file as a byte slice and checks every length against it before allocating, so
//! truncated, foreign or hostile files give a typed [`ReadError`], never a panic.
//! [`read_path`] opens only regular files (a FIFO, device or directory is refused before it
//! is opened, so nothing blocks) and reads under [`ReadLimits`]: the file size is checked
//! before reading, and the pixels and decoded bytes every header implies are checked before
//! anything is allocated (see [`limits`]).
//! Every image comes back in display orientation (row 0 at the top) with its
//! [`dhct_scan::ScanGeometry`]; values the format lacks are marked
//! [`dhct_scan::ValueSource::Assumed`] and can be supplied with [`GeometryOverrides`].
//!
//! ```no_run
//! let file = dhct_sm4_io::read_path("scan.sm4".as_ref()).unwrap();
//! let topography = file.topography().unwrap();
//! println!("{} x {} px", topography.geometry().columns(), topography.geometry().rows());
//! ```

mod atomic;
pub mod bytes;
pub mod createc;
mod detect;
mod error;
pub mod gsf;
pub mod gwy;
pub mod iso28600;
pub mod jpk;
pub mod limits;
pub mod matrix;
pub mod mul;
pub mod nanoscope;
pub mod nid;
pub mod npy;
pub mod npy_sidecar;
mod overrides;
mod placeholders;
pub mod png_file;
pub mod sm4;
pub mod sxm;
pub mod tiff_file;
mod unrecorded;
pub mod wsxm;

use std::path::Path;

pub use atomic::{AtomicFile, write_atomically};
pub use detect::{detect_format, detect_format_of_length};
pub use dhct_scan::{FileFormat, ScanFile};
pub use error::{OverrideRangeError, ReadError, WriteError};
pub use limits::{MAX_TEXT_FILE_BYTES, ReadLimits, check_regular_file, read_regular_text};
pub use overrides::GeometryOverrides;
pub use placeholders::{
    ASSUMED_PITCH, ASSUMED_PIXEL_PERIOD, ASSUMED_SCALE_KEY, ASSUMED_TIMING_KEY,
    PLAUSIBLE_LINE_TIME_S, PLAUSIBLE_PITCH_M, PLAUSIBLE_PIXEL_PERIOD_S, PLAUSIBLE_SCAN_ANGLE_RAD,
    PLAUSIBLE_TURNAROUND_S, assumption_warnings,
};
pub use unrecorded::UNRECORDED_LINES_KEY;
use unrecorded::mark_unrecorded_lines;

/// Reads a file of any supported format, detected from its content, under the default
/// [`ReadLimits`]. Only regular files are read (see [`limits::open_regular_file`]).
/// Errors about the content do not repeat the path; callers add it as context.
pub fn read_path(path: &Path) -> Result<ScanFile, ReadError> {
    read_path_limited(path, &ReadLimits::default())
}

/// [`read_path`] under `limits`.
pub fn read_path_limited(path: &Path, limits: &ReadLimits) -> Result<ScanFile, ReadError> {
    let bytes = limits::read_regular_file(path, limits.max_bytes)?;
    if matrix::is_data_file(&bytes) {
        // A MATRIX data file is read with its parameter file from beside it.
        return matrix::read_files(path, &bytes, limits).map(mark_unrecorded_lines);
    }
    if detect_format(&bytes) == Some(FileFormat::Npy) {
        // With the JSON sidecar dhct writes beside it, and the other pass, when there.
        return npy_sidecar::read_with_sidecar(path, &bytes, limits).map(mark_unrecorded_lines);
    }
    read_bytes_limited(&bytes, limits)
}

/// Reads a file and then applies `overrides` to every channel's geometry.
pub fn read_path_with(path: &Path, overrides: &GeometryOverrides) -> Result<ScanFile, ReadError> {
    read_path_with_limits(path, overrides, &ReadLimits::default())
}

/// [`read_path_with`] under `limits`.
pub fn read_path_with_limits(
    path: &Path,
    overrides: &GeometryOverrides,
    limits: &ReadLimits,
) -> Result<ScanFile, ReadError> {
    let file = read_path_limited(path, limits)?;
    overrides.apply_to_file(file)
}

/// Reads an in-memory file of any supported format, detected from its content.
pub fn read_bytes(bytes: &[u8]) -> Result<ScanFile, ReadError> {
    read_bytes_limited(bytes, &ReadLimits::default())
}

/// [`read_bytes`] under `limits`.
pub fn read_bytes_limited(bytes: &[u8], limits: &ReadLimits) -> Result<ScanFile, ReadError> {
    match detect_format(bytes) {
        Some(format) => read_as_limited(format, bytes, limits),
        None => Err(ReadError::UnknownFormat),
    }
}

/// Reads `bytes` as the given format.
pub fn read_as(format: FileFormat, bytes: &[u8]) -> Result<ScanFile, ReadError> {
    read_as_limited(format, bytes, &ReadLimits::default())
}

/// [`read_as`] under `limits`. Lines the scan never recorded are read as missing
/// ([`UNRECORDED_LINES_KEY`]).
pub fn read_as_limited(
    format: FileFormat,
    bytes: &[u8],
    limits: &ReadLimits,
) -> Result<ScanFile, ReadError> {
    read_format(format, bytes, limits).map(mark_unrecorded_lines)
}

/// `bytes` read as `format`, as the file holds them.
fn read_format(
    format: FileFormat,
    bytes: &[u8],
    limits: &ReadLimits,
) -> Result<ScanFile, ReadError> {
    match format {
        FileFormat::RhkSm4 => sm4::read_limited(bytes, limits),
        FileFormat::RhkSm3 => sm4::sm3::read_limited(bytes, limits),
        FileFormat::NanonisSxm => sxm::read_limited(bytes, limits),
        FileFormat::Iso28600 => iso28600::read_limited(bytes, limits),
        FileFormat::Gsf => gsf::read_limited(bytes, limits),
        FileFormat::Npy => npy::read_limited(bytes, limits),
        FileFormat::Tiff => tiff_file::read_limited(bytes, limits),
        FileFormat::Gwyddion => gwy::read_limited(bytes, limits),
        FileFormat::NanosurfNid => nid::read_limited(bytes, limits),
        FileFormat::Nanoscope => nanoscope::read_limited(bytes, limits),
        FileFormat::CreatecDat => createc::read_limited(bytes, limits),
        FileFormat::OmicronMatrix => matrix::read_alone(bytes),
        FileFormat::Wsxm => wsxm::read_limited(bytes, limits),
        FileFormat::AarhusMul => mul::read_limited(bytes, limits),
        FileFormat::Jpk => jpk::read_limited(bytes, limits),
        FileFormat::Png => Err(ReadError::unsupported(
            FileFormat::Png,
            "PNG is an export format for pictures (no physical scale or float z); \
             read the TIFF, GSF or NPY written beside it instead",
        )),
    }
}
