//! The TIFF container of a JPK file: its header and directories (pages), read with every
//! offset and count checked against the file, and the typed values of their tags.

use std::collections::BTreeSet;

use dhct_scan::FileFormat;

use crate::ReadError;

pub(super) const FORMAT: FileFormat = FileFormat::Jpk;

/// Most pages (directories) a file may have.
pub(super) const MAX_PAGES: usize = 4096;
/// Most directory entries all pages together may have (real files: about 100 per page).
pub(super) const MAX_ENTRIES: usize = 1 << 18;
/// Largest image side accepted, pixels.
pub(super) const MAX_SIDE: u64 = 1 << 20;

/// Metadata key listing the pages that were not read as channels, and why.
pub(super) const SKIPPED_KEY: &str = "skipped pages";

/// Standard TIFF and JPK tag numbers.
pub(super) mod tag {
    pub(in crate::jpk) const IMAGE_WIDTH: u16 = 256;
    pub(in crate::jpk) const IMAGE_LENGTH: u16 = 257;
    pub(in crate::jpk) const BITS_PER_SAMPLE: u16 = 258;
    pub(in crate::jpk) const COMPRESSION: u16 = 259;
    pub(in crate::jpk) const PHOTOMETRIC: u16 = 262;
    pub(in crate::jpk) const STRIP_OFFSETS: u16 = 273;
    pub(in crate::jpk) const SAMPLES_PER_PIXEL: u16 = 277;
    pub(in crate::jpk) const ROWS_PER_STRIP: u16 = 278;
    pub(in crate::jpk) const STRIP_BYTE_COUNTS: u16 = 279;
    pub(in crate::jpk) const TILE_WIDTH: u16 = 322;
    pub(in crate::jpk) const TILE_OFFSETS: u16 = 324;
    pub(in crate::jpk) const SAMPLE_FORMAT: u16 = 339;

    pub(in crate::jpk) const FILE_FORMAT_VERSION: u16 = 0x8000;
    pub(in crate::jpk) const START_DATE: u16 = 0x8003;
    pub(in crate::jpk) const NAME: u16 = 0x8004;
    pub(in crate::jpk) const COMMENT: u16 = 0x8005;
    pub(in crate::jpk) const END_DATE: u16 = 0x8006;
    pub(in crate::jpk) const SAMPLE: u16 = 0x8007;
    pub(in crate::jpk) const ACCOUNT: u16 = 0x8009;
    pub(in crate::jpk) const FEEDBACK_MODE: u16 = 0x8030;
    pub(in crate::jpk) const FEEDBACK_P_GAIN: u16 = 0x8031;
    pub(in crate::jpk) const FEEDBACK_I_GAIN: u16 = 0x8032;
    pub(in crate::jpk) const SETPOINT: u16 = 0x8033;
    pub(in crate::jpk) const GRID_X0: u16 = 0x8040;
    pub(in crate::jpk) const GRID_Y0: u16 = 0x8041;
    pub(in crate::jpk) const GRID_U_LENGTH: u16 = 0x8042;
    pub(in crate::jpk) const GRID_V_LENGTH: u16 = 0x8043;
    pub(in crate::jpk) const GRID_THETA: u16 = 0x8044;
    pub(in crate::jpk) const GRID_REFLECT: u16 = 0x8045;
    pub(in crate::jpk) const LINE_END: u16 = 0x8048;
    pub(in crate::jpk) const SCANRATE_FREQUENCY: u16 = 0x8049;
    pub(in crate::jpk) const SCANRATE_DUTYCYCLE: u16 = 0x804A;
    pub(in crate::jpk) const MOTION: u16 = 0x804B;
    pub(in crate::jpk) const CHANNEL: u16 = 0x8050;
    pub(in crate::jpk) const CHANNEL_RETRACE: u16 = 0x8051;
    pub(in crate::jpk) const CHANNEL_FANCY_NAME: u16 = 0x8052;
    pub(in crate::jpk) const NR_OF_SLOTS: u16 = 0x8080;
    pub(in crate::jpk) const DEFAULT_SLOT: u16 = 0x8081;
    /// Slot `n`'s tags are at `SLOT_BASE + SLOT_STRIDE·n + offset`.
    pub(in crate::jpk) const SLOT_BASE: u16 = 0x8090;
    pub(in crate::jpk) const SLOT_STRIDE: u16 = 0x30;
    pub(in crate::jpk) const SLOT_NAME: u16 = 0x00;
    pub(in crate::jpk) const SLOT_ENCODER_UNIT: u16 = 0x12;
    pub(in crate::jpk) const SLOT_SCALING_TYPE: u16 = 0x13;
    pub(in crate::jpk) const SLOT_MULTIPLY: u16 = 0x14;
    pub(in crate::jpk) const SLOT_OFFSET: u16 = 0x15;
}

/// Slots that fit the tag space above [`tag::SLOT_BASE`].
pub(super) const MAX_SLOTS: u16 = (u16::MAX - tag::SLOT_BASE) / tag::SLOT_STRIDE;

