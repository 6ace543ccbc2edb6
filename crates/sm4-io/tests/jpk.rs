//! JPK image reader: synthetic JPK TIFFs written by the small writer below (values, units,
//! orientation, pitch, timing, names, pairing, skipped pages), broken variants that must give
//! typed errors, and — when `DHCT_REAL_DATA` names a directory holding them — the two real
//! sample files (GPL/LGPL-licensed, so not in the repository) against Gwyddion 2.62's values.

use std::f64::consts::FRAC_PI_2;
use std::path::{Path, PathBuf};

use dhct_scan::{FileFormat, ImageChannel, ScanDirection, ScanFile, ScanPass, ValueSource};
use dhct_sm4_io::{
    ASSUMED_PIXEL_PERIOD, ASSUMED_TIMING_KEY, ReadError, ReadLimits, detect_format, jpk,
    read_bytes, read_bytes_limited, read_path,
};

// ---------------------------------------------------------------------------------------
// A minimal TIFF writer.

/// A tag value.
#[derive(Debug, Clone)]
enum Value {
    Ascii(String),
    Short(u16),
    SShort(i16),
    SLong(i32),
    Longs(Vec<u32>),
    Double(f64),
}

impl Value {
    /// TIFF type, count and the value's bytes.
    fn encode(&self, little: bool) -> (u16, u32, Vec<u8>) {
        let order = |be: Vec<u8>, width: usize| -> Vec<u8> {
            if little {
                be.chunks(width)
                    .flat_map(|c| c.iter().rev().copied())
                    .collect()
            } else {
                be
            }
        };
        match self {
            Value::Ascii(s) => {
                let mut b = s.as_bytes().to_vec();
                b.push(0);
                (2, b.len() as u32, b)
            }
            Value::Short(v) => (3, 1, order(v.to_be_bytes().to_vec(), 2)),
            Value::SShort(v) => (8, 1, order(v.to_be_bytes().to_vec(), 2)),
            Value::SLong(v) => (9, 1, order(v.to_be_bytes().to_vec(), 4)),
            Value::Longs(v) => (
                4,
                v.len() as u32,
                order(v.iter().flat_map(|x| x.to_be_bytes()).collect(), 4),
            ),
            Value::Double(v) => (12, 1, order(v.to_be_bytes().to_vec(), 8)),
        }
    }
}

fn ascii(s: &str) -> Value {
    Value::Ascii(s.to_string())
}

/// One page: its tags (StripOffsets and StripByteCounts are added by the writer) and strips.
#[derive(Debug, Clone)]
struct Page {
    tags: Vec<(u16, Value)>,
    strips: Vec<Vec<u8>>,
}

impl Page {
    fn set(&mut self, tag: u16, value: Value) {
        self.tags.retain(|(t, _)| *t != tag);
        self.tags.push((tag, value));
    }

    fn remove(&mut self, tag: u16) {
        self.tags.retain(|(t, _)| *t != tag);
    }
}

/// A classic TIFF of `pages`, little- or big-endian.
fn write_tiff(little: bool, pages: &[Page]) -> Vec<u8> {
    let u16b = |v: u16| {
        if little {
            v.to_le_bytes()
        } else {
            v.to_be_bytes()
        }
    };
    let u32b = |v: u32| {
        if little {
            v.to_le_bytes()
        } else {
            v.to_be_bytes()
        }
    };
    let mut out: Vec<u8> = if little {
        b"II*\0".to_vec()
    } else {
        b"MM\0*".to_vec()
    };
    out.extend([0; 4]);
    let mut link_at = 4;
    for page in pages {
        let (mut offsets, mut counts) = (Vec::new(), Vec::new());
        for strip in &page.strips {
            offsets.push(out.len() as u32);
            counts.push(strip.len() as u32);
            out.extend(strip);
        }
        let mut tags = page.tags.clone();
        if !page.strips.is_empty() {
            tags.push((273, Value::Longs(offsets)));
            tags.push((279, Value::Longs(counts)));
        }
        tags.sort_by_key(|(t, _)| *t);
        if out.len() % 2 == 1 {
            out.push(0);
        }
        let ifd = out.len();
        out[link_at..link_at + 4].copy_from_slice(&u32b(ifd as u32));
        let mut extra = Vec::new();
        let extra_start = ifd + 2 + 12 * tags.len() + 4;
        out.extend(u16b(tags.len() as u16));
        for (tag, value) in &tags {
            let (kind, count, mut bytes) = value.encode(little);
            out.extend(u16b(*tag));
            out.extend(u16b(kind));
            out.extend(u32b(count));
            if bytes.len() <= 4 {
                bytes.resize(4, 0);
                out.extend(bytes);
            } else {
                out.extend(u32b((extra_start + extra.len()) as u32));
                extra.extend(bytes);
                if extra.len() % 2 == 1 {
                    extra.push(0);
                }
            }
        }
        link_at = out.len();
        out.extend([0; 4]);
        out.extend(extra);
    }
    out
}

// ---------------------------------------------------------------------------------------
// The synthetic JPK file.

const COLUMNS: usize = 6;
const ROWS: usize = 4;
const U_LENGTH: f64 = 1.2e-7;
const V_LENGTH: f64 = -0.8e-7; // negative: the pitch is its magnitude
const X0: f64 = 2.0e-6;
const Y0: f64 = -1.0e-6;
const THETA: f64 = 0.1;
const FREQUENCY: f64 = 2.0;
const DUTY: f64 = 0.8;
/// The height slots' calibration ("calibrated": metres).
const HEIGHT_MULTIPLY: f64 = -2.0e-9;
const HEIGHT_OFFSET: f64 = 1.0e-6;
/// The error signal's ("volts").
const VOLTS_MULTIPLY: f64 = 1.0e-3;
const VOLTS_OFFSET: f64 = 5.0;

