//! The SM4 writer: one image page per trace or retrace image.
//!
//! File layout written (all offsets absolute, little-endian):
//!
//! ```text
//! 0     u16 56, signature "STiMage 005.004 1" (36 bytes UTF-16LE), page count,
//!       object count 1, object field size 12, 2 reserved u32
//! 58    file object list: [page index header]
//! 70    page index header (page count, 1 object, 2 reserved) + list: [page index array]
//! 98    page index array: per page GUID, data type 0 (image), source 1 (processed),
//!       2 objects, minor version 4, list [page header, page data]
//! ...   per page: 180-byte page header + list [string data]; 17 strings; i32 data
//! ```

use std::io::Write;
use std::time::{SystemTime, UNIX_EPOCH};

use dhct_scan::clock::civil_from_days;
use dhct_scan::{FileFormat, ImageChannel, ScanFile, ScanGeometry, ScanPass};

use super::layout::{
    FILE_HEADER_SIZE, MINOR_VERSION_WRITTEN, MISSING_RAW, OBJECT_ENTRY_SIZE, PAGE_HEADER_SIZE,
    PAGE_INDEX_ENTRY_SIZE, PAGE_INDEX_HEADER_SIZE, SIGNATURE_BYTES, SIGNATURE_WRITTEN, data_type,
    object, page_type, scan_dir, source, string,
};
use super::orientation::{Orientation, scale_signs};
use crate::WriteError;

const FORMAT: FileFormat = FileFormat::RhkSm4;

/// Largest raw magnitude the quantiser aims for: 2^31 − 128, leaving headroom for the
/// rounding of the f32 scale and offset.
const RAW_LIMIT: f64 = 2_147_483_520.0;

/// The group id written to every page (RHK groups pages of one acquisition by it).
const GROUP_ID: u32 = 1;

fn unrepresentable(reason: impl Into<String>) -> WriteError {
    WriteError::Unrepresentable {
        format: FORMAT,
        reason: reason.into(),
    }
}

/// Little-endian appends.
trait Put {
    fn u16(&mut self, v: u16);
    fn u32(&mut self, v: u32);
    fn i32(&mut self, v: i32);
    fn f32(&mut self, v: f32);
}

impl Put for Vec<u8> {
    fn u16(&mut self, v: u16) {
        self.extend_from_slice(&v.to_le_bytes());
    }
    fn u32(&mut self, v: u32) {
        self.extend_from_slice(&v.to_le_bytes());
    }
    fn i32(&mut self, v: i32) {
        self.extend_from_slice(&v.to_le_bytes());
    }
    fn f32(&mut self, v: f32) {
        self.extend_from_slice(&v.to_le_bytes());
    }
}

/// One image to be written as a page.
struct PageOut<'a> {
    channel: &'a ImageChannel,
    geometry: &'a ScanGeometry,
    pass: ScanPass,
}

/// i32 samples with the affine map back to physical values: `value = raw·z_scale + z_offset`.
struct Quantized {
    z_scale: f32,
    z_offset: f32,
    /// Samples in file order (see [`Orientation`]).
    raw: Vec<i32>,
    min: i32,
    max: i32,
}

