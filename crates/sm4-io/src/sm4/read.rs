//! The SM4 reader: file header → page index → image pages → [`ScanFile`].

use std::collections::{BTreeMap, HashMap, VecDeque};

use dhct_scan::{
    FileFormat, ImageChannel, ScanDirection, ScanFile, ScanGeometry, ScanPair, ValueSource,
};
use ndarray::Array2;

use super::layout::{
    self, FILE_HEADER_FIELDS_OFFSET, FILE_HEADER_SIZE, MAX_OBJECTS_PER_LIST, MISSING_RAW,
    OBJECT_ENTRY_SIZE, PAGE_HEADER_SIZE, PAGE_HEADER_USED, PAGE_INDEX_ENTRY_SIZE,
    PAGE_INDEX_HEADER_SIZE, data_type, object, page_type, scan_dir, string,
};
use super::orientation::{Orientation, slow_direction};
use super::units::{length_factor, si_unit};
use crate::bytes::{ByteReader, checked_data_len};
use crate::limits::{Budget, ReadLimits};
use crate::placeholders::{
    ASSUMED_SCALE_KEY, ASSUMED_TIMING_KEY, PLAUSIBLE_PITCH_M, PLAUSIBLE_PIXEL_PERIOD_S,
    PLAUSIBLE_SCAN_ANGLE_RAD, note, plausible,
};
use crate::{GeometryOverrides, ReadError};

const FORMAT: FileFormat = FileFormat::RhkSm4;

/// Metadata key listing why a page's scan angle was replaced by 0.
const ASSUMED_ANGLE_KEY: &str = "assumed scan angle";

use crate::placeholders::{ASSUMED_PITCH, ASSUMED_PIXEL_PERIOD};

fn corrupt(reason: impl Into<String>) -> ReadError {
    ReadError::corrupt(FORMAT, reason)
}

/// One object list entry: what is stored where.
#[derive(Debug, Clone, Copy)]
pub(super) struct Object {
    kind: u32,
    /// Absolute byte offset in the file.
    offset: u64,
    /// Bytes.
    size: u64,
}

fn find(objects: &[Object], kind: u32) -> Option<Object> {
    objects.iter().copied().find(|o| o.kind == kind)
}

/// Bounds the total bytes the parser may visit to a small multiple of the file size, so a
/// hostile file whose pages all point at the same large object cannot make us allocate or
/// loop far beyond its own size.
struct VisitBudget {
    remaining: u64,
}

impl VisitBudget {
    fn new(file_len: usize) -> VisitBudget {
        VisitBudget {
            remaining: (file_len as u64).saturating_mul(2).saturating_add(1 << 20),
        }
    }

    fn spend(&mut self, bytes: u64, what: &str) -> Result<(), ReadError> {
        match self.remaining.checked_sub(bytes) {
            Some(rest) => {
                self.remaining = rest;
                Ok(())
            }
            None => Err(corrupt(format!(
                "{what}: the file's objects refer to the same bytes too many times"
            ))),
        }
    }
}

/// The page header fields dhct uses (little-endian, at the page header object's offset).
/// SM3 pages carry the same fields (without the object list).
#[derive(Debug, Clone)]
pub(super) struct PageHeader {
    pub(super) string_count: u16,
    pub(super) page_type: u32,
    pub(super) x_size: u32,
    pub(super) y_size: u32,
    pub(super) scan_dir: u32,
    /// Metres per pixel along stored columns (signed; see `orientation.rs`).
    pub(super) x_scale: f32,
    /// Metres per pixel along stored rows (signed).
    pub(super) y_scale: f32,
    /// z units per raw count.
    pub(super) z_scale: f32,
    /// Metres.
    pub(super) x_offset: f32,
    /// Metres.
    pub(super) y_offset: f32,
    /// z units.
    pub(super) z_offset: f32,
    /// Seconds per pixel.
    pub(super) period: f32,
    /// Volts.
    pub(super) bias: f32,
    /// Amperes.
    pub(super) current: f32,
    /// Degrees.
    pub(super) angle: f32,
    /// The page header's object list (empty for SM3).
    pub(super) objects: Vec<Object>,
}