/// Raw value of stored row `row`, column `col` of the height trace; the retrace adds 1000.
fn height_raw(row: usize, col: usize) -> i32 {
    100 * row as i32 + col as i32 - 150
}

fn error_raw(row: usize, col: usize) -> u16 {
    60000 + 10 * row as u16 + col as u16
}

fn measured_raw(row: usize, col: usize) -> f32 {
    0.25 * (10 * row + col) as f32
}

/// Slot `n`'s tags.
fn slot(n: u16, name: &str, unit: Option<&str>, scaling: Option<(f64, f64)>) -> Vec<(u16, Value)> {
    let base = 0x8090 + 0x30 * n;
    let mut tags = vec![(base, ascii(name)), (base + 0x11, ascii("SignedInteger"))];
    if let Some(unit) = unit {
        tags.push((base + 0x12, ascii(unit)));
    }
    match scaling {
        None => tags.push((base + 0x13, ascii("NullScaling"))),
        Some((multiply, offset)) => {
            tags.push((base + 0x13, ascii("LinearScaling")));
            tags.push((base + 0x14, Value::Double(multiply)));
            tags.push((base + 0x15, Value::Double(offset)));
        }
    }
    tags
}

/// Standard tags of a grey page and its strips of `rows_per_strip` rows of `sample`s.
fn grey_page<T>(
    bits: u16,
    sample_format: Option<u16>,
    rows_per_strip: usize,
    value: impl Fn(usize, usize) -> T,
    bytes: impl Fn(T) -> Vec<u8>,
) -> Page {
    let mut tags = vec![
        (256, Value::Short(COLUMNS as u16)),
        (257, Value::Short(ROWS as u16)),
        (258, Value::Short(bits)),
        (259, Value::Short(1)),
        (262, Value::Short(1)),
        (277, Value::Short(1)),
        (278, Value::Short(rows_per_strip as u16)),
    ];
    if let Some(format) = sample_format {
        tags.push((339, Value::Short(format)));
    }
    let strips = (0..ROWS)
        .step_by(rows_per_strip)
        .map(|first| {
            (first..(first + rows_per_strip).min(ROWS))
                .flat_map(|row| (0..COLUMNS).map(move |col| (row, col)))
                .flat_map(|(row, col)| bytes(value(row, col)))
                .collect()
        })
        .collect();
    Page { tags, strips }
}

/// The channel tags: internal name, retrace flag, display name and calibration slots.
fn channel_tags(
    page: &mut Page,
    key: &str,
    retrace: bool,
    fancy: &str,
    default: &str,
    slots: Vec<Vec<(u16, Value)>>,
) {
    page.tags.push((0x8050, ascii(key)));
    page.tags.push((0x8051, Value::SShort(i16::from(retrace))));
    page.tags.push((0x8052, ascii(fancy)));
    page.tags.push((0x8080, Value::SLong(slots.len() as i32)));
    page.tags.push((0x8081, ascii(default)));
    page.tags.extend(slots.into_iter().flatten());
}

/// Page 0 (thumbnail and settings), height retrace and trace (int32), an error signal trace
/// (uint16, no SampleFormat), a phase page whose default slot is missing (skipped), and a
/// measured height trace (float32, "nominal" slot with NullScaling).
fn synthetic_pages(little: bool) -> Vec<Page> {
    let mut thumbnail = Page {
        tags: vec![
            (256, Value::Short(2)),
            (257, Value::Short(2)),
            (258, Value::Short(8)),
            (259, Value::Short(1)),
            (262, Value::Short(3)),
            (278, Value::Short(2)),
            (0x8000, ascii("6.1.0")),
            (0x8003, ascii("2024-01-02 03:04:05.678 UTC")),
            (0x8004, ascii("Synthetic")),
            (0x8005, ascii("<empty>")),
            (0x8006, ascii("2024-01-02 03:04:07.678 UTC")),
            (0x8030, ascii("contact")),
            (0x8033, Value::Double(0.75)),
            (0x8040, Value::Double(X0)),
            (0x8041, Value::Double(Y0)),
            (0x8042, Value::Double(U_LENGTH)),
            (0x8043, Value::Double(V_LENGTH)),
            (0x8044, Value::Double(THETA)),
            (0x8045, Value::SShort(0)),
            (0x8049, Value::Double(FREQUENCY)),
            (0x804A, Value::Double(DUTY)),
            (0x804B, ascii("bottomUp")),
            (0x8050, ascii("thumbnail")),
        ],
        strips: vec![vec![0, 1, 2, 3]],
    };
    // The thumbnail has its own slots, which must not matter.
    thumbnail.tags.push((0x8081, ascii("volts")));
    let order = move |b: [u8; 4]| -> Vec<u8> {
        if little {
            b.iter().rev().copied().collect()
        } else {
            b.to_vec()
        }
    };
    let height_slots = || {
        vec![
            slot(0, "raw", None, None),
            slot(1, "volts", Some("V"), Some((VOLTS_MULTIPLY, VOLTS_OFFSET))),
            slot(
                2,
                "calibrated",
                Some("m"),
                Some((HEIGHT_MULTIPLY, HEIGHT_OFFSET)),
            ),
        ]
    };
    let mut retrace = grey_page(
        32,
        Some(2),
        3,
        |r, c| height_raw(r, c) + 1000,
        |v: i32| order(v.to_be_bytes()),
    );
    channel_tags(
        &mut retrace,
        "height",
        true,
        "Height",
        "calibrated",
        height_slots(),
    );
    let mut trace = grey_page(32, Some(2), 3, height_raw, |v: i32| order(v.to_be_bytes()));
    channel_tags(
        &mut trace,
        "height",
        false,
        "Height",
        "calibrated",
        height_slots(),
    );
    let mut error = grey_page(16, None, 1, error_raw, |v: u16| {
        if little {
            v.to_le_bytes().to_vec()
        } else {
            v.to_be_bytes().to_vec()
        }
    });
    channel_tags(
        &mut error,
        "error",
        false,
        "Error Signal",
        "volts",
        vec![
            slot(0, "raw", None, None),
            slot(1, "volts", Some("V"), Some((VOLTS_MULTIPLY, VOLTS_OFFSET))),
        ],
    );
    let mut phase = grey_page(32, Some(2), 4, |_, _| 7i32, |v: i32| order(v.to_be_bytes()));
    channel_tags(
        &mut phase,
        "phase",
        false,
        "Lock-In Phase",
        "degrees",
        vec![slot(0, "raw", None, None)],
    );
    let mut measured = grey_page(32, Some(3), 2, measured_raw, |v: f32| {
        order(v.to_be_bytes())
    });
    channel_tags(
        &mut measured,
        "measuredHeight",
        false,
        "Height (measured)",
        "nominal",
        vec![
            slot(0, "raw", None, None),
            slot(1, "nominal", Some("m"), None),
        ],
    );
    vec![thumbnail, retrace, trace, error, phase, measured]
}

