//! RHK Technology SM4 files (XPMPro / Rev9 "STiMage 005"), read and written.
//!
//! # Layout
//!
//! Learned from Gwyddion's `modules/file/rhk-sm4.c` and spym's `spym/io/rhksm4/_sm4.py`, and
//! checked byte by byte against a real Rev9 file. Everything is little-endian.
//!
//! * **File header** at 0: u16 header size (56, counting the bytes after it); 36-byte UTF-16LE
//!   signature `"STiMage 005.004 1"` (major.minor version, "1" = Unicode); u32 page count,
//!   object count, object field size (12), two reserved u32. The file's object list follows
//!   at `2 + header size`.
//! * **Object list**: entries of u32 type, u32 absolute offset, u32 size. Types used here:
//!   1 page index header, 2 page index array, 3 page header, 4 page data, 10 string data
//!   (13/15 PRM text and its header, 9 colour info, 14/16 thumbnail … are skipped).
//!   Entries with size 0 are empty slots.
//! * **Page index header** (object 1): u32 page count, u32 object count, two reserved u32,
//!   then its object list, which holds the page index array (object 2).
//! * **Page index array**: per page a 16-byte GUID, u32 data type (0 image, 1 line/spectrum,
//!   6 sequential, …), u32 source type, u32 object count, u32 minor version, then that many
//!   objects (page header, page data, thumbnail …). The array object's size is that of one
//!   entry's fixed part (32 bytes); the next entry starts after the current one's objects.
//! * **Page header** (object 3), 180 bytes: u16 field size, u16 string count, u32 page type
//!   (1 topography, 2 current, …), data sub-source, line type, i32 x/y corner, u32 x size,
//!   y size, image type, scan direction (0 right, 1 left, 2 up, 3 down), group id, data size,
//!   i32 min/max raw z; f32 x scale, y scale, z scale, xy scale, x offset, y offset, z offset
//!   (metres, metres per pixel), period (s per pixel), bias (V), current (A), angle (degrees);
//!   u32 colour-info count, grid x/y size, object count; 64 bytes of flags and reserved.
//!   The page header's own object list (string data, drift, colour info …) follows it.
//! * **Strings** (object 10): `string count` times a u16 number of UTF-16 code units and the
//!   units: label, system text, session text, user text, path, date (MM/DD/YY), time,
//!   x units, y units, z units, x label, y label, status channel text, completed line count,
//!   oversampling count, sliced voltage, PLL-pro status (17 in Rev9 files).
//! * **Data** (object 4): `x size · y size` i32, row by row;
//!   `value = raw · z scale + z offset` in z units (metres for topography).
//!
//! Only image pages (data type 0) are read; spectra and other pages are skipped, and listed
//! in the metadata key `"skipped pages"`. Every offset and size is checked against the file
//! before use, object lists are capped at 1024 entries, and the total bytes visited are
//! capped at twice the file size (+1 MiB), so pages that all point at one large object cannot
//! multiply the work or memory. The PRM block (instrument parameters, maybe
//! zlib-compressed) is not needed: the page header has everything the geometry needs.
//!
//! # Orientation and directions
//!
//! Stored sample `(i, j)` (row `i`, column `j`) lies at `x = x_offset + j·x_scale`,
//! `y = y_offset + i·y_scale` with y up on the sample. So a negative x scale mirrors the
//! columns and a positive y scale flips the rows into display orientation (x right, row 0 at
//! the top). spym applies exactly these sign rules; Gwyddion 2.62 always mirrors the columns
//! and flips the rows when the y scale is positive ("up images") — the same for the usual
//! negative x scale. On the real file (both scales negative) Gwyddion's import and ours are
//! identical, and the forward image lies about 8 px to the right of the backward one, as
//! feedback lag does when the forward line runs Right.
//!
//! * Fast direction: the page's scan direction code.
//! * Slow direction: not stated in the page header (nor the PRM text). Lines are taken to be
//!   stored in acquisition order, so it is `Down` for a negative y scale (stored line 0 at the
//!   top) and `Up` for a positive one; for a vertical fast axis `Left`/`Right` from the sign of
//!   the x scale.
//! * Pairs: two image pages of one channel (label, unit, page type, size, scales)
//!   with opposite scan directions form a [`dhct_scan::ScanPair`]; the earlier page is the
//!   trace. A lone page is a trace if it runs Right or Down (RHK "forward"), else a retrace.
//!   Pages whose periods differ (one NaN, or ten times the other) are still paired: the
//!   usable period is taken (the trace's if both are), the timing is marked assumed and
//!   both values are recorded under [`crate::ASSUMED_TIMING_KEY`].
//! * Pixel pitch `|x scale|`, `|y scale|` (x/y units, normally "m"); pixel period = period;
//!   scan angle = angle converted to radians (sign passed through as stored); offset = x/y
//!   offset. Turnaround time is not in the file: 0. A scale or period that is zero,
//!   negative, non-finite or outside [`crate::PLAUSIBLE_PITCH_M`] /
//!   [`crate::PLAUSIBLE_PIXEL_PERIOD_S`], or non-length x/y units, give [`crate::ASSUMED_PITCH`] /
//!   [`crate::ASSUMED_PIXEL_PERIOD`] marked [`dhct_scan::ValueSource::Assumed`], with the
//!   reason in the metadata keys [`crate::ASSUMED_SCALE_KEY`] / [`crate::ASSUMED_TIMING_KEY`]
//!   (`dhct info` shows them; `dhct correct` warns); an unknown scan direction code gives
//!   `Right` with the timing marked assumed; a non-finite scan angle or one beyond a full
//!   turn gives 0 (noted under `assumed scan angle`).
//! * Metadata (from the first image page): `signature`, `date` (ISO), `time`, `bias` (V),
//!   `current` (A), `system text`, `session text`, `user text`, `path`, `image pages`,
//!   `skipped pages`.
//! * Missing values: raw `i32::MIN` (what dhct writes for NaN) reads as NaN, as do lines past
//!   the "completed line count" of an aborted scan.
//!
//! The writer ([`write()`]) emits the reverse: x scale negative, y scale negative for a
//! downward slow scan; 17 strings (date as MM/DD/YY, which spym requires); z scale and offset
//! chosen so the data use nearly the whole i32 range. Lost on writing: turnaround time,
//! value sources (all read back as stated), and metadata other than date, time, bias,
//! current, texts and path. spym can label only Right/Left pages (its forward/backward), and
//! its image reshape assumes square pages. Gwyddion 2.62 and spym 0.9.2 both read the
//! written files back to the same values (`scripts/spym_sm4_crosscheck.py`).
//!
//! The older SM3 format ("STiMage 004") is read by [`sm3::read`]; see `docs/formats/sm3.md`.

