//! RHK SM3 files ("STiMage 004", the predecessor of SM4): reader only.
//!
//! Layout (from Gwyddion's `modules/file/rhk-sm3.c`; no real SM3 file was available to check
//! it, so this reader is tested only on files built from that description). An SM3 file is a
//! plain sequence of pages, each:
//!
//! * u16 `param_size`: bytes of page header after this field; the strings start at
//!   `page start + 2 + param_size`;
//! * 36-byte UTF-16LE signature `"STiMage 004.NNN N"`;
//! * u16 string count; u32 data type (0 image, 1 line, 3 annotated line), page type,
//!   data sub-source, line type; i32 x/y coordinate; u32 x size, y size, source type,
//!   image type, scan direction (0 right, 1 left, 2 up, 3 down), group id, data size;
//!   i32 min/max z; f32 x scale, y scale, z scale, xy scale, x offset, y offset, z offset,
//!   period, bias, current, angle; 16-byte page id (160 bytes from the page start in all);
//! * the strings: label, system text, session text, user text, path, date, time, x units,
//!   y units, z units, x label, y label (u16 count of UTF-16 code units, then the units);
//! * `x size · y size` little-endian i32 samples, `value = raw · z scale + z offset`;
//! * for image pages only: u16 colour-info size and that many bytes.
//!
//! Images are decoded exactly like SM4 pages (same sign rules, directions and pairing; see
//! [`crate::sm4`]). Gwyddion's SM3 module takes absolute scales and always mirrors columns;
//! that agrees with these rules for the usual negative x and y scales. Not validated on a
//! real SM3 file (we have none); see `docs/formats/sm3.md`.

use dhct_scan::{FileFormat, ScanFile};

use super::layout::string;
use super::read::{PageHeader, decode_image, decode_utf16, file_metadata, pair_pages};
use crate::ReadError;
use crate::bytes::{ByteReader, checked_data_len};
use crate::limits::{Budget, ReadLimits};

const FORMAT: FileFormat = FileFormat::RhkSm3;

/// "STiMage 004." in UTF-16LE, at byte 2 of every page.
const MAGIC_PREFIX: &str = "STiMage 004.";
/// Bytes from a page's start to the end of its fixed fields (the page id).
const PAGE_FIELDS_END: u64 = 160;
/// Data type code of an image page.
const IMAGE: u32 = 0;

/// True if `bytes` start like an SM3 file (UTF-16LE "STiMage 004." at byte 2).
pub fn looks_like_sm3(bytes: &[u8]) -> bool {
    magic_at(bytes, 0)
}

fn magic_at(bytes: &[u8], page_start: usize) -> bool {
    let magic: Vec<u8> = MAGIC_PREFIX
        .encode_utf16()
        .flat_map(u16::to_le_bytes)
        .collect();
    page_start
        .checked_add(2)
        .and_then(|from| bytes.get(from..from.checked_add(magic.len())?))
        .is_some_and(|head| head == magic.as_slice())
}

fn corrupt(reason: impl Into<String>) -> ReadError {
    ReadError::corrupt(FORMAT, reason)
}

/// Reads an SM3 file: one [`dhct_scan::ScanPair`] per image channel; line pages are skipped.
pub fn read(bytes: &[u8]) -> Result<ScanFile, ReadError> {
    read_limited(bytes, &ReadLimits::default())
}