/// TIFF field types.
pub(super) const ASCII: u16 = 2;
pub(super) const FLOAT: u16 = 11;
pub(super) const DOUBLE: u16 = 12;

/// Bytes per value of a classic TIFF field type; `None` for types this reader does not know.
pub(super) fn type_size(field_type: u16) -> Option<u64> {
    match field_type {
        1 | 2 | 6 | 7 => Some(1),
        3 | 8 => Some(2),
        4 | 9 | 11 | 13 => Some(4),
        5 | 10 | 12 => Some(8),
        _ => None,
    }
}

/// Byte order of the file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Order {
    Little,
    Big,
}

/// The byte order and the offset of the first directory, from the 8-byte TIFF header.
pub(super) fn header(bytes: &[u8]) -> Result<(Order, u64), ReadError> {
    let order = match bytes.get(..2) {
        Some(b"II") => Order::Little,
        Some(b"MM") => Order::Big,
        _ => return Err(ReadError::wrong_format(FORMAT, "no TIFF byte-order mark")),
    };
    let tiff = Tiff { bytes, order };
    let magic = tiff.u16_at(2, "the TIFF header")?;
    match magic {
        42 => {}
        43 => {
            return Err(ReadError::unsupported(
                FORMAT,
                "BigTIFF (JPK's image files are classic TIFFs)",
            ));
        }
        other => {
            return Err(ReadError::wrong_format(
                FORMAT,
                format!("TIFF version {other} instead of 42"),
            ));
        }
    }
    let first = u64::from(tiff.u32_at(4, "the TIFF header")?);
    Ok((order, first))
}

/// One directory entry; its value has been checked to lie inside the file.
#[derive(Debug, Clone, Copy)]
pub(super) struct Entry {
    pub(super) tag: u16,
    pub(super) kind: u16,
    pub(super) count: u64,
    /// Where the value's bytes start (`None` for a field type this reader does not know).
    pub(super) value_at: Option<u64>,
}

/// One directory: its entries sorted by tag (the first of duplicate tags kept).
#[derive(Debug, Clone)]
pub(super) struct Page {
    pub(super) entries: Vec<Entry>,
}

impl Page {
    pub(super) fn entry(&self, tag: u16) -> Option<&Entry> {
        self.entries
            .binary_search_by_key(&tag, |e| e.tag)
            .ok()
            .map(|i| &self.entries[i])
    }
}

/// The file with its byte order.
pub(super) struct Tiff<'a> {
    pub(super) bytes: &'a [u8],
    pub(super) order: Order,
}