/// One page index entry.
#[derive(Debug, Clone)]
struct PageIndex {
    data_type: u32,
    objects: Vec<Object>,
}

/// An image page decoded into display orientation.
#[derive(Debug)]
pub(super) struct ImagePage {
    number: u32,
    channel: ImageChannel,
    fast: ScanDirection,
    geometry: ScanGeometry,
    /// Identifies pages that belong to one channel (label, unit, type, size, scales).
    key: PairKey,
    strings: Vec<String>,
    header: PageHeader,
    /// Why values of this page were assumed: (metadata key, reason).
    notes: Vec<(&'static str, String)>,
}

#[derive(Debug, Clone, PartialEq, Eq, Hash)]
struct PairKey {
    name: String,
    unit: String,
    page_type: u32,
    x_size: u32,
    y_size: u32,
    x_scale_bits: u32,
    y_scale_bits: u32,
}

struct Parser<'a> {
    reader: ByteReader<'a>,
    /// Bytes per object list entry (the file header's "object field size", normally 12).
    stride: u64,
    budget: VisitBudget,
    /// Pixels and decoded bytes (see [`crate::limits`]).
    images: crate::limits::Budget,
}

impl Parser<'_> {
    /// Reads an object list of `count` entries at `offset`.
    fn objects(&mut self, offset: u64, count: u32, what: &str) -> Result<Vec<Object>, ReadError> {
        if count > MAX_OBJECTS_PER_LIST {
            return Err(corrupt(format!(
                "{what} claims {count} objects (at most {MAX_OBJECTS_PER_LIST} are plausible)"
            )));
        }
        let len = u64::from(count) * self.stride;
        self.reader.slice_at(offset, len, what)?;
        self.budget.spend(len, what)?;
        let mut objects = Vec::with_capacity(count as usize);
        for k in 0..u64::from(count) {
            self.reader.seek(offset + k * self.stride, what)?;
            let kind = self.reader.u32_le(what)?;
            let offset = u64::from(self.reader.u32_le(what)?);
            let size = u64::from(self.reader.u32_le(what)?);
            objects.push(Object { kind, offset, size });
        }
        Ok(objects)
    }

    /// Reads the page index entry at `offset` whose fixed part is `entry_size` bytes.
    /// Returns the entry and the offset of the next one.
    fn page_index(
        &mut self,
        number: u32,
        offset: u64,
        entry_size: u64,
    ) -> Result<(PageIndex, u64), ReadError> {
        let what = format!("page index entry {number}");
        self.budget.spend(entry_size, &what)?;
        self.reader.seek(offset, &what)?;
        self.reader.take(16, &what)?; // page GUID
        let data_type = self.reader.u32_le(&what)?;
        let _source = self.reader.u32_le(&what)?;
        let object_count = self.reader.u32_le(&what)?;
        let _minor_version = self.reader.u32_le(&what)?;
        let list_offset = offset
            .checked_add(entry_size)
            .ok_or_else(|| corrupt(format!("{what} lies beyond any file")))?;
        let objects = self.objects(list_offset, object_count, &format!("{what} object list"))?;
        let next = list_offset + u64::from(object_count) * self.stride;
        Ok((PageIndex { data_type, objects }, next))
    }

    fn page_header(&mut self, number: u32, object: Object) -> Result<PageHeader, ReadError> {
        let what = format!("page {number} header");
        if object.size < u64::from(PAGE_HEADER_USED) {
            return Err(corrupt(format!(
                "{what} is {} bytes, fewer than the {PAGE_HEADER_USED} of its fields",
                object.size
            )));
        }
        self.budget.spend(u64::from(PAGE_HEADER_SIZE), &what)?;
        let r = &mut self.reader;
        r.seek(object.offset, &what)?;
        let _field_size = r.u16_le(&what)?;
        let string_count = r.u16_le(&what)?;
        let page_type = r.u32_le(&what)?;
        let _data_sub_source = r.u32_le(&what)?;
        let _line_type = r.u32_le(&what)?;
        let _x_corner = r.i32_le(&what)?;
        let _y_corner = r.i32_le(&what)?;
        let x_size = r.u32_le(&what)?;
        let y_size = r.u32_le(&what)?;
        let _image_type = r.u32_le(&what)?;
        let scan_dir = r.u32_le(&what)?;
        let _group_id = r.u32_le(&what)?;
        let _data_size = r.u32_le(&what)?;
        let _min_z = r.i32_le(&what)?;
        let _max_z = r.i32_le(&what)?;
        let x_scale = r.f32_le(&what)?;
        let y_scale = r.f32_le(&what)?;
        let z_scale = r.f32_le(&what)?;
        let _xy_scale = r.f32_le(&what)?;
        let x_offset = r.f32_le(&what)?;
        let y_offset = r.f32_le(&what)?;
        let z_offset = r.f32_le(&what)?;
        let period = r.f32_le(&what)?;
        let bias = r.f32_le(&what)?;
        let current = r.f32_le(&what)?;
        let angle = r.f32_le(&what)?;
        let _color_info_count = r.u32_le(&what)?;
        let _grid_x_size = r.u32_le(&what)?;
        let _grid_y_size = r.u32_le(&what)?;
        let object_count = r.u32_le(&what)?;
        // The object list follows the fixed 180-byte header (as Gwyddion and spym read it).
        let objects = self.objects(
            object.offset + u64::from(PAGE_HEADER_SIZE),
            object_count,
            &format!("{what} object list"),
        )?;
        Ok(PageHeader {
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
            objects,
        })
    }

    /// Reads the first [`string::KNOWN`] strings of a page's string object: each a u16
    /// count of UTF-16LE code units, then the units.
    fn strings(
        &mut self,
        number: u32,
        object: Object,
        count: u16,
    ) -> Result<Vec<String>, ReadError> {
        let what = format!("page {number} strings");
        let end = object.offset.saturating_add(object.size);
        self.reader.slice_at(object.offset, object.size, &what)?;
        let mut position = object.offset;
        let mut strings = Vec::new();
        for _ in 0..usize::from(count).min(string::KNOWN) {
            if position.saturating_add(2) > end {
                return Err(corrupt(format!("{what} run past the end of their object")));
            }
            self.reader.seek(position, &what)?;
            let units = u64::from(self.reader.u16_le(&what)?);
            position += 2;
            if position.saturating_add(2 * units) > end {
                return Err(corrupt(format!("{what} run past the end of their object")));
            }
            self.budget.spend(2 + 2 * units, &what)?;
            let bytes = self.reader.take(2 * units, &what)?;
            position += 2 * units;
            strings.push(decode_utf16(bytes));
        }
        Ok(strings)
    }

    fn image_page(&mut self, number: u32, index: &PageIndex) -> Result<ImagePage, ReadError> {
        let header_object = find(&index.objects, object::PAGE_HEADER)
            .ok_or_else(|| corrupt(format!("image page {number} has no page header object")))?;
        let header = self.page_header(number, header_object)?;
        let strings = match find(&header.objects, object::STRING_DATA) {
            Some(o) if o.size > 0 => self.strings(number, o, header.string_count)?,
            _ => Vec::new(),
        };
        let (columns, rows) = (header.x_size, header.y_size);
        if columns == 0 || rows == 0 {
            return Err(corrupt(format!(
                "image page {number} is {columns} x {rows} px"
            )));
        }
        let data_object = find(&index.objects, object::PAGE_DATA)
            .ok_or_else(|| corrupt(format!("image page {number} has no data object")))?;
        let expected = checked_data_len(FORMAT, u64::from(rows), u64::from(columns), 4)?;
        if data_object.size != expected {
            return Err(corrupt(format!(
                "image page {number} is {columns} x {rows} px (needs {expected} bytes of i32) \
                 but its data object holds {} bytes",
                data_object.size
            )));
        }
        let what = format!("page {number} data");
        let raw = self.reader.slice_at(data_object.offset, expected, &what)?;
        self.budget.spend(expected, &what)?;
        decode_image(number, header, strings, raw, &mut self.images)
    }
}

