//! JPK Instruments image reader (`.jpk`, `.jpk-qi-image`; NanoWizard and related AFMs).
//!
//! # Format
//!
//! A JPK image file is a classic TIFF (`II` or `MM`; the real files are big-endian) with one
//! directory (page) per image and JPK's private tags 0x8000–0x8FFF:
//!
//! * **Page 0** is a small 8-bit palette thumbnail whose tags hold the scan's global
//!   settings: software version (0x8000), start and end dates (0x8003, 0x8006), name
//!   (0x8004), feedback mode and setpoint (0x8030, 0x8033), the scan grid (0x8040–0x8047),
//!   the line rate and duty cycle (0x8049, 0x804A) and the slow-axis motion (0x804B). Its
//!   pixels are not read.
//! * **Every later page** with `PhotometricInterpretation` 1 (grey) and 16- or 32-bit
//!   samples (`SampleFormat` 1 unsigned, 2 signed or, for 32 bits, 3 float; a missing
//!   `SampleFormat` means unsigned) is a channel: uncompressed strips of `ImageWidth` samples
//!   per row, one sample per pixel. Its tags name it: 0x8050 the internal name (`height`,
//!   `measuredHeight`, `amplitude`, …), 0x8051 non-zero for a retrace, 0x8052 the display
//!   name ("Height", "Height (measured)", …).
//!
//! The directories are parsed here, not by the `tiff` crate: every offset and count is
//! checked against the file before use, a loop in the directory chain is refused, and the
//! pages, directory entries and pixels a file may declare are bounded (the pixels through
//! the [`ReadLimits`] budget), so a hostile file gives a [`ReadError`], never a panic or an
//! allocation beyond the file's size and the budget.
//!
//! # Channels and names
//!
//! A trace and a retrace page of the same internal name (and size) become one [`ScanPair`];
//! a channel recorded in one pass only becomes a pair with that pass alone. Pages are paired
//! in file order, each with the first earlier page of its name that still lacks its pass, so
//! two trace pages of one name (the QI sample has two `measuredHeight` pages, "Height
//! (measured)" and a "Ref. Force Height at 40%" computed from the force curves) stay separate
//! pairs. A pair is named by the display name (0x8052, else 0x8050); when several pairs
//! would share a name, each of them gets its first page's index appended, e.g.
//! "Height (measured) (page 3)". The metadata entry `jpk pages` lists which page went where
//! and with which calibration.
//!
//! Pairs are in file order, except that the preferred topography is moved first so that
//! [`ScanFile::topography`] returns it: the first `measuredHeight` pair (the z sensor's
//! measured position, closed loop, free of the z piezo's own hysteresis and creep) when there
//! is one, else the first `height` pair (the z piezo's commanded position). Either can be
//! chosen by name.
//!
//! # Calibration
//!
//! A channel page lists calibration *slots* (0x8080 = their number): slot `n`'s tags start
//! at `0x8090 + 0x30·n` with its name (+0x00), unit (+0x12, `Encoder_Unit`), scaling type
//! (+0x13) and, for `LinearScaling`, multiplier (+0x14) and offset (+0x15). The slot named
//! by `DefaultSlot` (0x8081) gives `z = raw · multiplier + offset` in its unit (the
//! multiplier and offset are stated back to the raw integer; the slots' parent chain is not
//! walked). A `NullScaling` slot is `z = raw`. A channel whose default slot is missing, not
//! found, of another scaling type or without a finite multiplier and offset is **skipped**,
//! with the reason under the metadata key `skipped pages` (not read with a made-up scale).
//! Units are kept as the file spells them: "m", "V", "deg", "N", "N/m".
//!
//! # Orientation
//!
//! Unless `Grid_Reflect` (0x8045; looked up in the channel's page, then in page 0) is
//! non-zero, the first stored row is the *bottom* of the image (as Gwyddion and AFMReader
//! show these files), so the rows are reversed into display orientation (row 0 at the top).
//! Columns are never mirrored: trace and retrace are both stored left to right, and the
//! trace runs to the right.
//!
//! `Motion` (0x804B) gives the slow direction in the grid's terms: `bottomUp` starts at the
//! first stored row, `topDown` at the last. Without reflection that is [`ScanDirection::Up`]
//! and [`ScanDirection::Down`] respectively. With reflection set (no such file was available
//! to check) the same rule is applied to the unreversed rows, whose first row is then the
//! top (`bottomUp` becomes [`ScanDirection::Down`]), and the timing is marked
//! [`ValueSource::Assumed`]. Without a known `Motion` (QI images have none) the lines are
//! taken as acquired in stored order, the timing marked assumed and the reason noted.
//!
//! # Geometry and timing
//!
//! * Pitch: `|Grid_uLength| / ImageWidth` along x and `|Grid_vLength| / ImageLength` along
//!   y (metres, 0x8042/0x8043). Implausible or missing: [`crate::ASSUMED_PITCH`], marked
//!   assumed.
//! * `Scanrate_Frequency` (0x8049) is the rate of line *pairs* (trace + retrace; on the
//!   real file the end minus start date over the line count is `1/f`) and
//!   `Scanrate_Dutycycle` (0x804A) the fraction of it spent scanning. Each pass takes
//!   `duty / (2 f)` and each turnaround `(1 − duty) / (2 f)`. Without a usable duty cycle
//!   the turnaround is taken as 0 (noted). Without a usable frequency (QI images have none:
//!   each pixel is a force curve) the timing is the placeholder
//!   [`crate::ASSUMED_PIXEL_PERIOD`], marked assumed and noted.
//! * Scan angle: `Grid_Theta` (0x8044), radians, as the scan angle.
//! * Offset: `Grid_x0`/`Grid_y0` (0x8040/0x8041) is the grid's origin corner (where `u` and
//!   `v` start), not its centre. The geometry's offset is the centre,
//!   `(x0, y0) + R(θ)·(uLength/2, vLength/2)` with `R(θ)` a counter-clockwise rotation. This
//!   reading of θ and of the origin fits the one real file with θ ≠ 0 (θ = π/2): the tip
//!   position its page 0 properties record (`xy-scanner-position-map…start-position`,
//!   apparently where the tip rested when the file was saved) lies within 0.001 pixel of
//!   `u = 0, v = vLength − ½ pixel` under that reading, the start of the last line of a
//!   `bottomUp` scan. JPK's documentation was not available to confirm it; the raw origin
//!   is kept in the metadata as `grid origin`. With `Grid_Reflect` set the offset is not set.
//!
//! # Metadata
//!
//! From page 0: `name`, `comment`, `sample`, `date` (start), `end date`, `software version`,
//! `account`, `feedback mode`, `setpoint` (a bare number: its unit depends on the feedback
//! mode, V in the sample files), `feedback p gain`, `feedback i gain`, `scan rate`,
//! `duty cycle`, `line end`, `motion`, `scan size`, `grid origin`, `scan angle`,
//! `grid reflect` (the text `<empty>` counts as absent). Also `jpk pages` (which page is
//! which pass of which pair, with its slot and unit), `skipped pages`, and the
//! [`crate::ASSUMED_SCALE_KEY`] / [`crate::ASSUMED_TIMING_KEY`] notes.
//!
//! # Refused
//!
//! BigTIFF; a TIFF whose first directory lacks JPK's tags (that is a plain TIFF); files whose
//! directories, strips or tag values run past the end or loop ([`ReadError::Truncated`],
//! [`ReadError::Corrupt`]); a file in which no page is a readable channel
//! ([`ReadError::NoImage`], listing why each page was skipped). Compressed, tiled,
//! multi-sample, 8-bit or 16-bit float pages are skipped and listed in `skipped pages`.
//! The related `.jpk-force`, `.jpk-force-map` and `.jpk-qi-data` files are ZIP archives of
//! force curves, not images, and are not detected as JPK.

