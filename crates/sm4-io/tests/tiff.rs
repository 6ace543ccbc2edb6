//! TIFF writers and reader: exact float32 round trip, 16-bit round trip within quantisation,
//! foreign TIFFs of other sample types, and hostile inputs.

use std::io::Cursor;

use dhct_scan::{FileFormat, ImageChannel, ValueSource};
use dhct_sm4_io::{ReadError, read_bytes, tiff_file};
use ndarray::Array2;
use proptest::prelude::*;
use tiff::encoder::{TiffEncoder, colortype};

/// A non-square image with a NaN, values exactly representable as f32.
fn sample() -> ImageChannel {
    let mut z = Array2::from_shape_fn((5, 7), |(r, c)| {
        f64::from(((r as f32) * 0.37 - (c as f32) * 0.11).sin() * 1e-10)
    });
    z[[3, 2]] = f64::NAN;
    ImageChannel::new("Topography", "m", z)
}

#[test]
fn float32_round_trip_is_exact() {
    let channel = sample();
    let mut bytes = Vec::new();
    tiff_file::write_f32(&channel, &mut bytes).unwrap();
    let scan = read_bytes(&bytes).unwrap();
    assert_eq!(scan.format, FileFormat::Tiff);
    let pair = &scan.pairs[0];
    let back = pair.trace().unwrap();
    assert_eq!(back.name, "Topography");
    assert_eq!(back.unit, "m");
    assert_eq!(back.z.dim(), (5, 7));
    for (a, b) in back.z.iter().zip(channel.z.iter()) {
        assert_eq!(a.to_bits(), b.to_bits());
    }
    let g = pair.geometry();
    assert_eq!((g.columns(), g.rows()), (7, 5));
    assert_eq!(g.scale_source(), ValueSource::Assumed);
    assert_eq!(g.timing_source(), ValueSource::Assumed);
    assert_eq!(g.pitch_x(), dhct_sm4_io::ASSUMED_PITCH);
    assert_eq!(
        scan.metadata.get("tiff sample bits").map(String::as_str),
        Some("32")
    );
}

#[test]
fn u16_round_trip_is_within_half_a_step() {
    let channel = sample();
    let mut bytes = Vec::new();
    let scale = tiff_file::write_u16(&channel, &mut bytes).unwrap();
    let (low, high) = channel.finite_range().unwrap();
    assert_eq!(scale.offset, low);
    assert!((scale.step * 65535.0 - (high - low)).abs() <= 1e-9 * (high - low));
    assert_eq!(scale.count(low), 0);
    assert_eq!(scale.count(high), 65535);
    assert_eq!(scale.count(f64::NAN), 0);

    let back = read_bytes(&bytes).unwrap();
    let z = &back.pairs[0].trace().unwrap().z;
    for (a, b) in z.iter().zip(channel.z.iter()) {
        if b.is_nan() {
            assert_eq!(*a, low, "NaN is stored as count 0");
        } else {
            assert!(
                (a - b).abs() <= scale.step * 0.5 + 1e-12 * high.abs(),
                "{a} vs {b}"
            );
        }
    }
    assert_eq!(back.pairs[0].trace().unwrap().unit, "m");
    assert_eq!(
        back.metadata.get("tiff sample bits").map(String::as_str),
        Some("16")
    );
}

#[test]
fn flat_and_empty_images_have_a_usable_scale() {
    let flat = ImageChannel::new("flat", "V", Array2::from_elem((2, 3), 1.25));
    let mut bytes = Vec::new();
    let scale = tiff_file::write_u16(&flat, &mut bytes).unwrap();
    assert_eq!(scale.value(scale.count(1.25)), 1.25);
    let z = read_bytes(&bytes).unwrap().pairs[0]
        .trace()
        .unwrap()
        .z
        .clone();
    assert!(z.iter().all(|v| *v == 1.25));

    let nan = ImageChannel::new("nan", "V", Array2::from_elem((2, 2), f64::NAN));
    let scale = tiff_file::write_u16(&nan, &mut Vec::new()).unwrap();
    assert_eq!((scale.offset, scale.step), (0.0, 1.0));

    let empty = ImageChannel::new("empty", "V", Array2::zeros((0, 3)));
    assert!(tiff_file::write_f32(&empty, &mut Vec::new()).is_err());
}