/// Decodes an image page whose `raw` data (`x_size · y_size` little-endian i32, checked by
/// the caller) and header are known: display orientation, units, geometry, pairing key.
pub(super) fn decode_image(
    number: u32,
    header: PageHeader,
    strings: Vec<String>,
    raw: &[u8],
    images: &mut Budget,
) -> Result<ImagePage, ReadError> {
    let text = |k: usize| strings.get(k).map(|s| s.trim()).unwrap_or("");
    let (columns, rows) = (header.x_size, header.y_size);
    let expected = u64::from(columns)
        .checked_mul(u64::from(rows))
        .and_then(|n| n.checked_mul(4));
    if columns == 0 || rows == 0 || expected != Some(raw.len() as u64) {
        return Err(corrupt(format!(
            "image page {number} is {columns} x {rows} px with {} bytes of data",
            raw.len()
        )));
    }
    images.charge_images(FORMAT, u64::from(columns), u64::from(rows), 1, 0)?;
    let (z_factor, unit) = si_unit(text(string::Z_UNITS));
    let (columns, rows) = (columns as usize, rows as usize);
    let x_scale = f64::from(header.x_scale);
    let y_scale = f64::from(header.y_scale);
    let orientation = Orientation::from_scales(x_scale, y_scale);
    let z_scale = f64::from(header.z_scale) * z_factor;
    let z_offset = f64::from(header.z_offset) * z_factor;
    let mut z = Array2::<f64>::zeros((rows, columns));
    for (k, chunk) in raw.chunks_exact(4).enumerate() {
        let value = match chunk {
            [a, b, c, d] => i32::from_le_bytes([*a, *b, *c, *d]),
            _ => continue,
        };
        let (row, column) = orientation.map(k / columns, k % columns, rows, columns);
        if let Some(cell) = z.get_mut((row, column)) {
            *cell = if value == MISSING_RAW {
                f64::NAN
            } else {
                f64::from(value) * z_scale + z_offset
            };
        }
    }

    let (fast, direction_known) = match scan_dir::decode(header.scan_dir) {
        Some(direction) => (direction, true),
        None => (ScanDirection::Right, false),
    };
    let slow = slow_direction(fast, x_scale, y_scale);
    let mut notes = Vec::new();
    if !direction_known {
        notes.push((
            ASSUMED_TIMING_KEY,
            format!(
                "page {number}: unknown scan direction code {}, Right assumed",
                header.scan_dir
            ),
        ));
    }
    let geometry = page_geometry(
        number,
        &header,
        &strings,
        (columns, rows),
        (fast, slow),
        direction_known,
        &mut notes,
    )?;
    blank_incomplete_lines(&mut z, &geometry, text(string::COMPLETED_LINE_COUNT));

    let name = match text(string::LABEL) {
        "" => page_type::name(header.page_type).to_string(),
        label => label.to_string(),
    };
    let key = PairKey {
        name: name.clone(),
        unit: unit.clone(),
        page_type: header.page_type,
        x_size: header.x_size,
        y_size: header.y_size,
        x_scale_bits: header.x_scale.abs().to_bits(),
        y_scale_bits: header.y_scale.abs().to_bits(),
    };
    Ok(ImagePage {
        number,
        channel: ImageChannel::new(name, unit, z),
        fast,
        geometry,
        key,
        strings,
        header,
        notes,
    })
}