use std::collections::{BTreeMap, BTreeSet};

use dhct_scan::{FileFormat, ImageChannel, ScanDirection, ScanGeometry, ScanPair, ValueSource};

use crate::limits::{Budget, ReadLimits};
use crate::placeholders::{
    ASSUMED_PITCH, ASSUMED_PIXEL_PERIOD, ASSUMED_SCALE_KEY, ASSUMED_TIMING_KEY,
    PLAUSIBLE_LINE_TIME_S, PLAUSIBLE_PITCH_M, PLAUSIBLE_PIXEL_PERIOD_S, PLAUSIBLE_SCAN_ANGLE_RAD,
    PLAUSIBLE_TURNAROUND_S, note, plausible,
};
use crate::{ReadError, ScanFile};

const FORMAT: FileFormat = FileFormat::Jpk;

/// Most pages (directories) a file may have.
const MAX_PAGES: usize = 4096;
/// Most directory entries all pages together may have (real files: about 100 per page).
const MAX_ENTRIES: usize = 1 << 18;
/// Largest image side accepted, pixels.
const MAX_SIDE: u64 = 1 << 20;

/// Metadata key listing the pages that were not read as channels, and why.
const SKIPPED_KEY: &str = "skipped pages";

/// Standard TIFF and JPK tag numbers.
mod tag {
    pub const IMAGE_WIDTH: u16 = 256;
    pub const IMAGE_LENGTH: u16 = 257;
    pub const BITS_PER_SAMPLE: u16 = 258;
    pub const COMPRESSION: u16 = 259;
    pub const PHOTOMETRIC: u16 = 262;
    pub const STRIP_OFFSETS: u16 = 273;
    pub const SAMPLES_PER_PIXEL: u16 = 277;
    pub const ROWS_PER_STRIP: u16 = 278;
    pub const STRIP_BYTE_COUNTS: u16 = 279;
    pub const TILE_WIDTH: u16 = 322;
    pub const TILE_OFFSETS: u16 = 324;
    pub const SAMPLE_FORMAT: u16 = 339;

    pub const FILE_FORMAT_VERSION: u16 = 0x8000;
    pub const START_DATE: u16 = 0x8003;
    pub const NAME: u16 = 0x8004;
    pub const COMMENT: u16 = 0x8005;
    pub const END_DATE: u16 = 0x8006;
    pub const SAMPLE: u16 = 0x8007;
    pub const ACCOUNT: u16 = 0x8009;
    pub const FEEDBACK_MODE: u16 = 0x8030;
    pub const FEEDBACK_P_GAIN: u16 = 0x8031;
    pub const FEEDBACK_I_GAIN: u16 = 0x8032;
    pub const SETPOINT: u16 = 0x8033;
    pub const GRID_X0: u16 = 0x8040;
    pub const GRID_Y0: u16 = 0x8041;
    pub const GRID_U_LENGTH: u16 = 0x8042;
    pub const GRID_V_LENGTH: u16 = 0x8043;
    pub const GRID_THETA: u16 = 0x8044;
    pub const GRID_REFLECT: u16 = 0x8045;
    pub const LINE_END: u16 = 0x8048;
    pub const SCANRATE_FREQUENCY: u16 = 0x8049;
    pub const SCANRATE_DUTYCYCLE: u16 = 0x804A;
    pub const MOTION: u16 = 0x804B;
    pub const CHANNEL: u16 = 0x8050;
    pub const CHANNEL_RETRACE: u16 = 0x8051;
    pub const CHANNEL_FANCY_NAME: u16 = 0x8052;
    pub const NR_OF_SLOTS: u16 = 0x8080;
    pub const DEFAULT_SLOT: u16 = 0x8081;
    /// Slot `n`'s tags are at `SLOT_BASE + SLOT_STRIDE·n + offset`.
    pub const SLOT_BASE: u16 = 0x8090;
    pub const SLOT_STRIDE: u16 = 0x30;
    pub const SLOT_NAME: u16 = 0x00;
    pub const SLOT_ENCODER_UNIT: u16 = 0x12;
    pub const SLOT_SCALING_TYPE: u16 = 0x13;
    pub const SLOT_MULTIPLY: u16 = 0x14;
    pub const SLOT_OFFSET: u16 = 0x15;
}