/// Writes `file` as SM4: per [`dhct_scan::ScanPair`] a trace page then a retrace page.
pub(crate) fn write<W: Write>(file: &ScanFile, w: &mut W) -> Result<(), WriteError> {
    let mut pages = Vec::new();
    for pair in &file.pairs {
        let geometry = pair.geometry();
        let both = pair.trace().is_some() && pair.retrace().is_some();
        if !both && !geometry.trace_fast().is_increasing() {
            return Err(unrepresentable(format!(
                "channel \"{}\" has a single image whose trace runs {:?}: SM4 marks a lone \
                 page as trace (forward) only by a Right or Down fast direction",
                pair.name(),
                geometry.trace_fast()
            )));
        }
        for (pass, channel) in pair.images() {
            pages.push(PageOut {
                channel,
                geometry,
                pass,
            });
        }
    }
    if pages.is_empty() {
        return Err(unrepresentable("the scan file holds no images"));
    }
    let page_count = u32::try_from(pages.len()).map_err(|_| unrepresentable("too many images"))?;

    let (date, time) = date_time(file);
    let mut encoded = Vec::with_capacity(pages.len());
    for (number, page) in pages.iter().enumerate() {
        encoded.push(encode_page(file, page, number, &date, &time)?);
    }

    // Offsets of everything, then the bytes in the same order.
    let object = u64::from(OBJECT_ENTRY_SIZE);
    let file_objects_at = 2 + u64::from(FILE_HEADER_SIZE);
    let index_header_at = file_objects_at + object;
    let array_at = index_header_at + u64::from(PAGE_INDEX_HEADER_SIZE) + object;
    let entry_len = u64::from(PAGE_INDEX_ENTRY_SIZE) + 2 * object;
    let mut position = array_at + entry_len * u64::from(page_count);
    let mut placed = Vec::with_capacity(encoded.len());
    for page in &encoded {
        let header_at = position;
        let strings_at = header_at + u64::from(PAGE_HEADER_SIZE) + object;
        let data_at = strings_at + page.strings.len() as u64;
        position = data_at + 4 * page.data.raw.len() as u64;
        placed.push((header_at, strings_at, data_at));
    }
    if position > u64::from(u32::MAX) {
        return Err(unrepresentable(format!(
            "the file would be {position} bytes; SM4 offsets are 32-bit"
        )));
    }
    let offset = |v: u64| v as u32; // every offset is ≤ position ≤ u32::MAX (checked above)

    let mut out = Vec::new();
    out.u16(FILE_HEADER_SIZE);
    let mut signature: Vec<u16> = SIGNATURE_WRITTEN.encode_utf16().collect();
    signature.resize(SIGNATURE_BYTES / 2, 0);
    for unit in signature {
        out.u16(unit);
    }
    out.u32(page_count);
    out.u32(1); // object count
    out.u32(OBJECT_ENTRY_SIZE);
    out.u32(0);
    out.u32(0);
    out.u32(object::PAGE_INDEX_HEADER);
    out.u32(offset(index_header_at));
    out.u32(PAGE_INDEX_HEADER_SIZE);
    out.u32(page_count);
    out.u32(1); // object count
    out.u32(0);
    out.u32(0);
    out.u32(object::PAGE_INDEX_ARRAY);
    out.u32(offset(array_at));
    out.u32(PAGE_INDEX_ENTRY_SIZE); // size of one entry's fixed part, as RHK writes it
    for (number, (page, &(header_at, _, data_at))) in encoded.iter().zip(&placed).enumerate() {
        out.extend_from_slice(&page_guid(number, &page.name));
        out.u32(data_type::IMAGE);
        out.u32(source::PROCESSED);
        out.u32(2); // object count
        out.u32(MINOR_VERSION_WRITTEN);
        out.u32(object::PAGE_HEADER);
        out.u32(offset(header_at));
        out.u32(PAGE_HEADER_SIZE);
        out.u32(object::PAGE_DATA);
        out.u32(offset(data_at));
        out.u32(offset(4 * page.data.raw.len() as u64));
    }
    w.write_all(&out)?;

    for (page, &(_, strings_at, _)) in encoded.iter().zip(&placed) {
        let mut header = page.header.clone();
        header.u32(object::STRING_DATA);
        header.u32(offset(strings_at));
        header.u32(offset(page.strings.len() as u64));
        w.write_all(&header)?;
        w.write_all(&page.strings)?;
        let mut buffer = Vec::with_capacity(1 << 16);
        for chunk in page.data.raw.chunks(1 << 14) {
            buffer.clear();
            for &v in chunk {
                buffer.i32(v);
            }
            w.write_all(&buffer)?;
        }
    }
    Ok(())
}