fn synthetic(little: bool) -> Vec<u8> {
    write_tiff(little, &synthetic_pages(little))
}

/// Display row `r` shows stored row `ROWS - 1 - r` (the first stored row is the bottom).
fn stored(display_row: usize) -> usize {
    ROWS - 1 - display_row
}

fn assert_close(what: &str, got: f64, want: f64, relative: f64) {
    let scale = want.abs().max(f64::MIN_POSITIVE);
    assert!(
        (got - want).abs() <= relative * scale,
        "{what}: got {got:e}, want {want:e}"
    );
}

#[test]
fn the_synthetic_file_reads_with_values_units_orientation_and_pairing() {
    for little in [false, true] {
        let bytes = synthetic(little);
        assert_eq!(detect_format(&bytes), Some(FileFormat::Jpk));
        assert!(jpk::looks_like_jpk(&bytes));
        let file = read_bytes(&bytes).unwrap();
        assert_eq!(file.format, FileFormat::Jpk);
        let names: Vec<&str> = file.pairs.iter().map(|p| p.name()).collect();
        // The measured height is moved first: it is the topography.
        assert_eq!(names, ["Height (measured)", "Height", "Error Signal"]);
        assert_eq!(file.topography().unwrap().name(), "Height (measured)");
        assert_eq!(file.channel("height").unwrap().name(), "Height");

        let height = &file.pairs[1];
        let (trace, retrace) = (height.trace().unwrap(), height.retrace().unwrap());
        for image in [trace, retrace] {
            assert_eq!(image.name, "Height");
            assert_eq!(image.unit, "m");
            assert_eq!((image.columns(), image.rows()), (COLUMNS, ROWS));
        }
        for r in 0..ROWS {
            for c in 0..COLUMNS {
                let z = |raw: i32| f64::from(raw) * HEIGHT_MULTIPLY + HEIGHT_OFFSET;
                assert_eq!(
                    trace.z[[r, c]],
                    z(height_raw(stored(r), c)),
                    "trace {r} {c}"
                );
                assert_eq!(
                    retrace.z[[r, c]],
                    z(height_raw(stored(r), c) + 1000),
                    "retrace {r} {c}"
                );
            }
        }

        let error = file.pairs[2].trace().unwrap();
        assert!(file.pairs[2].retrace().is_none());
        assert_eq!(error.unit, "V");
        assert_eq!(
            error.z[[0, 5]],
            f64::from(error_raw(3, 5)) * VOLTS_MULTIPLY + VOLTS_OFFSET
        );
        let measured = file.pairs[0].trace().unwrap();
        assert!(file.pairs[0].retrace().is_none());
        assert_eq!(measured.unit, "m");
        assert_eq!(measured.z[[3, 2]], f64::from(measured_raw(0, 2)));
        assert_eq!(measured.z[[0, 0]], f64::from(measured_raw(3, 0)));

        // The page with an unresolvable default slot is skipped, with the reason.
        let skipped = &file.metadata["skipped pages"];
        assert!(
            skipped.contains("page 4") && skipped.contains("\"degrees\""),
            "{skipped}"
        );
        assert!(file.metadata["jpk pages"].contains("page 1"));

        for pair in &file.pairs {
            let g = pair.geometry();
            assert_eq!((g.columns(), g.rows()), (COLUMNS, ROWS));
            assert_close("pitch x", g.pitch_x(), U_LENGTH / COLUMNS as f64, 1e-15);
            assert_close("pitch y", g.pitch_y(), -V_LENGTH / ROWS as f64, 1e-15);
            assert_eq!(g.scale_source(), ValueSource::Stated);
            assert_eq!(g.timing_source(), ValueSource::Stated);
            assert_eq!(g.fast_direction(ScanPass::Trace), ScanDirection::Right);
            assert_eq!(g.fast_direction(ScanPass::Retrace), ScanDirection::Left);
            assert_eq!(g.slow_direction(), ScanDirection::Up);
            let pass = DUTY / (2.0 * FREQUENCY);
            assert_close(
                "pixel period",
                g.pixel_period(),
                pass / COLUMNS as f64,
                1e-12,
            );
            assert_close(
                "turnaround",
                g.turnaround_time(),
                (1.0 - DUTY) / (2.0 * FREQUENCY),
                1e-12,
            );
            assert_close("line pair", 2.0 * g.line_period(), 1.0 / FREQUENCY, 1e-12);
            assert_eq!(g.scan_angle(), THETA);
            let (sin, cos) = THETA.sin_cos();
            let centre = (
                X0 + 0.5 * (U_LENGTH * cos - V_LENGTH * sin),
                Y0 + 0.5 * (U_LENGTH * sin + V_LENGTH * cos),
            );
            assert_close("offset x", g.offset().0, centre.0, 1e-12);
            assert_close("offset y", g.offset().1, centre.1, 1e-12);
        }
        let m = &file.metadata;
        assert_eq!(m["name"], "Synthetic");
        assert_eq!(m["date"], "2024-01-02 03:04:05.678 UTC");
        assert_eq!(m["end date"], "2024-01-02 03:04:07.678 UTC");
        assert_eq!(m["software version"], "6.1.0");
        assert_eq!(m["feedback mode"], "contact");
        assert_eq!(m["setpoint"], "0.75");
        assert!(m["scan rate"].starts_with("2 Hz"), "{}", m["scan rate"]);
        assert!(!m.contains_key("comment"), "<empty> is no comment");
        assert!(!m.contains_key(ASSUMED_TIMING_KEY));
    }
}

