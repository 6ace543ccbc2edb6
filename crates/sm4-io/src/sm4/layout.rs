//! Fixed sizes, object type codes and enumerations of the SM4 format.
//!
//! All multi-byte numbers in an SM4 file are little-endian. See the module docs of
//! [`crate::sm4`] for how these pieces fit together and where the facts come from.

use dhct_scan::ScanDirection;

/// Offset of the UTF-16LE signature (after the u16 header size).
pub(crate) const SIGNATURE_OFFSET: usize = 2;
/// Length of the signature field in bytes (18 UTF-16 code units).
pub(crate) const SIGNATURE_BYTES: usize = 36;
/// The part of the signature every SM4 file shares, "STiMage 005." in UTF-16LE.
pub(crate) const MAGIC_PREFIX: &str = "STiMage 005.";
/// The full signature we write: major version 005, minor 004, "1" = Unicode strings.
pub(crate) const SIGNATURE_WRITTEN: &str = "STiMage 005.004 1";
/// Minor version stored in each page index entry (4 = XPMPro, as in our real file).
pub(crate) const MINOR_VERSION_WRITTEN: u32 = 4;

/// Value of the leading u16: bytes of file header that follow it
/// (36 signature + 5 u32 fields = 56).
pub(crate) const FILE_HEADER_SIZE: u16 = 56;
/// Offset of the page count (the first u32 after the signature).
pub(crate) const FILE_HEADER_FIELDS_OFFSET: u64 = (SIGNATURE_OFFSET + SIGNATURE_BYTES) as u64;

/// Bytes of one object list entry (type, offset, size; three u32).
pub(crate) const OBJECT_ENTRY_SIZE: u32 = 12;
/// Bytes of the page index header before its object list (4 u32).
pub(crate) const PAGE_INDEX_HEADER_SIZE: u32 = 16;
/// Bytes of one page index entry before its object list (GUID + 4 u32).
pub(crate) const PAGE_INDEX_ENTRY_SIZE: u32 = 32;
/// Bytes of the page header fields; the page header's object list follows at this offset.
pub(crate) const PAGE_HEADER_SIZE: u32 = 180;
/// Bytes of the page header up to and including the object list count (the fields we use).
pub(crate) const PAGE_HEADER_USED: u32 = 116;
/// More objects than this in one list is treated as corruption (real files have ≤ 10).
pub(crate) const MAX_OBJECTS_PER_LIST: u32 = 1024;

/// Object type codes (the first u32 of an object list entry).
pub(crate) mod object {
    pub(crate) const PAGE_INDEX_HEADER: u32 = 1;
    pub(crate) const PAGE_INDEX_ARRAY: u32 = 2;
    pub(crate) const PAGE_HEADER: u32 = 3;
    pub(crate) const PAGE_DATA: u32 = 4;
    pub(crate) const STRING_DATA: u32 = 10;
}

/// Page data types (page index entry).
pub(crate) mod data_type {
    pub(crate) const IMAGE: u32 = 0;

    /// A human-readable name for metadata.
    pub(crate) fn name(code: u32) -> &'static str {
        match code {
            0 => "image",
            1 => "line/spectrum",
            2 => "xy data",
            3 => "annotated line",
            4 => "text",
            5 => "annotated text",
            6 => "sequential",
            7 => "movie",
            _ => "unknown",
        }
    }
}

/// Page source types (page index entry).
pub(crate) mod source {
    /// Data that went through software after acquisition (what dhct writes).
    pub(crate) const PROCESSED: u32 = 1;
}

/// Page types (page header): the physical channel.
pub(crate) mod page_type {
    pub(crate) const TOPOGRAPHIC: u32 = 1;
    pub(crate) const CURRENT: u32 = 2;
    pub(crate) const AUX: u32 = 3;

    /// A human-readable name for channels without a label.
    pub(crate) fn name(code: u32) -> &'static str {
        match code {
            1 => "Topography",
            2 => "Current",
            3 => "Aux",
            4 => "Force",
            5 => "Signal",
            6 => "FFT",
            17 => "Autocorrelation",
            19 | 20 => "Gain topography",
            21 | 22 => "Gain current",
            25 => "Counter",
            27 => "AFM",
            30 => "Video channel",
            _ => "Channel",
        }
    }
}

/// Indices into a page's string list (UTF-16 strings with a u16 length prefix).
pub(crate) mod string {
    pub(crate) const LABEL: usize = 0;
    pub(crate) const SYSTEM_TEXT: usize = 1;
    pub(crate) const SESSION_TEXT: usize = 2;
    pub(crate) const USER_TEXT: usize = 3;
    pub(crate) const PATH: usize = 4;
    pub(crate) const DATE: usize = 5;
    pub(crate) const TIME: usize = 6;
    pub(crate) const X_UNITS: usize = 7;
    pub(crate) const Y_UNITS: usize = 8;
    pub(crate) const Z_UNITS: usize = 9;
    pub(crate) const COMPLETED_LINE_COUNT: usize = 13;
    /// Strings we read (the rest are ignored) and write: label … PLL-pro status, as in
    /// files from RHK XPMPro / Rev9 (our real file has exactly 17).
    pub(crate) const KNOWN: usize = 17;
}

/// The page header's scan direction code: the fast direction of that page.
pub(crate) mod scan_dir {
    use super::ScanDirection;

    pub(crate) const RIGHT: u32 = 0;
    pub(crate) const LEFT: u32 = 1;
    pub(crate) const UP: u32 = 2;
    pub(crate) const DOWN: u32 = 3;

    /// The direction of a code, or `None` for an unknown code.
    pub(crate) fn decode(code: u32) -> Option<ScanDirection> {
        match code {
            RIGHT => Some(ScanDirection::Right),
            LEFT => Some(ScanDirection::Left),
            UP => Some(ScanDirection::Up),
            DOWN => Some(ScanDirection::Down),
            _ => None,
        }
    }

    /// The code of a direction.
    pub(crate) fn encode(direction: ScanDirection) -> u32 {
        match direction {
            ScanDirection::Right => RIGHT,
            ScanDirection::Left => LEFT,
            ScanDirection::Up => UP,
            ScanDirection::Down => DOWN,
        }
    }
}

/// Raw value that dhct writes for a missing (NaN) sample and reads back as NaN.
pub(crate) const MISSING_RAW: i32 = i32::MIN;