fn encode<C: colortype::ColorType>(width: u32, height: u32, data: &[C::Inner]) -> Vec<u8>
where
    [C::Inner]: tiff::encoder::TiffValue,
{
    let mut cursor = Cursor::new(Vec::new());
    TiffEncoder::new(&mut cursor)
        .unwrap()
        .write_image::<C>(width, height, data)
        .unwrap();
    cursor.into_inner()
}

#[test]
fn foreign_tiffs_of_other_sample_types_are_read_as_raw_values() {
    let f64_data: Vec<f64> = (0..12).map(|i| i as f64 * 1.5e-11 - 3e-11).collect();
    let scan = tiff_file::read(&encode::<colortype::Gray64Float>(4, 3, &f64_data)).unwrap();
    let channel = scan.pairs[0].trace().unwrap();
    assert_eq!(channel.name, tiff_file::DEFAULT_NAME);
    assert_eq!(channel.unit, "");
    assert_eq!(channel.z.dim(), (3, 4));
    assert_eq!(channel.z[[0, 3]], f64_data[3], "row-major, row 0 first");
    assert_eq!(channel.z[[2, 0]], f64_data[8]);

    let u8_data: Vec<u8> = (0..6).map(|i| i * 40).collect();
    let z = tiff_file::read(&encode::<colortype::Gray8>(2, 3, &u8_data))
        .unwrap()
        .pairs[0]
        .trace()
        .unwrap()
        .z
        .clone();
    assert_eq!(
        z.iter().copied().collect::<Vec<_>>(),
        vec![0.0, 40.0, 80.0, 120.0, 160.0, 200.0]
    );

    let u16_data: Vec<u16> = vec![0, 1, 65535, 7];
    let z = tiff_file::read(&encode::<colortype::Gray16>(4, 1, &u16_data))
        .unwrap()
        .pairs[0]
        .trace()
        .unwrap()
        .z
        .clone();
    assert_eq!(z.row(0).to_vec(), vec![0.0, 1.0, 65535.0, 7.0]);

    let i16_data: Vec<i16> = vec![-5, 5];
    let z = tiff_file::read(&encode::<colortype::GrayI16>(1, 2, &i16_data))
        .unwrap()
        .pairs[0]
        .trace()
        .unwrap()
        .z
        .clone();
    assert_eq!(z.column(0).to_vec(), vec![-5.0, 5.0]);
}

#[test]
fn colour_tiffs_are_unsupported() {
    let rgb = encode::<colortype::RGB8>(2, 2, &[0u8; 12]);
    assert!(matches!(
        tiff_file::read(&rgb),
        Err(ReadError::Unsupported { .. })
    ));
}

/// A little-endian TIFF with one IFD describing a float32 grey image of `width × height`
/// whose single strip of `strip_bytes` bytes starts right after the IFD.
fn handmade_tiff(width: u32, height: u32, strip_bytes: u32) -> Vec<u8> {
    let entries: [(u16, u16, u32); 10] = [
        (256, 4, width),               // ImageWidth, LONG
        (257, 4, height),              // ImageLength
        (258, 3, 32),                  // BitsPerSample, SHORT
        (259, 3, 1),                   // Compression: none
        (262, 3, 1),                   // PhotometricInterpretation: BlackIsZero
        (273, 4, 8 + 2 + 10 * 12 + 4), // StripOffsets
        (277, 3, 1),                   // SamplesPerPixel
        (278, 4, height),              // RowsPerStrip
        (279, 4, strip_bytes),         // StripByteCounts
        (339, 3, 3),                   // SampleFormat: IEEE float
    ];
    let mut out = b"II*\0".to_vec();
    out.extend_from_slice(&8u32.to_le_bytes());
    out.extend_from_slice(&(entries.len() as u16).to_le_bytes());
    for (tag, kind, value) in entries {
        out.extend_from_slice(&tag.to_le_bytes());
        out.extend_from_slice(&kind.to_le_bytes());
        out.extend_from_slice(&1u32.to_le_bytes());
        if kind == 3 {
            out.extend_from_slice(&(value as u16).to_le_bytes());
            out.extend_from_slice(&[0, 0]);
        } else {
            out.extend_from_slice(&value.to_le_bytes());
        }
    }
    out.extend_from_slice(&0u32.to_le_bytes());
    out.extend(std::iter::repeat_n(0u8, strip_bytes.min(4096) as usize));
    out
}