/// Slots that fit the tag space above [`tag::SLOT_BASE`].
const MAX_SLOTS: u16 = (u16::MAX - tag::SLOT_BASE) / tag::SLOT_STRIDE;

/// TIFF field types.
const ASCII: u16 = 2;
const FLOAT: u16 = 11;
const DOUBLE: u16 = 12;

/// Bytes per value of a classic TIFF field type; `None` for types this reader does not know.
fn type_size(field_type: u16) -> Option<u64> {
    match field_type {
        1 | 2 | 6 | 7 => Some(1),
        3 | 8 => Some(2),
        4 | 9 | 11 | 13 => Some(4),
        5 | 10 | 12 => Some(8),
        _ => None,
    }
}

/// True when `bytes` are a classic TIFF whose first directory carries JPK's own tags:
/// `FileFormatVersion` (0x8000) as text, or the grid lengths (0x8042 and 0x8043) as reals.
/// Only the entries' tags and types are looked at (a JPK file cut short after its first
/// directory is still recognised, and then reported as truncated). Never fails: anything
/// unreadable is simply not JPK.
pub fn looks_like_jpk(bytes: &[u8]) -> bool {
    let Ok((order, first)) = header(bytes) else {
        return false;
    };
    let tiff = Tiff { bytes, order };
    let Ok(count) = tiff.u16_at(first, "") else {
        return false;
    };
    let kind = |wanted: u16| {
        (0..u64::from(count)).find_map(|k| {
            let at = first + 2 + 12 * k;
            match tiff.u16_at(at, "") {
                Ok(found) if found == wanted => tiff.u16_at(at + 2, "").ok(),
                _ => None,
            }
        })
    };
    let typed = |t: u16, types: &[u16]| kind(t).is_some_and(|k| types.contains(&k));
    typed(tag::FILE_FORMAT_VERSION, &[ASCII])
        || (typed(tag::GRID_U_LENGTH, &[FLOAT, DOUBLE])
            && typed(tag::GRID_V_LENGTH, &[FLOAT, DOUBLE]))
}

/// [`looks_like_jpk`] for a parsed first directory.
fn is_jpk_page(page: &Page) -> bool {
    let typed = |t: u16, types: &[u16]| page.entry(t).is_some_and(|e| types.contains(&e.kind));
    typed(tag::FILE_FORMAT_VERSION, &[ASCII])
        || (typed(tag::GRID_U_LENGTH, &[FLOAT, DOUBLE])
            && typed(tag::GRID_V_LENGTH, &[FLOAT, DOUBLE]))
}

/// Reads a JPK image file (see the module docs).
pub fn read(bytes: &[u8]) -> Result<ScanFile, ReadError> {
    read_limited(bytes, &ReadLimits::default())
}

/// [`read`] under `limits` (see [`crate::limits`]): every channel is charged to the budget
/// before its values are allocated.
pub fn read_limited(bytes: &[u8], limits: &ReadLimits) -> Result<ScanFile, ReadError> {
    let mut budget = Budget::new(limits, bytes.len())?;
    let (order, first) = header(bytes)?;
    let tiff = Tiff { bytes, order };
    let pages = tiff.pages(first)?;
    let global = &pages[0];
    if !is_jpk_page(global) {
        return Err(ReadError::wrong_format(
            FORMAT,
            "the TIFF's first directory has no JPK tags (0x8000 or 0x8042/0x8043)",
        ));
    }
    let mut metadata = describe(&tiff, global);
    let mut skipped = Vec::new();
    let mut channels = Vec::new();
    for (index, page) in pages.iter().enumerate().skip(1) {
        match tiff.channel(index, page, global, &mut budget)? {
            Ok(channel) => channels.push(channel),
            Err(reason) => skipped.push(format!("page {index}: {reason}")),
        }
    }
    if !skipped.is_empty() {
        metadata.insert(SKIPPED_KEY.to_string(), skipped.join("; "));
    }
    if channels.is_empty() {
        return Err(ReadError::NoImage {
            format: FORMAT,
            reason: if skipped.is_empty() {
                "the file has only its thumbnail page".to_string()
            } else {
                format!("no page is a readable channel ({})", skipped.join("; "))
            },
        });
    }
    let groups = group(channels);
    let geometry = GeometryFactory::new(&tiff, global, &mut metadata);
    let mut pairs = Vec::with_capacity(groups.len());
    let mut listing = Vec::with_capacity(groups.len());
    for group in groups {
        let (columns, rows) = (group.columns, group.rows);
        let g = geometry.build(columns, rows, group.reflect, &mut metadata)?;
        let describe_page = |channel: &Channel, pass: &str| {
            format!(
                "page {} → \"{}\" {pass} (slot \"{}\", unit \"{}\")",
                channel.page, group.name, channel.slot, channel.unit
            )
        };
        let mut image = |channel: Option<Channel>, pass: &str| {
            channel.map(|c| {
                listing.push(describe_page(&c, pass));
                ImageChannel::from_row_major(group.name.clone(), c.unit, rows, columns, c.values)
            })
        };
        let trace = image(group.trace, "trace").transpose();
        let retrace = image(group.retrace, "retrace").transpose();
        let geometry_error = |source| ReadError::geometry(FORMAT, source);
        let pair = ScanPair::from_parts(
            g,
            trace.map_err(geometry_error)?,
            retrace.map_err(geometry_error)?,
        )
        .map_err(geometry_error)?;
        pairs.push(pair);
    }
    metadata.insert("jpk pages".to_string(), listing.join("; "));
    Ok(ScanFile {
        format: FORMAT,
        pairs,
        metadata,
    })
}

/// Byte order of the file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Order {
    Little,
    Big,
}