impl<'a> Tiff<'a> {
    pub(super) fn slice(&self, offset: u64, len: u64, what: &str) -> Result<&'a [u8], ReadError> {
        let file_len = self.bytes.len() as u64;
        match offset.checked_add(len) {
            Some(end) if end <= file_len => Ok(&self.bytes[offset as usize..end as usize]),
            _ => Err(ReadError::Truncated {
                format: FORMAT,
                what: what.to_string(),
                offset,
                needed: len,
                len: file_len,
            }),
        }
    }

    pub(super) fn array<const N: usize>(
        &self,
        offset: u64,
        what: &str,
    ) -> Result<[u8; N], ReadError> {
        let mut out = [0u8; N];
        out.copy_from_slice(self.slice(offset, N as u64, what)?);
        if self.order == Order::Little {
            out.reverse();
        }
        // Now big-endian whatever the file's order.
        Ok(out)
    }

    pub(super) fn u16_at(&self, offset: u64, what: &str) -> Result<u16, ReadError> {
        Ok(u16::from_be_bytes(self.array(offset, what)?))
    }

    pub(super) fn u32_at(&self, offset: u64, what: &str) -> Result<u32, ReadError> {
        Ok(u32::from_be_bytes(self.array(offset, what)?))
    }

    /// The chain of directories from `first`: at least one, at most [`MAX_PAGES`], no loop.
    pub(super) fn pages(&self, first: u64) -> Result<Vec<Page>, ReadError> {
        let mut pages = Vec::new();
        let mut seen = BTreeSet::new();
        let mut entries_left = MAX_ENTRIES;
        let mut next = first;
        while next != 0 {
            if pages.len() >= MAX_PAGES {
                return Err(ReadError::corrupt(
                    FORMAT,
                    format!("more than {MAX_PAGES} directories"),
                ));
            }
            if !seen.insert(next) {
                return Err(ReadError::corrupt(
                    FORMAT,
                    format!("the directory chain loops back to offset {next}"),
                ));
            }
            let index = pages.len();
            pages.push(self.page(index, next, &mut entries_left)?);
            let count = u64::from(self.u16_at(next, "a directory")?);
            let link = next + 2 + 12 * count;
            next = u64::from(self.u32_at(link, &format!("the link after directory {index}"))?);
        }
        if pages.is_empty() {
            return Err(ReadError::corrupt(FORMAT, "the TIFF has no directory"));
        }
        Ok(pages)
    }

    /// The directory at `offset` (page `index`, for messages), its entries charged to
    /// `entries_left`.
    pub(super) fn page(
        &self,
        index: usize,
        offset: u64,
        entries_left: &mut usize,
    ) -> Result<Page, ReadError> {
        let what = format!("directory {index}");
        let count = self.u16_at(offset, &what)?;
        let count = usize::from(count);
        if count > *entries_left {
            return Err(ReadError::corrupt(
                FORMAT,
                format!("the directories declare more than {MAX_ENTRIES} entries"),
            ));
        }
        *entries_left -= count;
        // The entries and the link to the next directory must all be in the file.
        self.slice(offset, 2 + 12 * count as u64 + 4, &what)?;
        let mut entries = Vec::with_capacity(count);
        for k in 0..count as u64 {
            let at = offset + 2 + 12 * k;
            let tag = self.u16_at(at, &what)?;
            let kind = self.u16_at(at + 2, &what)?;
            let count = u64::from(self.u32_at(at + 4, &what)?);
            let value_at = match type_size(kind) {
                None => None,
                Some(size) => {
                    let len = size * count;
                    let value_at = if len <= 4 {
                        at + 8
                    } else {
                        u64::from(self.u32_at(at + 8, &what)?)
                    };
                    let file_len = self.bytes.len() as u64;
                    if value_at.checked_add(len).is_none_or(|end| end > file_len) {
                        return Err(ReadError::Truncated {
                            format: FORMAT,
                            what: format!(
                                "the value of tag {tag} (0x{tag:04X}) in directory {index}"
                            ),
                            offset: value_at,
                            needed: len,
                            len: file_len,
                        });
                    }
                    Some(value_at)
                }
            };
            entries.push(Entry {
                tag,
                kind,
                count,
                value_at,
            });
        }
        entries.sort_by_key(|e| e.tag);
        entries.dedup_by_key(|e| e.tag);
        Ok(Page { entries })
    }

    /// The `i`-th value of `entry` as an integer (BYTE, SHORT, LONG and their signed kinds;
    /// `None` for other types or past the count).
    pub(super) fn integer_at(&self, entry: &Entry, i: u64) -> Option<i64> {
        if i >= entry.count {
            return None;
        }
        let at = entry.value_at?;
        let value = match entry.kind {
            1 => i64::from(self.slice(at + i, 1, "").ok()?[0]),
            6 => i64::from(self.slice(at + i, 1, "").ok()?[0] as i8),
            3 => i64::from(self.u16_at(at + 2 * i, "").ok()?),
            8 => i64::from(self.u16_at(at + 2 * i, "").ok()? as i16),
            4 => i64::from(self.u32_at(at + 4 * i, "").ok()?),
            9 => i64::from(self.u32_at(at + 4 * i, "").ok()? as i32),
            _ => return None,
        };
        Some(value)
    }

    pub(super) fn unsigned(&self, page: &Page, tag: u16) -> Option<u64> {
        let entry = page.entry(tag)?;
        self.integer_at(entry, 0)
            .and_then(|v| u64::try_from(v).ok())
    }

    /// All values of an unsigned integer array (StripOffsets, StripByteCounts).
    pub(super) fn unsigned_array(&self, page: &Page, tag: u16) -> Option<Vec<u64>> {
        let entry = page.entry(tag)?;
        (0..entry.count)
            .map(|i| {
                self.integer_at(entry, i)
                    .and_then(|v| u64::try_from(v).ok())
            })
            .collect()
    }

    /// The first value of a real (FLOAT or DOUBLE) or integer field; `None` if not finite.
    pub(super) fn real(&self, page: &Page, tag: u16) -> Option<f64> {
        let entry = page.entry(tag)?;
        let at = entry.value_at?;
        if entry.count == 0 {
            return None;
        }
        let value = match entry.kind {
            FLOAT => f64::from(f32::from_bits(self.u32_at(at, "").ok()?)),
            DOUBLE => {
                let bytes: [u8; 8] = self.array(at, "").ok()?;
                f64::from_be_bytes(bytes)
            }
            _ => self.integer_at(entry, 0)? as f64,
        };
        value.is_finite().then_some(value)
    }

    /// A flag: any non-zero integer.
    pub(super) fn flag(&self, page: &Page, tag: u16) -> Option<bool> {
        let entry = page.entry(tag)?;
        self.integer_at(entry, 0).map(|v| v != 0)
    }

    /// An ASCII field up to its first NUL, trimmed; `None` when absent or empty.
    pub(super) fn text(&self, page: &Page, tag: u16) -> Option<String> {
        let entry = page.entry(tag).filter(|e| e.kind == ASCII)?;
        let bytes = self.slice(entry.value_at?, entry.count, "").ok()?;
        let end = bytes.iter().position(|&b| b == 0).unwrap_or(bytes.len());
        let text = String::from_utf8_lossy(&bytes[..end]).trim().to_string();
        (!text.is_empty()).then_some(text)
    }
}