/// A page ready to be written.
struct EncodedPage {
    name: String,
    /// The 180-byte page header (its object list is appended once offsets are known).
    header: Vec<u8>,
    /// The string object: u16 count + UTF-16LE code units, [`string::KNOWN`] times.
    strings: Vec<u8>,
    data: Quantized,
}

fn encode_page(
    file: &ScanFile,
    page: &PageOut<'_>,
    number: usize,
    date: &str,
    time: &str,
) -> Result<EncodedPage, WriteError> {
    let g = page.geometry;
    let channel = page.channel;
    let fast = g.fast_direction(page.pass);
    let slow = g.slow_direction();
    let (x_sign, y_sign) = scale_signs(g.trace_fast(), slow);
    let x_scale = finite_f32("x pixel pitch", x_sign * g.pitch_x())?;
    let y_scale = finite_f32("y pixel pitch", y_sign * g.pitch_y())?;
    let period = finite_f32("pixel period", g.pixel_period())?;
    let angle = finite_f32("scan angle", g.scan_angle().to_degrees())?;
    let (offset_x, offset_y) = g.offset();
    let x_offset = finite_f32("x offset", offset_x)?;
    let y_offset = finite_f32("y offset", offset_y)?;
    if x_scale == 0.0 || y_scale == 0.0 || period == 0.0 {
        return Err(unrepresentable(
            "pixel pitch or period is too small for a 32-bit float",
        ));
    }
    let columns = u32::try_from(g.columns()).map_err(|_| unrepresentable("image too wide"))?;
    let rows = u32::try_from(g.rows()).map_err(|_| unrepresentable("image too tall"))?;
    let orientation = Orientation::from_scales(f64::from(x_scale), f64::from(y_scale));
    let data = quantize(channel, orientation)?;
    let data_size = u32::try_from(4 * data.raw.len() as u64)
        .map_err(|_| unrepresentable(format!("channel \"{}\" is too large", channel.name)))?;

    let kind = match channel.unit.as_str() {
        "m" => page_type::TOPOGRAPHIC,
        "A" => page_type::CURRENT,
        _ => page_type::AUX,
    };
    let metadata_number = |key: &str| {
        file.metadata
            .get(key)
            .and_then(|v| v.split_whitespace().next())
            .and_then(|v| v.parse::<f32>().ok())
            .filter(|v| v.is_finite())
            .unwrap_or(0.0)
    };

    let mut header = Vec::with_capacity(PAGE_HEADER_SIZE as usize + 12);
    header.u16(PAGE_HEADER_SIZE as u16);
    header.u16(string::KNOWN as u16);
    header.u32(kind);
    header.u32(0); // data sub-source
    header.u32(0); // line type: not a line (an image)
    header.i32(0); // x corner
    header.i32(0); // y corner
    header.u32(columns);
    header.u32(rows);
    header.u32(0); // image type: normal
    header.u32(scan_dir::encode(fast));
    header.u32(GROUP_ID);
    header.u32(data_size);
    header.i32(data.min);
    header.i32(data.max);
    header.f32(x_scale);
    header.f32(y_scale);
    header.f32(data.z_scale);
    header.f32(0.0); // xy scale
    header.f32(x_offset);
    header.f32(y_offset);
    header.f32(data.z_offset);
    header.f32(period);
    header.f32(metadata_number("bias"));
    header.f32(metadata_number("current"));
    header.f32(angle);
    header.u32(0); // colour info count
    header.u32(0); // grid x size
    header.u32(0); // grid y size
    header.u32(1); // object count: the string data
    header.resize(PAGE_HEADER_SIZE as usize, 0); // 32-bit data flag and reserved bytes

    let text = |key: &str| file.metadata.get(key).map(String::as_str).unwrap_or("");
    let completed = completed_lines(channel, g);
    let strings_list: [&str; string::KNOWN] = [
        &channel.name,
        text("system text"),
        text("session text"),
        text("user text"),
        text("path"),
        date,
        time,
        "m",
        "m",
        &channel.unit,
        "",
        "",
        "",
        &format!("{completed:04}"),
        "0",
        "",
        "",
    ];
    let mut strings = Vec::new();
    for s in strings_list {
        let units: Vec<u16> = s.encode_utf16().take(usize::from(u16::MAX)).collect();
        strings.u16(units.len() as u16);
        for unit in units {
            strings.u16(unit);
        }
    }
    Ok(EncodedPage {
        name: format!("{}/{number}", channel.name),
        header,
        strings,
        data,
    })
}