fn read_pages(pages: &[Page]) -> Result<ScanFile, ReadError> {
    jpk::read(&write_tiff(false, pages))
}

#[test]
fn motion_reflection_and_missing_timing_set_the_slow_direction_and_sources() {
    // topDown: the first stored row (display bottom) is acquired last.
    let mut pages = synthetic_pages(false);
    pages[0].set(0x804B, ascii("topDown"));
    let file = read_pages(&pages).unwrap();
    assert_eq!(
        file.pairs[0].geometry().slow_direction(),
        ScanDirection::Down
    );
    assert_eq!(
        file.pairs[0].geometry().timing_source(),
        ValueSource::Stated
    );

    // No Motion: as stored (bottom first, so up), assumed and noted.
    pages[0].remove(0x804B);
    let file = read_pages(&pages).unwrap();
    let g = file.pairs[0].geometry();
    assert_eq!(g.slow_direction(), ScanDirection::Up);
    assert_eq!(g.timing_source(), ValueSource::Assumed);
    assert!(file.metadata[ASSUMED_TIMING_KEY].contains("Motion"));

    // No line rate (as in QI images): the placeholder timing, assumed and noted.
    let mut pages = synthetic_pages(false);
    pages[0].remove(0x8049);
    pages[0].remove(0x804A);
    let file = read_pages(&pages).unwrap();
    let g = file.pairs[0].geometry();
    assert_eq!(g.timing_source(), ValueSource::Assumed);
    assert_eq!(g.pixel_period(), ASSUMED_PIXEL_PERIOD);
    assert_eq!(g.turnaround_time(), 0.0);
    assert!(file.metadata[ASSUMED_TIMING_KEY].contains("0x8049"));
    assert_eq!(g.scale_source(), ValueSource::Stated);

    // Grid_Reflect in the channel page: rows as stored, first stored row on top.
    let mut pages = synthetic_pages(false);
    pages[2].set(0x8045, Value::SShort(1));
    let file = read_pages(&pages).unwrap();
    let height = file.channel("Height").unwrap();
    // The reflected trace no longer pairs with the unreflected retrace.
    assert!(height.trace().is_none() || height.retrace().is_none());
    let trace = file
        .pairs
        .iter()
        .find_map(|p| p.trace().filter(|t| t.name.starts_with("Height (page")))
        .unwrap_or_else(|| {
            panic!(
                "{:?}",
                file.pairs.iter().map(|p| p.name()).collect::<Vec<_>>()
            )
        });
    assert_eq!(
        trace.z[[0, 0]],
        f64::from(height_raw(0, 0)) * HEIGHT_MULTIPLY + HEIGHT_OFFSET
    );
    // Reflected in page 0: every channel keeps its stored order; bottomUp now runs down.
    let mut pages = synthetic_pages(false);
    pages[0].set(0x8045, Value::SShort(1));
    let file = read_pages(&pages).unwrap();
    let g = file.pairs[0].geometry();
    assert_eq!(g.slow_direction(), ScanDirection::Down);
    assert_eq!(g.timing_source(), ValueSource::Assumed);
    let height = file.channel("Height").unwrap().trace().unwrap();
    assert_eq!(
        height.z[[0, 0]],
        f64::from(height_raw(0, 0)) * HEIGHT_MULTIPLY + HEIGHT_OFFSET
    );

    // No grid lengths: the placeholder pitch, assumed.
    let mut pages = synthetic_pages(false);
    pages[0].remove(0x8042);
    let file = read_pages(&pages).unwrap();
    assert_eq!(
        file.pairs[0].geometry().scale_source(),
        ValueSource::Assumed
    );
}

#[test]
fn duplicate_channels_stay_separate_pairs_with_distinct_names() {
    let mut pages = synthetic_pages(false);
    // A second trace of the measured height, and a second height trace.
    let extra_measured = pages[5].clone();
    let extra_height = pages[2].clone();
    pages.push(extra_measured);
    pages.push(extra_height);
    let file = read_pages(&pages).unwrap();
    let names: Vec<&str> = file.pairs.iter().map(|p| p.name()).collect();
    assert_eq!(
        names,
        [
            "Height (measured) (page 5)",
            "Height (page 1)",
            "Error Signal",
            "Height (measured) (page 6)",
            "Height (page 7)"
        ]
    );
    // The first height pair holds pages 1 (retrace) and 2 (trace); page 7 stands alone.
    assert!(file.pairs[1].trace().is_some() && file.pairs[1].retrace().is_some());
    assert!(file.pairs[4].trace().is_some() && file.pairs[4].retrace().is_none());
    assert_eq!(
        file.topography().unwrap().name(),
        "Height (measured) (page 5)"
    );
}

