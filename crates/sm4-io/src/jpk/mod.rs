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

use std::collections::BTreeMap;

use dhct_scan::{ImageChannel, ScanPair};

use crate::limits::{Budget, ReadLimits};
use crate::{ReadError, ScanFile};

mod channel;
mod directory;
mod geometry;

use channel::*;
use directory::*;
use geometry::*;

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