/// [`read`] under `limits` (see [`crate::limits`]).
pub fn read_limited(bytes: &[u8], limits: &ReadLimits) -> Result<ScanFile, ReadError> {
    let mut images = Budget::new(limits, bytes.len())?;
    if !looks_like_sm3(bytes) {
        return Err(ReadError::wrong_format(
            FORMAT,
            "no UTF-16 \"STiMage 004.\" (SM3) signature at byte 2",
        ));
    }
    let signature = decode_utf16(bytes.get(2..38).unwrap_or_default());
    let mut reader = ByteReader::new(bytes, FORMAT);
    let mut pages = Vec::new();
    let mut skipped = Vec::new();
    let mut start = 0u64;
    let mut number = 0u32;
    while (start as usize) < bytes.len() {
        let what = format!("SM3 page {number}");
        if !magic_at(bytes, start as usize) {
            return Err(corrupt(format!(
                "{what} at byte {start} has no SM3 signature"
            )));
        }
        reader.seek(start, &what)?;
        let param_size = u64::from(reader.u16_le(&what)?);
        if 2 + param_size < PAGE_FIELDS_END {
            return Err(corrupt(format!(
                "{what} header is {param_size} bytes, too short for its fields"
            )));
        }
        reader.seek(start + 38, &what)?;
        let string_count = reader.u16_le(&what)?;
        let data_type = reader.u32_le(&what)?;
        let page_type = reader.u32_le(&what)?;
        let _data_sub_source = reader.u32_le(&what)?;
        let _line_type = reader.u32_le(&what)?;
        let _x_coord = reader.i32_le(&what)?;
        let _y_coord = reader.i32_le(&what)?;
        let x_size = reader.u32_le(&what)?;
        let y_size = reader.u32_le(&what)?;
        let _source_type = reader.u32_le(&what)?;
        let _image_type = reader.u32_le(&what)?;
        let scan_dir = reader.u32_le(&what)?;
        let _group_id = reader.u32_le(&what)?;
        let _data_size = reader.u32_le(&what)?;
        let _min_z = reader.i32_le(&what)?;
        let _max_z = reader.i32_le(&what)?;
        let x_scale = reader.f32_le(&what)?;
        let y_scale = reader.f32_le(&what)?;
        let z_scale = reader.f32_le(&what)?;
        let _xy_scale = reader.f32_le(&what)?;
        let x_offset = reader.f32_le(&what)?;
        let y_offset = reader.f32_le(&what)?;
        let z_offset = reader.f32_le(&what)?;
        let period = reader.f32_le(&what)?;
        let bias = reader.f32_le(&what)?;
        let current = reader.f32_le(&what)?;
        let angle = reader.f32_le(&what)?;

        // Strings: all must be walked to find the data; the first few are kept.
        reader.seek(start + 2 + param_size, &what)?;
        let mut strings = Vec::new();
        for k in 0..usize::from(string_count) {
            let units = u64::from(reader.u16_le(&what)?);
            let text = reader.take(2 * units, &what)?;
            if k < string::KNOWN {
                strings.push(decode_utf16(text));
            }
        }
        let data_len = checked_data_len(FORMAT, u64::from(y_size), u64::from(x_size), 4)?;
        let raw = reader.take(data_len, &what)?;
        if data_type == IMAGE {
            let colour_info = u64::from(reader.u16_le(&what)?);
            reader.take(colour_info, &what)?;
            let header = PageHeader {
                string_count,
                page_type,
                x_size,
                y_size,
                scan_dir,
                x_scale,
                y_scale,
                z_scale,
                x_offset,
                y_offset,
                z_offset,
                period,
                bias,
                current,
                angle,
                objects: Vec::new(),
            };
            pages.push(decode_image(number, header, strings, raw, &mut images)?);
        } else {
            skipped.push(format!("{number} (data type {data_type})"));
        }
        // At least the 160 fixed bytes were consumed, so this always moves forward.
        start = reader.position() as u64;
        number = number
            .checked_add(1)
            .ok_or_else(|| corrupt("too many pages"))?;
    }
    if pages.is_empty() {
        return Err(ReadError::NoImage {
            format: FORMAT,
            reason: format!("none of its {number} SM3 pages is an image"),
        });
    }
    let mut metadata = file_metadata(&pages, &signature);
    if !skipped.is_empty() {
        metadata.insert("skipped pages".to_string(), skipped.join(", "));
    }
    Ok(ScanFile {
        format: FORMAT,
        pairs: pair_pages(pages, &mut metadata)?,
        metadata,
    })
}