#[test]
fn handmade_tiff_reads_and_hostile_dimensions_fail() {
    // The hand-made layout is valid when the sizes are honest.
    let ok = handmade_tiff(3, 2, 24);
    let scan = tiff_file::read(&ok).unwrap();
    assert_eq!(scan.pairs[0].trace().unwrap().z.dim(), (2, 3));
    // Huge sizes: refused before decoding, without allocating.
    for (w, h, strip) in [
        (2_147_483_648, 2_147_483_648, u32::MAX),
        (u32::MAX, u32::MAX, 16),
        (100_000, 100_000, 4096),
        (65_536, 65_536, 4),
    ] {
        assert!(
            tiff_file::read(&handmade_tiff(w, h, strip)).is_err(),
            "{w} x {h}"
        );
    }
    // Honest dimensions but a strip that is not in the file.
    assert!(tiff_file::read(&handmade_tiff(64, 64, 64 * 64 * 4)).is_err());
    assert!(tiff_file::read(&handmade_tiff(0, 5, 0)).is_err());
}

#[test]
fn truncated_files_are_errors_or_identical() {
    let channel = sample();
    let mut bytes = Vec::new();
    tiff_file::write_f32(&channel, &mut bytes).unwrap();
    let full = tiff_file::read(&bytes).unwrap();
    let mut accepted = 0;
    for cut in 0..bytes.len() {
        if let Ok(scan) = tiff_file::read(&bytes[..cut]) {
            // Only trailing padding may be cut without changing the image.
            accepted += 1;
            let (a, b) = (
                &scan.pairs[0].trace().unwrap().z,
                &full.pairs[0].trace().unwrap().z,
            );
            assert!(
                a.iter()
                    .zip(b.iter())
                    .all(|(x, y)| x.to_bits() == y.to_bits()),
                "cut at {cut}"
            );
        }
    }
    assert!(accepted <= 1, "{accepted} truncated files were accepted");
}

#[test]
fn random_bytes_are_rejected() {
    let mut state = 0xE7037ED1A0B428DBu64;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state as u8
    };
    for len in [0usize, 4, 8, 16, 100, 1000] {
        for _ in 0..30 {
            let mut bytes: Vec<u8> = (0..len).map(|_| next()).collect();
            assert!(tiff_file::read(&bytes).is_err());
            if bytes.len() >= 8 {
                bytes[..4].copy_from_slice(b"II*\0");
                let _ = tiff_file::read(&bytes);
                bytes[..4].copy_from_slice(b"MM\0*");
                let _ = tiff_file::read(&bytes);
            }
        }
    }
}

fn small_valid_file() -> Vec<u8> {
    let mut bytes = Vec::new();
    tiff_file::write_f32(&sample(), &mut bytes).unwrap();
    bytes
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    #[test]
    fn mutated_files_never_panic(
        edits in prop::collection::vec((0usize..600, any::<u8>()), 1..8),
        cut in 0usize..600,
    ) {
        let mut bytes = small_valid_file();
        for (position, value) in edits {
            let len = bytes.len();
            bytes[position % len] = value;
        }
        let cut = cut.min(bytes.len());
        for candidate in [&bytes[..], &bytes[..cut]] {
            if let Ok(scan) = tiff_file::read(candidate) {
                let z = &scan.pairs[0].trace().unwrap().z;
                prop_assert!(z.len() <= candidate.len() * tiff_file::DECODE_BUDGET_PER_BYTE);
            }
        }
    }
}