mod layout;
mod orientation;
mod read;
pub mod sm3;
mod units;
mod write;

use std::io::Write;

use crate::{ReadError, ScanFile, WriteError};

/// Reads an SM4 file from memory: one [`dhct_scan::ScanPair`] per image channel.
pub fn read(bytes: &[u8]) -> Result<ScanFile, ReadError> {
    read::read(bytes, &crate::ReadLimits::default())
}

/// [`read()`] under `limits` (see [`crate::limits`]).
pub fn read_limited(bytes: &[u8], limits: &crate::ReadLimits) -> Result<ScanFile, ReadError> {
    read::read(bytes, limits)
}

/// Writes `file` as SM4: per pair a trace page then a retrace page (whichever exist).
///
/// Fails with [`WriteError::Unrepresentable`] if a value does not fit the format (32-bit
/// offsets, f32 scales), or if a pair has a single image whose trace runs Left or Up.
pub fn write<W: Write>(file: &ScanFile, w: &mut W) -> Result<(), WriteError> {
    write::write(file, w)
}

/// True if `bytes` start like an SM4 file (UTF-16LE "STiMage 005." at byte 2).
pub fn looks_like_sm4(bytes: &[u8]) -> bool {
    let magic = layout::MAGIC_PREFIX
        .encode_utf16()
        .flat_map(u16::to_le_bytes)
        .collect::<Vec<u8>>();
    bytes.len() >= layout::SIGNATURE_OFFSET + layout::SIGNATURE_BYTES
        && bytes
            .get(layout::SIGNATURE_OFFSET..layout::SIGNATURE_OFFSET + magic.len())
            .is_some_and(|head| head == magic.as_slice())
}