fn finite_f32(what: &str, value: f64) -> Result<f32, WriteError> {
    let v = value as f32;
    if v.is_finite() {
        Ok(v)
    } else {
        Err(unrepresentable(format!(
            "{what} {value} does not fit a 32-bit float"
        )))
    }
}

/// Picks `z_scale` and `z_offset` (both f32, as stored) so the finite values span nearly
/// the whole i32 range, and rounds every value with exactly those f32 numbers, so a reader
/// gets each value back within `z_scale / 2`. Non-finite values become [`MISSING_RAW`].
fn quantize(channel: &ImageChannel, orientation: Orientation) -> Result<Quantized, WriteError> {
    let (rows, columns) = (channel.rows(), channel.columns());
    let (lo, hi) = channel.finite_range().unwrap_or((0.0, 0.0));
    let z_offset = (lo / 2.0 + hi / 2.0) as f32;
    if !z_offset.is_finite() {
        return Err(unrepresentable(format!(
            "channel \"{}\" values exceed the 32-bit float range",
            channel.name
        )));
    }
    let offset = f64::from(z_offset);
    let half = (hi - offset).abs().max((lo - offset).abs());
    let tiny = f64::from(f32::MIN_POSITIVE);
    let scale = if half > 0.0 {
        (half / RAW_LIMIT).max(tiny)
    } else if offset != 0.0 {
        (offset.abs() * 2f64.powi(-40)).max(tiny)
    } else {
        1.0
    };
    let mut z_scale = scale as f32;
    if f64::from(z_scale) < scale {
        z_scale = z_scale.next_up();
    }
    if !z_scale.is_finite() {
        return Err(unrepresentable(format!(
            "channel \"{}\" spans more than a 32-bit float scale can express",
            channel.name
        )));
    }
    let step = f64::from(z_scale);
    let limit = f64::from(i32::MAX);
    let mut raw = Vec::with_capacity(rows * columns);
    let (mut min, mut max) = (i32::MAX, i32::MIN);
    for file_row in 0..rows {
        for file_column in 0..columns {
            let (row, column) = orientation.map(file_row, file_column, rows, columns);
            let value = channel.z.get((row, column)).copied().unwrap_or(f64::NAN);
            let sample = if value.is_finite() {
                let r = ((value - offset) / step).round().clamp(-limit, limit) as i32;
                min = min.min(r);
                max = max.max(r);
                r
            } else {
                MISSING_RAW
            };
            raw.push(sample);
        }
    }
    if min > max {
        (min, max) = (0, 0);
    }
    Ok(Quantized {
        z_scale,
        z_offset,
        raw,
        min,
        max,
    })
}

/// Lines acquired before a trailing run of all-NaN lines (an aborted scan), in the
/// direction of the slow scan; the full line count for a complete image.
fn completed_lines(channel: &ImageChannel, g: &ScanGeometry) -> usize {
    let lines = g.slow_len();
    let line_is_empty = |k: usize| -> bool {
        // Line k in acquisition order, as a display row or column.
        let along = if g.slow_direction().is_increasing() {
            k
        } else {
            lines - 1 - k
        };
        match g.slow_direction().axis() {
            dhct_scan::Axis::Vertical => channel.z.row(along).iter().all(|v| v.is_nan()),
            dhct_scan::Axis::Horizontal => channel.z.column(along).iter().all(|v| v.is_nan()),
        }
    };
    let mut completed = lines;
    while completed > 1 && line_is_empty(completed - 1) {
        completed -= 1;
    }
    completed
}