#[test]
fn a_retrace_alone_is_a_retrace_only_pair_and_height_is_the_topography_without_a_measured_one() {
    let mut pages = synthetic_pages(false);
    pages.truncate(2); // thumbnail + height retrace
    let file = read_pages(&pages).unwrap();
    assert_eq!(file.pairs.len(), 1);
    assert!(file.pairs[0].trace().is_none());
    assert_eq!(file.topography().unwrap().name(), "Height");
    assert_eq!(file.pairs[0].retrace().unwrap().name, "Height");
}

#[test]
fn broken_files_give_typed_errors() {
    let pages = synthetic_pages(false);
    let bytes = write_tiff(false, &pages);
    // Cut anywhere: an error (or, cut in the thumbnail's pixels only, still a file).
    for cut in 0..bytes.len() {
        match jpk::read(&bytes[..cut]) {
            Ok(file) => assert!(!file.pairs.is_empty()),
            Err(
                ReadError::Truncated { .. }
                | ReadError::WrongFormat { .. }
                | ReadError::Corrupt { .. }
                | ReadError::NoImage { .. },
            ) => {}
            Err(other) => panic!("cut at {cut}: {other}"),
        }
        let _ = read_bytes(&bytes[..cut]);
    }
    // A cut inside the last page's strips is reported as truncated.
    let last_strip = bytes.len() - 400;
    let error = jpk::read(&bytes[..last_strip]).unwrap_err();
    assert!(matches!(error, ReadError::Truncated { .. }), "{error}");

    // Every single byte flipped, and every 4-byte word set to hostile numbers: no panic.
    for at in 0..bytes.len() {
        let mut mutant = bytes.clone();
        mutant[at] ^= 0xFF;
        let _ = read_bytes(&mutant);
    }
    for at in (0..bytes.len().saturating_sub(4)).step_by(2) {
        for word in [0u32, 1, 0x7FFF_FFFF, 0xFFFF_FFFF, 0x0001_0000] {
            let mut mutant = bytes.clone();
            mutant[at..at + 4].copy_from_slice(&word.to_be_bytes());
            let _ = read_bytes_limited(
                &mutant,
                &ReadLimits {
                    max_bytes: 64 << 20,
                    max_pixels: 1 << 20,
                },
            );
        }
    }

    // Not a TIFF; BigTIFF; a TIFF without JPK tags.
    assert!(matches!(
        jpk::read(b"GIF89a"),
        Err(ReadError::WrongFormat { .. })
    ));
    assert!(matches!(
        jpk::read(b"MM\0+\0\x08\0\0\0\0\0\0\0\0\0\x10"),
        Err(ReadError::Unsupported { .. })
    ));
    let mut plain = pages.clone();
    plain[0].tags.retain(|(t, _)| *t < 0x8000);
    let plain = write_tiff(false, &plain);
    assert!(!jpk::looks_like_jpk(&plain));
    assert_eq!(detect_format(&plain), Some(FileFormat::Tiff));
    let error = jpk::read(&plain).unwrap_err();
    assert!(matches!(error, ReadError::WrongFormat { .. }), "{error}");

    // Too few strip offsets; a strip byte count too small; RowsPerStrip 0; zero width.
    let mut broken = pages.clone();
    broken[1].strips.pop();
    let error = read_pages(&broken).unwrap_err();
    assert!(error.to_string().contains("StripOffsets"), "{error}");
    let mut broken = pages.clone();
    broken[1].strips[0].truncate(8);
    let error = read_pages(&broken).unwrap_err();
    assert!(
        error.to_string().contains("strip 0 holds 8 bytes"),
        "{error}"
    );
    let mut broken = pages.clone();
    broken[1].set(278, Value::Short(0));
    let error = read_pages(&broken).unwrap_err();
    assert!(error.to_string().contains("RowsPerStrip"), "{error}");
    let mut broken = pages.clone();
    broken[2].set(256, Value::Short(0));
    let error = read_pages(&broken).unwrap_err();
    assert!(error.to_string().contains("ImageWidth"), "{error}");

    // A non-finite multiplier: that channel is skipped, naming why.
    let mut broken = pages.clone();
    broken[3].set(0x80D4, Value::Double(f64::NAN)); // slot 1's multiplier
    let file = read_pages(&broken).unwrap();
    assert!(file.metadata["skipped pages"].contains("page 3"));
    assert!(file.channel("Error Signal").is_err());

    // No readable channel at all: no image, listing the reasons.
    let mut broken = pages.clone();
    for page in &mut broken[1..] {
        page.remove(0x8081);
    }
    let error = read_pages(&broken).unwrap_err();
    assert!(
        matches!(&error, ReadError::NoImage { reason, .. } if reason.contains("DefaultSlot")),
        "{error}"
    );

    // A page that claims a huge image is refused by the budget before allocating.
    let mut broken = pages.clone();
    broken[1].set(256, Value::Longs(vec![60_000]));
    broken[1].set(257, Value::Longs(vec![60_000]));
    let error = read_pages(&broken).unwrap_err();
    assert!(matches!(error, ReadError::OverBudget { .. }), "{error}");
}

// ---------------------------------------------------------------------------------------
// The real sample files, against Gwyddion 2.62 (from the research pack's reference.json).

/// One channel as Gwyddion 2.62 shows it.
struct Reference {
    /// The pair dhct names it, and which pass.
    name: &'static str,
    retrace: bool,
    xres: usize,
    yres: usize,
    xreal: f64,
    yreal: f64,
    unit: &'static str,
    min: f64,
    max: f64,
    mean: f64,
    /// Top-left, top-right, bottom-left, bottom-right in display orientation.
    corners: [f64; 4],
}