/// The byte order and the offset of the first directory, from the 8-byte TIFF header.
fn header(bytes: &[u8]) -> Result<(Order, u64), ReadError> {
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
struct Entry {
    tag: u16,
    kind: u16,
    count: u64,
    /// Where the value's bytes start (`None` for a field type this reader does not know).
    value_at: Option<u64>,
}

/// One directory: its entries sorted by tag (the first of duplicate tags kept).
#[derive(Debug, Clone)]
struct Page {
    entries: Vec<Entry>,
}

impl Page {
    fn entry(&self, tag: u16) -> Option<&Entry> {
        self.entries
            .binary_search_by_key(&tag, |e| e.tag)
            .ok()
            .map(|i| &self.entries[i])
    }
}

/// The file with its byte order.
struct Tiff<'a> {
    bytes: &'a [u8],
    order: Order,
}

impl<'a> Tiff<'a> {
    fn slice(&self, offset: u64, len: u64, what: &str) -> Result<&'a [u8], ReadError> {
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

    fn array<const N: usize>(&self, offset: u64, what: &str) -> Result<[u8; N], ReadError> {
        let mut out = [0u8; N];
        out.copy_from_slice(self.slice(offset, N as u64, what)?);
        if self.order == Order::Little {
            out.reverse();
        }
        // Now big-endian whatever the file's order.
        Ok(out)
    }

    fn u16_at(&self, offset: u64, what: &str) -> Result<u16, ReadError> {
        Ok(u16::from_be_bytes(self.array(offset, what)?))
    }

    fn u32_at(&self, offset: u64, what: &str) -> Result<u32, ReadError> {
        Ok(u32::from_be_bytes(self.array(offset, what)?))
    }