/// The scan geometry of one page (see the module docs for the conventions).
///
/// A scale or period that is not finite, not positive or outside the plausible ranges of
/// `crate::PLAUSIBLE_*` becomes the placeholder, marked assumed, with the reason pushed
/// to `notes`; so does a scan angle beyond one full turn (0 is used).
fn page_geometry(
    number: u32,
    header: &PageHeader,
    strings: &[String],
    (columns, rows): (usize, usize),
    (fast, slow): (ScanDirection, ScanDirection),
    direction_known: bool,
    notes: &mut Vec<(&'static str, String)>,
) -> Result<ScanGeometry, ReadError> {
    let text = |k: usize| strings.get(k).map(|s| s.trim()).unwrap_or("");
    // Lateral units: metres normally; anything else leaves the pitch unknown.
    let x_factor = length_factor(text(string::X_UNITS));
    let y_factor = length_factor(text(string::Y_UNITS));
    let mut scale_stated = x_factor.is_some() && y_factor.is_some();
    if !scale_stated {
        notes.push((
            ASSUMED_SCALE_KEY,
            format!(
                "page {number}: x/y units \"{}\"/\"{}\" are not lengths",
                text(string::X_UNITS),
                text(string::Y_UNITS)
            ),
        ));
    }
    let mut pitch = |axis: &str, scale: f32, factor: Option<f64>| {
        let value = f64::from(scale).abs() * factor.unwrap_or(1.0);
        if plausible(value, &PLAUSIBLE_PITCH_M) {
            value
        } else {
            scale_stated = false;
            notes.push((
                ASSUMED_SCALE_KEY,
                format!("page {number}: {axis} scale {scale} is not a usable pixel pitch"),
            ));
            ASSUMED_PITCH
        }
    };
    let pitch_x = pitch("x", header.x_scale, x_factor);
    let pitch_y = pitch("y", header.y_scale, y_factor);
    let period = f64::from(header.period);
    let period_stated = plausible(period, &PLAUSIBLE_PIXEL_PERIOD_S);
    if !period_stated {
        notes.push((
            ASSUMED_TIMING_KEY,
            format!(
                "page {number}: period {period} s per pixel is unusable, \
                 {ASSUMED_PIXEL_PERIOD} s assumed"
            ),
        ));
    }
    let period = if period_stated {
        period
    } else {
        ASSUMED_PIXEL_PERIOD
    };
    let finite_or_zero = |v: f64| if v.is_finite() { v } else { 0.0 };
    let angle = f64::from(header.angle).to_radians();
    let angle = if plausible(angle, &PLAUSIBLE_SCAN_ANGLE_RAD) {
        angle
    } else {
        notes.push((
            ASSUMED_ANGLE_KEY,
            format!(
                "page {number}: scan angle {} degrees is unusable, 0 assumed",
                header.angle
            ),
        ));
        0.0
    };
    let offset_x = finite_or_zero(f64::from(header.x_offset) * x_factor.unwrap_or(1.0));
    let offset_y = finite_or_zero(f64::from(header.y_offset) * y_factor.unwrap_or(1.0));
    let source = |stated: bool| {
        if stated {
            ValueSource::Stated
        } else {
            ValueSource::Assumed
        }
    };
    let geometry = ScanGeometry::new(columns, rows, pitch_x, pitch_y, period, fast, slow)
        .and_then(|g| g.with_scan_angle(angle))
        .and_then(|g| g.with_offset(offset_x, offset_y))
        .map_err(|e| ReadError::geometry(FORMAT, e))?;
    Ok(geometry
        .with_scale_source(source(scale_stated))
        .with_timing_source(source(period_stated && direction_known))
        .with_start_time(page_start_time(text(string::DATE), text(string::TIME))))
}

/// The page's DATE ("MM/DD/YY") and TIME ("HH:MM:SS") strings as seconds since 1970
/// ([`dhct_scan::clock`]); two-digit years are 19xx from 70 on, else 20xx.
fn page_start_time(date: &str, time: &str) -> Option<f64> {
    let parts: Vec<u32> = date
        .split('/')
        .map(|p| p.trim().parse().ok())
        .collect::<Option<_>>()?;
    let [month, day, year] = parts.as_slice() else {
        return None;
    };
    let year = match *year {
        y @ 0..=69 => 2000 + i64::from(y),
        y @ 70..=99 => 1900 + i64::from(y),
        y => i64::from(y),
    };
    let clock = dhct_scan::clock::parse_time_of_day(time)?;
    dhct_scan::clock::seconds_from_civil((year, *month, *day), clock)
}

/// Sets the lines a partial scan never reached to NaN: lines (in acquisition order) from
/// the page's "completed line count" on, when that count is between 1 and the line count.
fn blank_incomplete_lines(z: &mut Array2<f64>, geometry: &ScanGeometry, completed: &str) {
    let Ok(completed) = completed.parse::<usize>() else {
        return;
    };
    let lines = geometry.slow_len();
    if completed == 0 || completed >= lines {
        return;
    }
    let slow = geometry.slow_direction();
    for ((row, column), value) in z.indexed_iter_mut() {
        let along = match slow {
            ScanDirection::Down => row,
            ScanDirection::Up => lines - 1 - row,
            ScanDirection::Right => column,
            ScanDirection::Left => lines - 1 - column,
        };
        if along >= completed {
            *value = f64::NAN;
        }
    }
}

/// UTF-16LE code units to a string, dropping trailing NULs; invalid units become U+FFFD.
pub(super) fn decode_utf16(bytes: &[u8]) -> String {
    let units: Vec<u16> = bytes
        .chunks_exact(2)
        .map(|pair| match pair {
            [lo, hi] => u16::from_le_bytes([*lo, *hi]),
            _ => 0,
        })
        .collect();
    String::from_utf16_lossy(&units)
        .trim_end_matches('\0')
        .to_string()
}

/// Reads a whole SM4 file. See [`crate::sm4`] for the layout and conventions.
pub(crate) fn read(bytes: &[u8], limits: &ReadLimits) -> Result<ScanFile, ReadError> {
    if !super::looks_like_sm4(bytes) {
        return Err(ReadError::wrong_format(
            FORMAT,
            "no UTF-16 \"STiMage 005.\" signature at byte 2",
        ));
    }
    let mut reader = ByteReader::new(bytes, FORMAT);
    let header_size = reader.u16_le("file header size")?;
    if header_size < FILE_HEADER_SIZE {
        return Err(corrupt(format!(
            "file header size is {header_size} bytes, fewer than the {FILE_HEADER_SIZE} of its fields"
        )));
    }
    let signature = decode_utf16(reader.slice_at(
        layout::SIGNATURE_OFFSET as u64,
        layout::SIGNATURE_BYTES as u64,
        "signature",
    )?);
    reader.seek(FILE_HEADER_FIELDS_OFFSET, "file header")?;
    let _total_page_count = reader.u32_le("file header page count")?;
    let object_count = reader.u32_le("file header object count")?;
    let object_field_size = reader.u32_le("file header object field size")?;
    if object_field_size < OBJECT_ENTRY_SIZE {
        return Err(corrupt(format!(
            "object entries are {object_field_size} bytes, fewer than the {OBJECT_ENTRY_SIZE} of their fields"
        )));
    }
    let mut parser = Parser {
        reader,
        stride: u64::from(object_field_size),
        budget: VisitBudget::new(bytes.len()),
        images: Budget::new(limits, bytes.len())?,
    };
    let file_objects = parser.objects(
        2 + u64::from(header_size),
        object_count,
        "file header object list",
    )?;

    let index_header = find(&file_objects, object::PAGE_INDEX_HEADER)
        .ok_or_else(|| corrupt("the file header lists no page index header"))?;
    if index_header.size < u64::from(PAGE_INDEX_HEADER_SIZE) {
        return Err(corrupt("the page index header object is too small"));
    }
    parser
        .reader
        .seek(index_header.offset, "page index header")?;
    let page_count = parser.reader.u32_le("page index header page count")?;
    let index_object_count = parser.reader.u32_le("page index header object count")?;
    let index_objects = parser.objects(
        index_header.offset + u64::from(PAGE_INDEX_HEADER_SIZE),
        index_object_count,
        "page index header object list",
    )?;
    let array = find(&index_objects, object::PAGE_INDEX_ARRAY)
        .ok_or_else(|| corrupt("the page index header lists no page index array"))?;
    if array.size < u64::from(PAGE_INDEX_ENTRY_SIZE) {
        return Err(corrupt(format!(
            "page index entries are {} bytes, fewer than the {PAGE_INDEX_ENTRY_SIZE} of their fields",
            array.size
        )));
    }

    let mut pages = Vec::new();
    let mut skipped = Vec::new();
    let mut position = array.offset;
    for number in 0..page_count {
        let (index, next) = parser.page_index(number, position, array.size)?;
        position = next;
        if index.data_type == data_type::IMAGE {
            pages.push(parser.image_page(number, &index)?);
        } else {
            skipped.push(format!("{number} ({})", data_type::name(index.data_type)));
        }
    }
    if pages.is_empty() {
        return Err(ReadError::NoImage {
            format: FORMAT,
            reason: format!("none of its {page_count} pages is an image"),
        });
    }

    let mut metadata = file_metadata(&pages, &signature);
    if !skipped.is_empty() {
        metadata.insert("skipped pages".to_string(), skipped.join(", "));
    }
    let pairs = pair_pages(pages, &mut metadata)?;
    Ok(ScanFile {
        format: FORMAT,
        pairs,
        metadata,
    })
}

/// Groups pages into trace/retrace pairs: two pages of the same channel (label, unit, type,
/// size, scales) with opposite fast directions. The earlier page in the file is the
/// trace. A page without a partner is a trace if it runs Right or Down (RHK's "forward"),
/// else a retrace. Every page's assumptions are noted in `metadata`; so is a pair whose
/// pages state different pixel periods (see [`reconcile_timing`]), which is still paired.
pub(super) fn pair_pages(
    pages: Vec<ImagePage>,
    metadata: &mut BTreeMap<String, String>,
) -> Result<Vec<ScanPair>, ReadError> {
    for page in &pages {
        for (key, text) in &page.notes {
            note(metadata, key, text.clone());
        }
    }
    let mut partner: Vec<Option<usize>> = vec![None; pages.len()];
    let mut is_retrace = vec![false; pages.len()];
    let mut waiting: HashMap<(PairKey, ScanDirection), VecDeque<usize>> = HashMap::new();
    for (j, page) in pages.iter().enumerate() {
        let wanted = (page.key.clone(), page.fast.reversed());
        match waiting.get_mut(&wanted).and_then(VecDeque::pop_front) {
            Some(i) => {
                if let Some(slot) = partner.get_mut(i) {
                    *slot = Some(j);
                }
                if let Some(flag) = is_retrace.get_mut(j) {
                    *flag = true;
                }
            }
            None => waiting
                .entry((page.key.clone(), page.fast))
                .or_default()
                .push_back(j),
        }
    }

    let mut slots: Vec<Option<ImagePage>> = pages.into_iter().map(Some).collect();
    let mut pairs = Vec::new();
    for i in 0..slots.len() {
        if is_retrace.get(i).copied().unwrap_or(false) {
            continue;
        }
        let Some(first) = slots.get_mut(i).and_then(Option::take) else {
            continue;
        };
        let second = partner
            .get(i)
            .copied()
            .flatten()
            .and_then(|j| slots.get_mut(j).and_then(Option::take));
        let pair = match second {
            Some(retrace) => {
                let geometry = reconcile_timing(&first, &retrace, metadata)?;
                ScanPair::new(geometry, first.channel, Some(retrace.channel))
            }
            None if first.fast.is_increasing() => {
                ScanPair::new(first.geometry, first.channel, None)
            }
            None => retrace_only(first),
        };
        pairs.push(pair.map_err(|e| ReadError::geometry(FORMAT, e))?);
    }
    Ok(pairs)
}

/// The geometry of a trace/retrace pair whose pages may state different pixel periods.
/// Equal periods: the trace's geometry. Otherwise the usable one (the trace's when both
/// are usable, e.g. one ×10 the other), with the timing marked assumed and both values
/// noted in `metadata`, so the choice is reported (as a warning by
/// [`crate::assumption_warnings`]) rather than silent.
fn reconcile_timing(
    trace: &ImagePage,
    retrace: &ImagePage,
    metadata: &mut BTreeMap<String, String>,
) -> Result<ScanGeometry, ReadError> {
    let (a, b) = (trace.header.period, retrace.header.period);
    if a.to_bits() == b.to_bits() {
        return Ok(trace.geometry.clone());
    }
    let usable = |p: f32| plausible(f64::from(p), &PLAUSIBLE_PIXEL_PERIOD_S);
    let use_retrace = !usable(a) && usable(b);
    note(
        metadata,
        ASSUMED_TIMING_KEY,
        format!(
            "the trace page {} states {a} s per pixel but the retrace page {} states {b} s; \
             the {}'s is used",
            trace.number,
            retrace.number,
            if use_retrace { "retrace" } else { "trace" }
        ),
    );
    let geometry = if use_retrace {
        let overrides = GeometryOverrides {
            pixel_period: Some(f64::from(b)),
            ..GeometryOverrides::default()
        };
        overrides
            .apply(&trace.geometry)
            .map_err(|e| ReadError::geometry(FORMAT, e))?
    } else {
        trace.geometry.clone()
    };
    Ok(geometry.with_timing_source(ValueSource::Assumed))
}

/// A lone Left- or Up-running page: a retrace whose trace would have run the other way.
fn retrace_only(page: ImagePage) -> Result<ScanPair, dhct_scan::GeometryError> {
    let g = &page.geometry;
    let geometry = ScanGeometry::new(
        g.columns(),
        g.rows(),
        g.pitch_x(),
        g.pitch_y(),
        g.pixel_period(),
        page.fast.reversed(),
        g.slow_direction(),
    )?
    .with_scan_angle(g.scan_angle())?
    .with_offset(g.offset().0, g.offset().1)?
    .with_scale_source(g.scale_source())
    .with_timing_source(g.timing_source());
    ScanPair::retrace_only(geometry, page.channel)
}

/// File-level metadata from the first image page's header and strings.
pub(super) fn file_metadata(pages: &[ImagePage], signature: &str) -> BTreeMap<String, String> {
    let mut metadata = BTreeMap::new();
    let mut put = |key: &str, value: String| {
        if !value.trim().is_empty() {
            metadata.insert(key.to_string(), value);
        }
    };
    put("signature", signature.trim().to_string());
    let Some(first) = pages.first() else {
        return metadata;
    };
    let text = |k: usize| first.strings.get(k).map(|s| s.trim()).unwrap_or("");
    put("date", iso_date(text(string::DATE)));
    put("time", text(string::TIME).to_string());
    put("bias", format!("{} V", first.header.bias));
    put("current", format!("{:e} A", first.header.current));
    put("system text", text(string::SYSTEM_TEXT).to_string());
    put("session text", text(string::SESSION_TEXT).to_string());
    put("user text", text(string::USER_TEXT).to_string());
    put("path", text(string::PATH).to_string());
    let channels: Vec<String> = pages
        .iter()
        .map(|p| {
            let direction = format!("{:?}", p.fast).to_lowercase();
            format!("{} {} ({direction})", p.number, p.channel.name)
        })
        .collect();
    put("image pages", channels.join(", "));
    metadata
}

/// RHK's "MM/DD/YY" as ISO "YYYY-MM-DD" (years < 70 in the 2000s); anything else unchanged.
fn iso_date(date: &str) -> String {
    let parts: Vec<&str> = date.split('/').collect();
    if let [mm, dd, yy] = parts.as_slice()
        && let (Ok(m), Ok(d), Ok(y)) = (mm.parse::<u32>(), dd.parse::<u32>(), yy.parse::<u32>())
        && (1..=12).contains(&m)
        && (1..=31).contains(&d)
        && y < 100
    {
        let year = if y < 70 { 2000 + y } else { 1900 + y };
        return format!("{year:04}-{m:02}-{d:02}");
    }
    date.to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn page_dates_become_start_times() {
        assert_eq!(
            page_start_time("06/03/23", "12:00:00"),
            Some(1_685_793_600.0)
        );
        assert_eq!(page_start_time("12/31/99", "00:00:01"), Some(946_598_401.0));
        assert_eq!(page_start_time("", "12:00:00"), None);
        assert_eq!(page_start_time("06/03/23", "noon"), None);
    }

    #[test]
    fn dates_become_iso() {
        assert_eq!(iso_date("06/03/23"), "2023-06-03");
        assert_eq!(iso_date("12/31/99"), "1999-12-31");
        assert_eq!(iso_date("2023-06-03"), "2023-06-03");
        assert_eq!(iso_date("13/01/23"), "13/01/23");
    }

    #[test]
    fn utf16_strings_drop_trailing_nuls() {
        assert_eq!(decode_utf16(b"S\0T\0\0\0"), "ST");
        assert_eq!(decode_utf16(b"S\0T"), "S");
    }
}