const SAMPLE_JPK: [Reference; 10] = [
    Reference {
        name: "Height",
        retrace: true,
        xres: 256,
        yres: 256,
        xreal: 3.2691651420070083e-07,
        yreal: 3.2691651420070083e-07,
        unit: "m",
        min: 3.3031139584270314e-06,
        max: 3.3597597155885194e-06,
        mean: 3.3453817636755115e-06,
        corners: [
            3.3031139584270314e-06,
            3.35308837831997e-06,
            3.3351830024704627e-06,
            3.3148224556405346e-06,
        ],
    },
    Reference {
        name: "Height (measured)",
        retrace: true,
        xres: 256,
        yres: 256,
        xreal: 3.2691651420070083e-07,
        yreal: 3.2691651420070083e-07,
        unit: "m",
        min: 3.78336827547752e-06,
        max: 3.833185340043501e-06,
        mean: 3.820060048462527e-06,
        corners: [
            3.78336827547752e-06,
            3.8278230290109805e-06,
            3.8097428279048605e-06,
            3.7908305700237804e-06,
        ],
    },
    Reference {
        name: "Lock-In Amplitude",
        retrace: true,
        xres: 256,
        yres: 256,
        xreal: 3.2691651420070083e-07,
        yreal: 3.2691651420070083e-07,
        unit: "m",
        min: 2.5376585416538728e-08,
        max: 2.6021679589417902e-08,
        mean: 2.5806028353464842e-08,
        corners: [
            2.587058790463212e-08,
            2.5853693248493446e-08,
            2.5513414966699308e-08,
            2.5423484008077324e-08,
        ],
    },
    Reference {
        name: "Lock-In Phase",
        retrace: true,
        xres: 256,
        yres: 256,
        xreal: 3.2691651420070083e-07,
        yreal: 3.2691651420070083e-07,
        unit: "deg",
        min: -9.653096855747206,
        max: -8.196206726891203,
        mean: -9.003915087025252,
        corners: [
            -9.395448139710869,
            -9.049769491052173,
            -8.940276649458403,
            -9.021352168845217,
        ],
    },
    Reference {
        name: "Error Signal",
        retrace: true,
        xres: 256,
        yres: 256,
        xreal: 3.2691651420070083e-07,
        yreal: 3.2691651420070083e-07,
        unit: "V",
        min: -0.010302428774447947,
        max: 0.008429020498996017,
        mean: -0.0003059742401749773,
        corners: [
            -0.00014680611962842625,
            0.0009886840379987295,
            -0.001601616307962173,
            0.004443016984392312,
        ],
    },
    Reference {
        name: "Height",
        retrace: false,
        xres: 256,
        yres: 256,
        xreal: 3.2691651420070083e-07,
        yreal: 3.2691651420070083e-07,
        unit: "m",
        min: 3.302591820187238e-06,
        max: 3.3609500421237925e-06,
        mean: 3.345370526514958e-06,
        corners: [
            3.3043276327342405e-06,
            3.353646705779923e-06,
            3.3344851510316033e-06,
            3.314873932574702e-06,
        ],
    },
    Reference {
        name: "Height (measured)",
        retrace: false,
        xres: 256,
        yres: 256,
        xreal: 3.2691651420070083e-07,
        yreal: 3.2691651420070083e-07,
        unit: "m",
        min: 3.7823466722985203e-06,
        max: 3.83423452741214e-06,
        mean: 3.819892564782179e-06,
        corners: [
            3.78396539063552e-06,
            3.82827288388178e-06,
            3.8090253437306002e-06,
            3.7912406091835402e-06,
        ],
    },
    Reference {
        name: "Lock-In Amplitude",
        retrace: false,
        xres: 256,
        yres: 256,
        xreal: 3.2691651420070083e-07,
        yreal: 3.2691651420070083e-07,
        unit: "m",
        min: 2.5393610206182408e-08,
        max: 2.6037007823737045e-08,
        mean: 2.5797276680637538e-08,
        corners: [
            2.5873097133589474e-08,
            2.583733949374536e-08,
            2.545490837322843e-08,
            2.5535556008731595e-08,
        ],
    },
    Reference {
        name: "Lock-In Phase",
        retrace: false,
        xres: 256,
        yres: 256,
        xreal: 3.2691651420070083e-07,
        yreal: 3.2691651420070083e-07,
        unit: "deg",
        min: -9.64865947394252,
        max: -8.230643580191055,
        mean: -9.014103464650098,
        corners: [
            -9.391751299822598,
            -9.22866697973191,
            -8.899619094650255,
            -8.899038848735922,
        ],
    },
    Reference {
        name: "Error Signal",
        retrace: false,
        xres: 256,
        yres: 256,
        xreal: 3.2691651420070083e-07,
        yreal: 3.2691651420070083e-07,
        unit: "V",
        min: -0.011332725993565726,
        max: 0.014514232390618524,
        mean: 0.0003217530912714991,
        corners: [
            -0.00031554746456295067,
            0.002087984731483428,
            0.00233082930778791,
            -0.003089815274215398,
        ],
    },
];