    /// The chain of directories from `first`: at least one, at most [`MAX_PAGES`], no loop.
    fn pages(&self, first: u64) -> Result<Vec<Page>, ReadError> {
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
    fn page(&self, index: usize, offset: u64, entries_left: &mut usize) -> Result<Page, ReadError> {
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
    fn integer_at(&self, entry: &Entry, i: u64) -> Option<i64> {
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

    fn unsigned(&self, page: &Page, tag: u16) -> Option<u64> {
        let entry = page.entry(tag)?;
        self.integer_at(entry, 0)
            .and_then(|v| u64::try_from(v).ok())
    }

    /// All values of an unsigned integer array (StripOffsets, StripByteCounts).
    fn unsigned_array(&self, page: &Page, tag: u16) -> Option<Vec<u64>> {
        let entry = page.entry(tag)?;
        (0..entry.count)
            .map(|i| {
                self.integer_at(entry, i)
                    .and_then(|v| u64::try_from(v).ok())
            })
            .collect()
    }

    /// The first value of a real (FLOAT or DOUBLE) or integer field; `None` if not finite.
    fn real(&self, page: &Page, tag: u16) -> Option<f64> {
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
    fn flag(&self, page: &Page, tag: u16) -> Option<bool> {
        let entry = page.entry(tag)?;
        self.integer_at(entry, 0).map(|v| v != 0)
    }

    /// An ASCII field up to its first NUL, trimmed; `None` when absent or empty.
    fn text(&self, page: &Page, tag: u16) -> Option<String> {
        let entry = page.entry(tag).filter(|e| e.kind == ASCII)?;
        let bytes = self.slice(entry.value_at?, entry.count, "").ok()?;
        let end = bytes.iter().position(|&b| b == 0).unwrap_or(bytes.len());
        let text = String::from_utf8_lossy(&bytes[..end]).trim().to_string();
        (!text.is_empty()).then_some(text)
    }

    /// The channel of page `index`: `Ok(Ok(channel))`, `Ok(Err(reason))` for a page that is
    /// not a readable channel (skipped), or `Err` for a file that is broken.
    fn channel(
        &self,
        index: usize,
        page: &Page,
        global: &Page,
        budget: &mut Budget,
    ) -> Result<Result<Channel, String>, ReadError> {
        let photometric = self.unsigned(page, tag::PHOTOMETRIC);
        if photometric != Some(1) {
            return Ok(Err(match photometric {
                Some(p) => format!("PhotometricInterpretation {p}, not a grey image"),
                None => "no PhotometricInterpretation".to_string(),
            }));
        }
        let bits = self.unsigned(page, tag::BITS_PER_SAMPLE).unwrap_or(1);
        let sample_format = self.unsigned(page, tag::SAMPLE_FORMAT).unwrap_or(1);
        let sample = match (bits, sample_format) {
            (16, 1) => Sample::U16,
            (16, 2) => Sample::I16,
            (32, 1) => Sample::U32,
            (32, 2) => Sample::I32,
            (32, 3) => Sample::F32,
            _ => {
                return Ok(Err(format!(
                    "{bits}-bit samples of SampleFormat {sample_format} (JPK channels are \
                     16- or 32-bit integers or 32-bit floats)"
                )));
            }
        };
        let compression = self.unsigned(page, tag::COMPRESSION).unwrap_or(1);
        if compression != 1 {
            return Ok(Err(format!("compressed (Compression {compression})")));
        }
        let samples = self.unsigned(page, tag::SAMPLES_PER_PIXEL).unwrap_or(1);
        if samples != 1 {
            return Ok(Err(format!("{samples} samples per pixel")));
        }
        if page.entry(tag::TILE_WIDTH).is_some() || page.entry(tag::TILE_OFFSETS).is_some() {
            return Ok(Err("tiled".to_string()));
        }
        let key = self.text(page, tag::CHANNEL);
        let display = self.text(page, tag::CHANNEL_FANCY_NAME);
        let retrace = self.flag(page, tag::CHANNEL_RETRACE).unwrap_or(false);
        let label = display
            .clone()
            .or_else(|| key.clone())
            .unwrap_or_else(|| format!("page {index}"));
        let scale = match self.default_slot(page) {
            Ok(scale) => scale,
            Err(reason) => return Ok(Err(format!("\"{label}\": {reason}"))),
        };
        let side = |t: u16, name: &str| -> Result<u64, ReadError> {
            match self.unsigned(page, t) {
                Some(n) if (1..=MAX_SIDE).contains(&n) => Ok(n),
                other => Err(ReadError::corrupt(
                    FORMAT,
                    format!(
                        "page {index}: {name} is {}, not 1 to {MAX_SIDE}",
                        other.map_or("missing".to_string(), |n| n.to_string())
                    ),
                )),
            }
        };
        let columns = side(tag::IMAGE_WIDTH, "ImageWidth")?;
        let rows = side(tag::IMAGE_LENGTH, "ImageLength")?;
        budget.charge_images(FORMAT, columns, rows, 1, 0)?;
        let reflect = self
            .flag(page, tag::GRID_REFLECT)
            .or_else(|| self.flag(global, tag::GRID_REFLECT))
            .unwrap_or(false);
        let raw = self.strips(index, page, columns, rows, sample)?;
        let (columns, rows) = (columns as usize, rows as usize);
        let mut values = Vec::new();
        values
            .try_reserve_exact(columns * rows)
            .map_err(|_| ReadError::corrupt(FORMAT, "not enough memory for the image"))?;
        for display_row in 0..rows {
            let stored = if reflect {
                display_row
            } else {
                rows - 1 - display_row
            };
            let line = raw[stored];
            values.extend(
                line.chunks_exact(sample.bytes())
                    .map(|b| sample.decode(b, self.order) * scale.multiply + scale.offset),
            );
        }
        Ok(Ok(Channel {
            page: index,
            key: key.unwrap_or_else(|| label.clone()),
            name: label,
            retrace,
            columns,
            rows,
            reflect,
            slot: scale.slot,
            unit: scale.unit,
            values,
        }))
    }

    /// The stored rows of a page (row 0 first), each `columns` samples, read through
    /// StripOffsets, RowsPerStrip and StripByteCounts.
    fn strips(
        &self,
        index: usize,
        page: &Page,
        columns: u64,
        rows: u64,
        sample: Sample,
    ) -> Result<Vec<&'a [u8]>, ReadError> {
        let corrupt = |what: String| ReadError::corrupt(FORMAT, format!("page {index}: {what}"));
        let rows_per_strip = match self.unsigned(page, tag::ROWS_PER_STRIP) {
            None => rows,
            Some(0) => return Err(corrupt("RowsPerStrip is 0".to_string())),
            Some(n) => n.min(rows),
        };
        let strips = rows.div_ceil(rows_per_strip);
        let offsets = self
            .unsigned_array(page, tag::STRIP_OFFSETS)
            .ok_or_else(|| corrupt("no usable StripOffsets".to_string()))?;
        if (offsets.len() as u64) < strips {
            return Err(corrupt(format!(
                "{} StripOffsets for {strips} strips of {rows_per_strip} rows",
                offsets.len()
            )));
        }
        let counts = self.unsigned_array(page, tag::STRIP_BYTE_COUNTS);
        let row_bytes = columns * sample.bytes() as u64;
        let mut lines = Vec::with_capacity(rows as usize);
        for strip in 0..strips {
            let first = strip * rows_per_strip;
            let strip_rows = rows_per_strip.min(rows - first);
            let needed = strip_rows * row_bytes;
            if let Some(counts) = &counts {
                match counts.get(strip as usize) {
                    Some(&count) if count >= needed => {}
                    Some(&count) => {
                        return Err(corrupt(format!(
                            "strip {strip} holds {count} bytes, {needed} needed for \
                             {strip_rows} rows of {columns} samples"
                        )));
                    }
                    None => {
                        return Err(corrupt(format!(
                            "{} StripByteCounts for {strips} strips",
                            counts.len()
                        )));
                    }
                }
            }
            let data = self.slice(
                offsets[strip as usize],
                needed,
                &format!("strip {strip} of page {index}"),
            )?;
            lines.extend(data.chunks_exact(row_bytes as usize));
        }
        Ok(lines)
    }

    /// The default calibration slot of a channel page, or why it cannot be used.
    fn default_slot(&self, page: &Page) -> Result<Scale, String> {
        let wanted = self
            .text(page, tag::DEFAULT_SLOT)
            .ok_or("no DefaultSlot (0x8081) names its calibration")?;
        let slots = self
            .unsigned(page, tag::NR_OF_SLOTS)
            .map_or(MAX_SLOTS, |n| n.min(u64::from(MAX_SLOTS)) as u16);
        let base = (0..slots)
            .map(|n| tag::SLOT_BASE + tag::SLOT_STRIDE * n)
            .find(|&base| self.text(page, base + tag::SLOT_NAME).as_deref() == Some(&wanted))
            .ok_or_else(|| {
                format!("its default calibration slot \"{wanted}\" is not in the file")
            })?;
        let unit = self
            .text(page, base + tag::SLOT_ENCODER_UNIT)
            .unwrap_or_default();
        let scaling = self.text(page, base + tag::SLOT_SCALING_TYPE);
        let (multiply, offset) = match scaling.as_deref() {
            Some("NullScaling") => (1.0, 0.0),
            Some("LinearScaling") => {
                match (
                    self.real(page, base + tag::SLOT_MULTIPLY),
                    self.real(page, base + tag::SLOT_OFFSET),
                ) {
                    (Some(m), Some(o)) => (m, o),
                    _ => {
                        return Err(format!(
                            "its default calibration slot \"{wanted}\" lacks a finite \
                             multiplier and offset"
                        ));
                    }
                }
            }
            other => {
                return Err(format!(
                    "its default calibration slot \"{wanted}\" has scaling type {}",
                    other.map_or("(none)".to_string(), |s| format!("\"{s}\""))
                ));
            }
        };
        Ok(Scale {
            slot: wanted,
            unit,
            multiply,
            offset,
        })
    }
}

/// How a sample is stored.
#[derive(Debug, Clone, Copy)]
enum Sample {
    U16,
    I16,
    U32,
    I32,
    F32,
}

impl Sample {
    fn bytes(self) -> usize {
        match self {
            Sample::U16 | Sample::I16 => 2,
            Sample::U32 | Sample::I32 | Sample::F32 => 4,
        }
    }

    /// The value of one sample's bytes (exactly [`Sample::bytes`] of them).
    fn decode(self, b: &[u8], order: Order) -> f64 {
        let two = || match order {
            Order::Big => [b[0], b[1]],
            Order::Little => [b[1], b[0]],
        };
        let four = || match order {
            Order::Big => [b[0], b[1], b[2], b[3]],
            Order::Little => [b[3], b[2], b[1], b[0]],
        };
        match self {
            Sample::U16 => f64::from(u16::from_be_bytes(two())),
            Sample::I16 => f64::from(i16::from_be_bytes(two())),
            Sample::U32 => f64::from(u32::from_be_bytes(four())),
            Sample::I32 => f64::from(i32::from_be_bytes(four())),
            Sample::F32 => f64::from(f32::from_be_bytes(four())),
        }
    }
}

/// A resolved calibration: `z = raw · multiply + offset`, in `unit`.
#[derive(Debug, Clone)]
struct Scale {
    slot: String,
    unit: String,
    multiply: f64,
    offset: f64,
}

/// One channel page, decoded into display orientation.
#[derive(Debug)]
struct Channel {
    page: usize,
    /// The internal name (0x8050) that pairs trace and retrace.
    key: String,
    /// The display name.
    name: String,
    retrace: bool,
    columns: usize,
    rows: usize,
    reflect: bool,
    slot: String,
    unit: String,
    values: Vec<f64>,
}

/// The pages of one pair.
#[derive(Debug)]
struct Group {
    key: String,
    name: String,
    first_page: usize,
    columns: usize,
    rows: usize,
    reflect: bool,
    trace: Option<Channel>,
    retrace: Option<Channel>,
}

/// Pairs the channels (see the module docs), names the pairs uniquely and puts the
/// preferred topography first.
fn group(channels: Vec<Channel>) -> Vec<Group> {
    let mut groups: Vec<Group> = Vec::new();
    for channel in channels {
        let home = groups.iter_mut().find(|g| {
            g.key == channel.key
                && (g.columns, g.rows, g.reflect)
                    == (channel.columns, channel.rows, channel.reflect)
                && if channel.retrace {
                    g.retrace.is_none()
                } else {
                    g.trace.is_none()
                }
        });
        let group = match home {
            Some(group) => group,
            None => {
                groups.push(Group {
                    key: channel.key.clone(),
                    name: channel.name.clone(),
                    first_page: channel.page,
                    columns: channel.columns,
                    rows: channel.rows,
                    reflect: channel.reflect,
                    trace: None,
                    retrace: None,
                });
                groups.last_mut().expect("just pushed")
            }
        };
        if channel.retrace {
            group.retrace = Some(channel);
        } else {
            group.trace = Some(channel);
        }
    }
    let mut uses: BTreeMap<String, usize> = BTreeMap::new();
    for g in &groups {
        *uses.entry(g.name.clone()).or_default() += 1;
    }
    for g in &mut groups {
        if uses[&g.name] > 1 {
            g.name = format!("{} (page {})", g.name, g.first_page);
        }
    }
    let preferred = groups
        .iter()
        .position(|g| g.key == "measuredHeight")
        .or_else(|| groups.iter().position(|g| g.key == "height"));
    if let Some(k) = preferred {
        let topography = groups.remove(k);
        groups.insert(0, topography);
    }
    groups
}

/// The file-wide scan settings from page 0, turned into a geometry per image size.
struct GeometryFactory {
    /// Grid lengths along u (x) and v (y), metres, signed as stated.
    lengths: Option<(f64, f64)>,
    origin: Option<(f64, f64)>,
    theta: Option<f64>,
    /// Line pair rate (Hz) and duty cycle.
    frequency: Option<f64>,
    duty: Option<f64>,
    /// `Some(true)`: bottomUp, `Some(false)`: topDown.
    bottom_up: Option<bool>,
    motion: Option<String>,
}

impl GeometryFactory {
    fn new(tiff: &Tiff, global: &Page, metadata: &mut BTreeMap<String, String>) -> Self {
        let real = |t| tiff.real(global, t);
        let lengths = match (real(tag::GRID_U_LENGTH), real(tag::GRID_V_LENGTH)) {
            (Some(u), Some(v)) => Some((u, v)),
            _ => None,
        };
        let origin = match (real(tag::GRID_X0), real(tag::GRID_Y0)) {
            (Some(x), Some(y)) => Some((x, y)),
            _ => None,
        };
        let theta = real(tag::GRID_THETA);
        if let Some(theta) = theta
            && !plausible(theta, &PLAUSIBLE_SCAN_ANGLE_RAD)
        {
            metadata.insert(
                "ignored scan angle".to_string(),
                format!("Grid_Theta = {theta} rad is beyond a full turn"),
            );
        }
        let motion = tiff.text(global, tag::MOTION);
        let bottom_up = match motion.as_deref() {
            Some("bottomUp") => Some(true),
            Some("topDown") => Some(false),
            _ => None,
        };
        GeometryFactory {
            lengths,
            origin,
            // `+ 0.0` turns a stated −0 into 0.
            theta: theta
                .filter(|t| plausible(*t, &PLAUSIBLE_SCAN_ANGLE_RAD))
                .map(|t| t + 0.0),
            frequency: real(tag::SCANRATE_FREQUENCY),
            duty: real(tag::SCANRATE_DUTYCYCLE),
            bottom_up,
            motion,
        }
    }

    fn build(
        &self,
        columns: usize,
        rows: usize,
        reflect: bool,
        metadata: &mut BTreeMap<String, String>,
    ) -> Result<ScanGeometry, ReadError> {
        let geometry_error = |source| ReadError::geometry(FORMAT, source);
        let pitch = self
            .lengths
            .map(|(u, v)| (u.abs() / columns as f64, v.abs() / rows as f64));
        let (pitch_x, pitch_y, scale_source) = match pitch {
            Some((x, y))
                if plausible(x, &PLAUSIBLE_PITCH_M) && plausible(y, &PLAUSIBLE_PITCH_M) =>
            {
                (x, y, ValueSource::Stated)
            }
            _ => {
                note(
                    metadata,
                    ASSUMED_SCALE_KEY,
                    match self.lengths {
                        Some((u, v)) => format!(
                            "Grid_uLength {u:e} m / Grid_vLength {v:e} m give an implausible \
                             pixel size for {columns} x {rows} px"
                        ),
                        None => "no Grid_uLength / Grid_vLength (0x8042/0x8043)".to_string(),
                    },
                );
                (ASSUMED_PITCH, ASSUMED_PITCH, ValueSource::Assumed)
            }
        };

        let mut timing_source = ValueSource::Stated;
        // The line pair period and the part of it spent scanning.
        let pair_period = self
            .frequency
            .filter(|f| *f > 0.0)
            .map(|f| 1.0 / f)
            .filter(|p| plausible(p / 2.0, &PLAUSIBLE_LINE_TIME_S));
        let (line_time, turnaround) = match pair_period {
            Some(period) => {
                let duty = self.duty.filter(|d| *d > 0.0 && *d <= 1.0);
                let duty = duty.unwrap_or_else(|| {
                    note(
                        metadata,
                        ASSUMED_TIMING_KEY,
                        "no usable Scanrate_Dutycycle (0x804A): no turnaround assumed",
                    );
                    1.0
                });
                (duty * period / 2.0, (1.0 - duty) * period / 2.0)
            }
            None => {
                timing_source = ValueSource::Assumed;
                note(
                    metadata,
                    ASSUMED_TIMING_KEY,
                    match self.frequency {
                        Some(f) => format!("Scanrate_Frequency (0x8049) of {f} Hz is implausible"),
                        None => "no Scanrate_Frequency (0x8049), as in QI (force map) images"
                            .to_string(),
                    },
                );
                (ASSUMED_PIXEL_PERIOD * columns as f64, 0.0)
            }
        };
        let line_time_usable = plausible(line_time / columns as f64, &PLAUSIBLE_PIXEL_PERIOD_S)
            && plausible(turnaround, &PLAUSIBLE_TURNAROUND_S);
        let (line_time, turnaround) = if line_time_usable {
            (line_time, turnaround)
        } else {
            timing_source = ValueSource::Assumed;
            note(
                metadata,
                ASSUMED_TIMING_KEY,
                format!(
                    "a line time of {line_time:e} s gives an implausible pixel period for \
                     {columns} px"
                ),
            );
            (ASSUMED_PIXEL_PERIOD * columns as f64, 0.0)
        };

        // Which end of the stored rows was acquired first, and where it is displayed.
        let first_stored_first = match self.bottom_up {
            Some(bottom_up) => bottom_up,
            None => {
                timing_source = ValueSource::Assumed;
                note(
                    metadata,
                    ASSUMED_TIMING_KEY,
                    match &self.motion {
                        Some(m) => format!(
                            "unknown Motion \"{m}\" (0x804B): lines taken as acquired in \
                             stored order"
                        ),
                        None => "no Motion (0x804B): lines taken as acquired in stored order"
                            .to_string(),
                    },
                );
                true
            }
        };
        if reflect {
            timing_source = ValueSource::Assumed;
            note(
                metadata,
                ASSUMED_TIMING_KEY,
                "Grid_Reflect is set: the slow direction follows Motion on the unreversed rows \
                 (unverified, no such file was available)",
            );
        }
        // Unreflected, the first stored row is the bottom of the displayed image.
        let slow = if first_stored_first != reflect {
            ScanDirection::Up
        } else {
            ScanDirection::Down
        };
        let mut geometry = ScanGeometry::from_line_time(
            columns,
            rows,
            pitch_x,
            pitch_y,
            line_time,
            ScanDirection::Right,
            slow,
        )
        .and_then(|g| g.with_turnaround(turnaround))
        .map_err(geometry_error)?
        .with_scale_source(scale_source)
        .with_timing_source(timing_source);
        let theta = self.theta.unwrap_or(0.0);
        if self.theta.is_some() {
            geometry = geometry.with_scan_angle(theta).map_err(geometry_error)?;
        }
        if let (Some((x0, y0)), Some((u, v)), false) = (self.origin, self.lengths, reflect) {
            let (sin, cos) = theta.sin_cos();
            let centre = (
                x0 + 0.5 * (u * cos - v * sin),
                y0 + 0.5 * (u * sin + v * cos),
            );
            if centre.0.is_finite() && centre.1.is_finite() {
                geometry = geometry
                    .with_offset(centre.0, centre.1)
                    .map_err(geometry_error)?;
            }
        }
        Ok(geometry)
    }
}

/// Metadata from page 0.
fn describe(tiff: &Tiff, global: &Page) -> BTreeMap<String, String> {
    let mut m = BTreeMap::new();
    let text = |t| tiff.text(global, t).filter(|s| s != "<empty>");
    for (key, t) in [
        ("name", tag::NAME),
        ("comment", tag::COMMENT),
        ("sample", tag::SAMPLE),
        ("date", tag::START_DATE),
        ("end date", tag::END_DATE),
        ("software version", tag::FILE_FORMAT_VERSION),
        ("account", tag::ACCOUNT),
        ("feedback mode", tag::FEEDBACK_MODE),
        ("line end", tag::LINE_END),
        ("motion", tag::MOTION),
    ] {
        if let Some(value) = text(t) {
            m.insert(key.to_string(), value);
        }
    }
    let real = |t| tiff.real(global, t);
    for (key, t) in [
        ("setpoint", tag::SETPOINT),
        ("feedback p gain", tag::FEEDBACK_P_GAIN),
        ("feedback i gain", tag::FEEDBACK_I_GAIN),
        ("duty cycle", tag::SCANRATE_DUTYCYCLE),
    ] {
        if let Some(value) = real(t) {
            m.insert(key.to_string(), value.to_string());
        }
    }
    if let Some(f) = real(tag::SCANRATE_FREQUENCY) {
        m.insert(
            "scan rate".to_string(),
            format!("{f} Hz (trace + retrace line pairs per second)"),
        );
    }
    if let (Some(u), Some(v)) = (real(tag::GRID_U_LENGTH), real(tag::GRID_V_LENGTH)) {
        m.insert("scan size".to_string(), format!("{u:e} m × {v:e} m"));
    }
    if let (Some(x), Some(y)) = (real(tag::GRID_X0), real(tag::GRID_Y0)) {
        m.insert(
            "grid origin".to_string(),
            format!("x0 = {x:e} m, y0 = {y:e} m"),
        );
    }
    if let Some(theta) = real(tag::GRID_THETA) {
        m.insert(
            "scan angle".to_string(),
            format!("{theta} rad ({:.3} deg)", theta.to_degrees()),
        );
    }
    if let Some(reflect) = tiff.flag(global, tag::GRID_REFLECT) {
        m.insert("grid reflect".to_string(), reflect.to_string());
    }
    m
}

#[cfg(test)]
mod tests {
    use super::*;

    const SHORT: u16 = 3;
    const LONG: u16 = 4;

    /// A big-endian TIFF header and one directory of `entries` (tag, type, count, value).
    fn tiny(entries: &[(u16, u16, u32, u32)]) -> Vec<u8> {
        let mut b = b"MM\0*\0\0\0\x08".to_vec();
        b.extend((entries.len() as u16).to_be_bytes());
        for &(t, kind, count, value) in entries {
            b.extend(t.to_be_bytes());
            b.extend(kind.to_be_bytes());
            b.extend(count.to_be_bytes());
            b.extend(value.to_be_bytes());
        }
        b.extend(0u32.to_be_bytes());
        b
    }

    #[test]
    fn detection_needs_a_jpk_tag_in_the_first_directory() {
        // 0x8000 as a 3-byte ASCII value held inline ("6.0" without NUL is fine).
        let jpk = tiny(&[(256, SHORT, 1, 1 << 16), (0x8000, ASCII, 3, 0x362E_3000)]);
        assert!(looks_like_jpk(&jpk));
        let plain = tiny(&[(256, SHORT, 1, 1 << 16), (0x8298, ASCII, 3, 0x4142_4300)]);
        assert!(!looks_like_jpk(&plain));
        // 0x8000 of another type is not JPK's.
        assert!(!looks_like_jpk(&tiny(&[(0x8000, LONG, 1, 5)])));
        // Grid lengths as doubles: the tags and types decide, even with the values cut off
        // (reading then reports the truncation).
        let cut = tiny(&[(0x8042, DOUBLE, 1, 1000), (0x8043, DOUBLE, 1, 1000)]);
        assert!(looks_like_jpk(&cut));
        assert!(matches!(read(&cut), Err(ReadError::Truncated { .. })));
        assert!(!looks_like_jpk(&tiny(&[(0x8042, DOUBLE, 1, 1000)])));
        let mut grid = tiny(&[(0x8042, DOUBLE, 1, 38), (0x8043, DOUBLE, 1, 38)]);
        grid.extend(1e-6f64.to_be_bytes());
        assert!(looks_like_jpk(&grid));
        // The second entry's tag and type end at byte 8 + 2 + 12 + 4.
        for cut in 0..jpk.len() {
            assert_eq!(looks_like_jpk(&jpk[..cut]), cut >= 26, "cut at {cut}");
        }
        assert!(!looks_like_jpk(b""));
        assert!(!looks_like_jpk(b"II+\0\x08\0\0\0"));
    }

    #[test]
    fn a_directory_chain_that_loops_is_refused() {
        let mut b = tiny(&[(0x8000, ASCII, 3, 0x362E_3000)]);
        let link = b.len() - 4;
        b[link..].copy_from_slice(&8u32.to_be_bytes());
        let error = read(&b).unwrap_err();
        assert!(error.to_string().contains("loops"), "{error}");
    }

    #[test]
    fn slots_resolve_by_name_and_refuse_unknown_scalings() {
        let mut b = tiny(&[
            (0x8080, LONG, 1, 2),
            (0x8081, ASCII, 2, 0x6200_0000),
            (0x8090, ASCII, 2, 0x6100_0000),
            (0x80A3, ASCII, 2, 0x7800_0000),
            (0x80C0, ASCII, 2, 0x6200_0000),
            (0x80D2, ASCII, 2, 0x6D00_0000),
            (0x80D3, ASCII, 14, 0),
            (0x80D4, DOUBLE, 1, 0),
            (0x80D5, DOUBLE, 1, 0),
        ]);
        let values = b.len() as u32;
        b.extend(b"LinearScaling\0");
        b.extend(2.5f64.to_be_bytes());
        b.extend((-1.0f64).to_be_bytes());
        // Point the out-of-line values at their bytes.
        let entry = |k: usize| 10 + 12 * k + 8;
        b[entry(6)..entry(6) + 4].copy_from_slice(&values.to_be_bytes());
        b[entry(7)..entry(7) + 4].copy_from_slice(&(values + 14).to_be_bytes());
        b[entry(8)..entry(8) + 4].copy_from_slice(&(values + 22).to_be_bytes());
        let (order, first) = header(&b).unwrap();
        let tiff = Tiff { bytes: &b, order };
        let page = tiff.page(0, first, &mut { MAX_ENTRIES }).unwrap();
        let scale = tiff.default_slot(&page).unwrap();
        assert_eq!(
            (
                scale.slot.as_str(),
                scale.unit.as_str(),
                scale.multiply,
                scale.offset
            ),
            ("b", "m", 2.5, -1.0)
        );
        // Default slot "a": scaling type "x" is refused, naming it.
        b[10 + 12 + 8] = b'a';
        let page = Tiff { bytes: &b, order }
            .page(0, first, &mut { MAX_ENTRIES })
            .unwrap();
        let reason = Tiff { bytes: &b, order }.default_slot(&page).unwrap_err();
        assert!(reason.contains("\"x\""), "{reason}");
    }
}