/// Date ("MM/DD/YY") and time ("HH:MM:SS") for the page strings: the first pair's start
/// time ([`ScanGeometry::start_time`]) when it has one, else from the metadata
/// ("date" as ISO "YYYY-MM-DD" or RHK's form, "time"), else the current UTC time.
fn date_time(file: &ScanFile) -> (String, String) {
    let start = file
        .pairs
        .first()
        .and_then(|p| p.geometry().start_time())
        .filter(|t| *t >= 0.0 && *t < 4e9);
    if let Some(start) = start {
        let start = start.round() as u64;
        let (year, month, day) = civil_from_days((start / 86_400) as i64);
        let seconds = start % 86_400;
        return (
            format!("{month:02}/{day:02}/{:02}", year.rem_euclid(100)),
            format!(
                "{:02}:{:02}:{:02}",
                seconds / 3600,
                seconds / 60 % 60,
                seconds % 60
            ),
        );
    }
    let now = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0);
    let (year, month, day) = civil_from_days((now / 86_400) as i64);
    let seconds = now % 86_400;
    let date = file
        .metadata
        .get("date")
        .and_then(|d| rhk_date(d))
        .unwrap_or_else(|| format!("{month:02}/{day:02}/{:02}", year.rem_euclid(100)));
    let time = file
        .metadata
        .get("time")
        .filter(|t| {
            let parts: Vec<&str> = t.split(':').collect();
            parts.len() == 3 && parts.iter().all(|p| p.parse::<u32>().is_ok())
        })
        .cloned()
        .unwrap_or_else(|| {
            format!(
                "{:02}:{:02}:{:02}",
                seconds / 3600,
                seconds / 60 % 60,
                seconds % 60
            )
        });
    (date, time)
}

/// "YYYY-MM-DD" or "MM/DD/YY" as "MM/DD/YY".
fn rhk_date(date: &str) -> Option<String> {
    let numbers = |parts: Vec<&str>| -> Option<Vec<u32>> {
        parts.iter().map(|p| p.trim().parse::<u32>().ok()).collect()
    };
    if let Some([y, m, d]) = numbers(date.split('-').collect()).as_deref() {
        return Some(format!("{m:02}/{d:02}/{:02}", y % 100));
    }
    if let Some([m, d, y]) = numbers(date.split('/').collect()).as_deref() {
        return Some(format!("{m:02}/{d:02}/{:02}", y % 100));
    }
    None
}

/// A stable, unique-per-page GUID (FNV-1a of the page number and name, shaped as a v4 GUID).
fn page_guid(number: usize, name: &str) -> [u8; 16] {
    let hash = |seed: u64| {
        let mut h = seed;
        for byte in (number as u64).to_le_bytes().iter().chain(name.as_bytes()) {
            h ^= u64::from(*byte);
            h = h.wrapping_mul(0x0000_0100_0000_01b3);
        }
        h
    };
    let mut guid = [0u8; 16];
    guid[..8].copy_from_slice(&hash(0xcbf2_9ce4_8422_2325).to_le_bytes());
    guid[8..].copy_from_slice(&hash(0x84222325_cbf29ce4).to_le_bytes());
    guid[7] = (guid[7] & 0x0f) | 0x40;
    guid[8] = (guid[8] & 0x3f) | 0x80;
    guid
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn civil_dates() {
        assert_eq!(civil_from_days(0), (1970, 1, 1));
        assert_eq!(civil_from_days(19_511), (2023, 6, 3));
        assert_eq!(civil_from_days(-1), (1969, 12, 31));
    }

    #[test]
    fn dates_become_rhk_form() {
        assert_eq!(rhk_date("2023-06-03").as_deref(), Some("06/03/23"));
        assert_eq!(rhk_date("06/03/23").as_deref(), Some("06/03/23"));
        assert_eq!(rhk_date("yesterday"), None);
    }

    #[test]
    fn guids_differ_per_page() {
        assert_ne!(page_guid(0, "a"), page_guid(1, "a"));
        assert_ne!(page_guid(0, "a"), page_guid(0, "b"));
    }
}