const SAMPLE_QI: [Reference; 6] = [
    Reference {
        name: "Height (measured) (page 1)",
        retrace: false,
        xres: 100,
        yres: 100,
        xreal: 4.999999999999986e-07,
        yreal: 4.999999999999986e-07,
        unit: "m",
        min: 3.142853802500212e-06,
        max: 3.6425877083098078e-06,
        mean: 3.215738256351236e-06,
        corners: [
            3.27262913131802e-06,
            3.2691528050053217e-06,
            3.2006906598050517e-06,
            3.1974614023041503e-06,
        ],
    },
    Reference {
        name: "Vertical Deflection",
        retrace: false,
        xres: 100,
        yres: 100,
        xreal: 4.999999999999986e-07,
        yreal: 4.999999999999986e-07,
        unit: "N",
        min: -1.5322723852006237e-09,
        max: -1.2998252391692565e-09,
        mean: -1.3615033224242346e-09,
        corners: [
            -1.4013546820335833e-09,
            -1.4128551711175671e-09,
            -1.3208687302154575e-09,
            -1.3361075014637868e-09,
        ],
    },
    Reference {
        name: "Height (measured) (page 3)",
        retrace: false,
        xres: 100,
        yres: 100,
        xreal: 4.999999999999986e-07,
        yreal: 4.999999999999986e-07,
        unit: "m",
        min: 3.1453153196092373e-06,
        max: 3.6434291135949836e-06,
        mean: 3.2181137138706184e-06,
        corners: [
            3.274661825629677e-06,
            3.2715451280109468e-06,
            3.203264527151721e-06,
            3.1996459710191394e-06,
        ],
    },
    Reference {
        name: "Adhesion",
        retrace: false,
        xres: 100,
        yres: 100,
        xreal: 4.999999999999986e-07,
        yreal: 4.999999999999986e-07,
        unit: "N",
        min: 7.432009460606388e-11,
        max: 7.892689489076963e-10,
        mean: 1.579363986493833e-10,
        corners: [
            2.44995217714045e-10,
            1.3032105020888657e-10,
            2.0285105587743638e-10,
            2.151746034334915e-10,
        ],
    },
    Reference {
        name: "Height",
        retrace: false,
        xres: 100,
        yres: 100,
        xreal: 4.999999999999986e-07,
        yreal: 4.999999999999986e-07,
        unit: "m",
        min: 3.078761212388776e-06,
        max: 3.6155921908621487e-06,
        mean: 3.159314616051172e-06,
        corners: [
            3.2071450753861398e-06,
            3.209201082570337e-06,
            3.1086179074301462e-06,
            3.1245204741063084e-06,
        ],
    },
    Reference {
        name: "Slope",
        retrace: false,
        xres: 100,
        yres: 100,
        xreal: 4.999999999999986e-07,
        yreal: 4.999999999999986e-07,
        unit: "N/m",
        min: 0.006158542296409469,
        max: 0.11379206989879155,
        mean: 0.0626381032694023,
        corners: [
            0.05563005626509259,
            0.06698703794909129,
            0.09379465232949735,
            0.07311113937407497,
        ],
    },
];

/// `$DHCT_REAL_DATA/name`, or `None` (with a note) when the variable is unset or the file
/// is absent.
fn real_file(name: &str) -> Option<PathBuf> {
    let Some(dir) = std::env::var_os("DHCT_REAL_DATA") else {
        eprintln!("note: DHCT_REAL_DATA is unset; skipping the real JPK file {name}");
        return None;
    };
    let path = Path::new(&dir).join(name);
    if !path.is_file() {
        eprintln!("note: {} is absent; skipping it", path.display());
        return None;
    }
    Some(path)
}

fn check_against_gwyddion(file: &ScanFile, references: &[Reference]) {
    const TOLERANCE: f64 = 1e-9;
    for reference in references {
        let pass = if reference.retrace {
            ScanPass::Retrace
        } else {
            ScanPass::Trace
        };
        let what = format!("{} {pass}", reference.name);
        let pair = file
            .pairs
            .iter()
            .find(|p| p.name() == reference.name)
            .unwrap_or_else(|| panic!("no pair {what}"));
        let image: &ImageChannel = pair.image(pass).unwrap_or_else(|| panic!("no {what}"));
        assert_eq!(image.name, reference.name);
        assert_eq!(image.unit, reference.unit, "{what}");
        assert_eq!(
            (image.columns(), image.rows()),
            (reference.xres, reference.yres)
        );
        let g = pair.geometry();
        assert_close(&what, g.width(), reference.xreal, 1e-12);
        assert_close(&what, g.height(), reference.yreal, 1e-12);
        let (low, high) = image.finite_range().unwrap();
        assert_close(&format!("{what} min"), low, reference.min, TOLERANCE);
        assert_close(&format!("{what} max"), high, reference.max, TOLERANCE);
        let mean = image.z.iter().sum::<f64>() / image.z.len() as f64;
        assert_close(&format!("{what} mean"), mean, reference.mean, TOLERANCE);
        let (last_row, last_col) = (reference.yres - 1, reference.xres - 1);
        let corners = [
            image.z[[0, 0]],
            image.z[[0, last_col]],
            image.z[[last_row, 0]],
            image.z[[last_row, last_col]],
        ];
        for (k, (got, want)) in corners.into_iter().zip(reference.corners).enumerate() {
            assert_close(&format!("{what} corner {k}"), got, want, TOLERANCE);
        }
    }
}

#[test]
fn the_real_afm_image_matches_gwyddion() {
    let Some(path) = real_file("sample_0.jpk") else {
        return;
    };
    let file = read_path(&path).unwrap();
    assert_eq!(file.format, FileFormat::Jpk);
    let names: Vec<&str> = file.pairs.iter().map(|p| p.name()).collect();
    assert_eq!(
        names,
        [
            "Height (measured)",
            "Height",
            "Lock-In Amplitude",
            "Lock-In Phase",
            "Error Signal"
        ]
    );
    assert_eq!(file.topography().unwrap().name(), "Height (measured)");
    for pair in &file.pairs {
        assert!(pair.trace().is_some() && pair.retrace().is_some());
    }
    check_against_gwyddion(&file, &SAMPLE_JPK);

    // 4 line pairs per second, 88.1 % of each pass scanning, upward, rotated 90°.
    let g = file.pairs[0].geometry();
    assert_eq!(g.scale_source(), ValueSource::Stated);
    assert_eq!(g.timing_source(), ValueSource::Stated);
    assert_eq!(g.slow_direction(), ScanDirection::Up);
    assert_eq!(g.trace_fast(), ScanDirection::Right);
    assert_close(
        "pixel period",
        g.pixel_period(),
        0.8810208 / 8.0 / 256.0,
        1e-12,
    );
    assert_close(
        "turnaround",
        g.turnaround_time(),
        (1.0 - 0.8810208) / 8.0,
        1e-12,
    );
    // The frame takes yres / f = 64 s; the dates say 63.93 s.
    assert_close("frame", g.frame_duration(), 64.0, 1e-12);
    assert_close("angle", g.scan_angle(), FRAC_PI_2, 1e-15);
    let (u, v, x0, y0) = (
        3.2691651420070083e-07,
        3.2691651420070083e-07,
        2.5844649317557376e-06,
        1.6229086882629253e-06,
    );
    assert_close("offset x", g.offset().0, x0 - v / 2.0, 1e-9);
    assert_close("offset y", g.offset().1, y0 + u / 2.0, 1e-9);
    let m = &file.metadata;
    assert_eq!(m["name"], "Glass in liquid");
    assert_eq!(m["date"], "2017-01-16 16:00:32.334 GMT");
    assert_eq!(m["end date"], "2017-01-16 16:01:36.264 GMT");
    assert_eq!(m["software version"], "6.0.41");
    assert_eq!(m["feedback mode"], "ac-ultra-speed-direct-drive");
    assert!(!m.contains_key("skipped pages"), "{m:?}");

    // The retrace is stored left to right like the trace: it correlates with the trace as
    // read, not mirrored.
    let height = file.channel("Height").unwrap();
    let (a, b) = (&height.trace().unwrap().z, &height.retrace().unwrap().z);
    let mut mirrored = b.clone();
    mirrored.invert_axis(ndarray::Axis(1));
    let (same, flipped) = (
        levelled_correlation(a, b),
        levelled_correlation(a, &mirrored),
    );
    assert!(same > 0.5 && same > flipped + 0.3, "{same} vs {flipped}");
}

#[test]
fn the_real_qi_image_matches_gwyddion() {
    let Some(path) = real_file("sample_0.jpk-qi-image") else {
        return;
    };
    let file = read_path(&path).unwrap();
    assert_eq!(file.format, FileFormat::Jpk);
    let names: Vec<&str> = file.pairs.iter().map(|p| p.name()).collect();
    assert_eq!(
        names,
        [
            "Height (measured) (page 1)",
            "Vertical Deflection",
            "Height (measured) (page 3)",
            "Adhesion",
            "Height",
            "Slope"
        ]
    );
    assert_eq!(
        file.topography().unwrap().name(),
        "Height (measured) (page 1)"
    );
    check_against_gwyddion(&file, &SAMPLE_QI);
    // QI images state no line rate: the timing is assumed, the scale stated.
    let g = file.pairs[0].geometry();
    assert_eq!(g.scale_source(), ValueSource::Stated);
    assert_eq!(g.timing_source(), ValueSource::Assumed);
    assert!(file.metadata[ASSUMED_TIMING_KEY].contains("0x8049"));
    assert_eq!(g.scan_angle(), 0.0);
}

/// Every directory entry's fields, replaced in turn by hostile big-endian words: a value
/// or a typed error, never a panic. The QI file is mutated whole; the larger AFM file is
/// first cut down to its first channel (its link to the third directory set to 0), to keep
/// the test quick.
#[test]
fn the_real_files_survive_hostile_directory_entries() {
    for name in ["sample_0.jpk-qi-image", "sample_0.jpk"] {
        let Some(path) = real_file(name) else {
            continue;
        };
        let mut bytes = std::fs::read(&path).unwrap();
        assert!(bytes.starts_with(b"MM\0*"), "the samples are big-endian");
        let word = |bytes: &[u8], at: usize| {
            u32::from_be_bytes(bytes[at..at + 4].try_into().unwrap()) as usize
        };
        let link = |bytes: &[u8], ifd: usize| {
            ifd + 2 + 12 * usize::from(u16::from_be_bytes([bytes[ifd], bytes[ifd + 1]]))
        };
        if name == "sample_0.jpk" {
            let second = word(&bytes, link(&bytes, word(&bytes, 4)));
            let third = word(&bytes, link(&bytes, second));
            let at = link(&bytes, second);
            bytes[at..at + 4].copy_from_slice(&[0; 4]);
            bytes.truncate(third);
            assert_eq!(read_bytes(&bytes).unwrap().pairs.len(), 1);
        }
        let mut fields = Vec::new();
        let mut ifd = word(&bytes, 4);
        while ifd != 0 {
            for entry in (ifd + 2..link(&bytes, ifd)).step_by(12) {
                fields.extend([entry, entry + 4, entry + 8]);
            }
            fields.push(link(&bytes, ifd));
            ifd = word(&bytes, link(&bytes, ifd));
        }
        let limits = ReadLimits {
            max_bytes: 64 << 20,
            max_pixels: 1 << 22,
        };
        let first_ifd = word(&bytes, 4) as u32;
        let (mut read, mut errors) = (0, 0);
        for at in fields {
            for hostile in [0u32, 1, 0x0000_FFFF, 0x7FFF_FFFF, 0xFFFF_FFFF, first_ifd] {
                let mut mutant = bytes.clone();
                mutant[at..at + 4].copy_from_slice(&hostile.to_be_bytes());
                match read_bytes_limited(&mutant, &limits) {
                    Ok(_) => read += 1,
                    Err(_) => errors += 1,
                }
            }
        }
        eprintln!("{name}: {read} mutants read, {errors} refused");
    }
}

/// Correlation of `a` and `b` after subtracting every row's mean.
fn levelled_correlation(a: &ndarray::Array2<f64>, b: &ndarray::Array2<f64>) -> f64 {
    let level = |m: &ndarray::Array2<f64>| {
        let mut m = m.clone();
        for mut row in m.rows_mut() {
            let mean = row.mean().unwrap();
            row.mapv_inplace(|v| v - mean);
        }
        m
    };
    let (a, b) = (level(a), level(b));
    (&a * &b).sum() / ((&a * &a).sum() * (&b * &b).sum()).sqrt()
}
