//! PNG writers: decode with the `png` crate and compare with the documented mappings.

use dhct_scan::ImageChannel;
use dhct_sm4_io::png_file::{self, Colormap, NAN_COLOUR};
use dhct_sm4_io::{ReadError, read_bytes};
use ndarray::Array2;

/// A non-square image with a NaN and an infinity.
fn sample() -> ImageChannel {
    let mut z = Array2::from_shape_fn((5, 8), |(r, c)| (r as f64 * 8.0 + c as f64) * 1e-11 - 1e-10);
    z[[1, 3]] = f64::NAN;
    z[[4, 0]] = f64::INFINITY;
    ImageChannel::new("Topography", "m", z)
}

/// Decodes a PNG: (width, height, colour type, bit depth, raw bytes).
fn decode(bytes: &[u8]) -> (u32, u32, png::ColorType, png::BitDepth, Vec<u8>) {
    let decoder = png::Decoder::new(std::io::Cursor::new(bytes));
    let mut reader = decoder.read_info().unwrap();
    let mut buffer = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buffer).unwrap();
    buffer.truncate(info.buffer_size());
    (
        info.width,
        info.height,
        info.color_type,
        info.bit_depth,
        buffer,
    )
}

#[test]
fn gray16_maps_the_finite_range_onto_0_to_65535() {
    let channel = sample();
    let mut bytes = Vec::new();
    let scale = png_file::write_gray16(&channel, &mut bytes).unwrap();
    let (width, height, color, depth, data) = decode(&bytes);
    assert_eq!((width, height), (8, 5));
    assert_eq!(
        (color, depth),
        (png::ColorType::Grayscale, png::BitDepth::Sixteen)
    );
    let (low, high) = channel.finite_range().unwrap();
    assert_eq!(scale.offset, low);
    let counts: Vec<u16> = data
        .chunks_exact(2)
        .map(|b| u16::from_be_bytes([b[0], b[1]]))
        .collect();
    assert_eq!(counts.len(), 40);
    for ((r, c), value) in channel.z.indexed_iter() {
        let count = counts[r * 8 + c];
        if value.is_finite() {
            let expected = ((value - low) / (high - low) * 65535.0).round() as u16;
            assert_eq!(count, expected, "row {r} column {c}");
            assert!((scale.value(count) - value).abs() <= scale.step * 0.5 + 1e-20);
        } else {
            assert_eq!(count, 0, "non-finite pixels are black");
        }
    }
    assert_eq!(counts[0], 0, "the minimum is black");
    assert_eq!(counts[39], 65535, "the maximum is white");
}

#[test]
fn colour_maps_match_the_documented_mapping() {
    let channel = sample();
    for colormap in Colormap::ALL {
        let mut bytes = Vec::new();
        let range = png_file::write_colormap(&channel, colormap, &mut bytes)
            .unwrap()
            .expect("finite values");
        let (low, high) = channel.finite_range().unwrap();
        assert_eq!((range.low, range.high), (low, high));
        let (width, height, color, depth, data) = decode(&bytes);
        assert_eq!((width, height), (8, 5));
        assert_eq!((color, depth), (png::ColorType::Rgb, png::BitDepth::Eight));
        for ((r, c), value) in channel.z.indexed_iter() {
            let i = 3 * (r * 8 + c);
            let pixel = [data[i], data[i + 1], data[i + 2]];
            let expected = if value.is_finite() {
                colormap.rgb((value - low) / (high - low))
            } else {
                NAN_COLOUR
            };
            assert_eq!(pixel, expected, "{colormap:?} row {r} column {c}");
        }
        assert_eq!(Colormap::parse(colormap.name()), Some(colormap));
    }
}

#[test]
fn colour_maps_run_from_dark_to_bright() {
    let luminance =
        |[r, g, b]: [u8; 3]| 0.2126 * f64::from(r) + 0.7152 * f64::from(g) + 0.0722 * f64::from(b);
    for colormap in Colormap::ALL {
        assert!(
            luminance(colormap.rgb(0.0)) < luminance(colormap.rgb(1.0)),
            "{colormap:?}"
        );
        assert_ne!(colormap.rgb(0.5), NAN_COLOUR);
    }
    assert_eq!(Colormap::Greys.rgb(0.0), [0, 0, 0]);
    assert_eq!(Colormap::Greys.rgb(1.0), [255, 255, 255]);
    assert_eq!(Colormap::Gold.rgb(0.0), [0, 0, 0]);
    assert_eq!(Colormap::Gold.rgb(0.5), [255, 128, 0]);
    assert_eq!(Colormap::Gold.rgb(1.0), [255, 255, 255]);
    assert_eq!(Colormap::parse("afmhot"), Some(Colormap::Gold));
    assert_eq!(Colormap::parse("Gray"), Some(Colormap::Greys));
    assert_eq!(Colormap::parse("jet"), None);
}

#[test]
fn images_without_finite_values_and_flat_images() {
    let nan = ImageChannel::new("nan", "m", Array2::from_elem((2, 3), f64::NAN));
    let mut bytes = Vec::new();
    assert_eq!(
        png_file::write_colormap(&nan, Colormap::Viridis, &mut bytes).unwrap(),
        None
    );
    let (_, _, _, _, data) = decode(&bytes);
    assert!(data.chunks_exact(3).all(|p| p == NAN_COLOUR));

    let flat = ImageChannel::new("flat", "m", Array2::from_elem((3, 2), 7.0));
    let mut bytes = Vec::new();
    let range = png_file::write_colormap(&flat, Colormap::Greys, &mut bytes)
        .unwrap()
        .unwrap();
    assert_eq!((range.low, range.high), (7.0, 7.0));
    let (_, _, _, _, data) = decode(&bytes);
    assert!(
        data.iter().all(|&b| b == 0),
        "a flat image gets the first colour"
    );

    let empty = ImageChannel::new("empty", "m", Array2::zeros((0, 0)));
    assert!(png_file::write_gray16(&empty, &mut Vec::new()).is_err());
}

#[test]
fn png_is_not_read_back_as_data() {
    let mut bytes = Vec::new();
    png_file::write_gray16(&sample(), &mut bytes).unwrap();
    assert!(matches!(
        read_bytes(&bytes),
        Err(ReadError::Unsupported { .. })
    ));
}

#[test]
fn pictures_of_every_colour_type_and_depth_read_back() {
    use dhct_sm4_io::ReadLimits;
    use dhct_sm4_io::png_file::{Picture, read_picture, write_picture};
    let (columns, rows) = (5, 3);
    let grey: Vec<f64> = (0..15).map(|k| f64::from(k) / 14.0).collect();
    let alpha: Vec<f64> = (0..15)
        .map(|k| if k % 2 == 0 { 1.0 } else { 0.0 })
        .collect();
    for with_alpha in [false, true] {
        for rgb in [false, true] {
            for sixteen in [false, true] {
                let picture = Picture {
                    columns,
                    rows,
                    grey: grey.clone(),
                    alpha: with_alpha.then(|| alpha.clone()),
                    bit_depth: if sixteen { 16 } else { 8 },
                };
                let mut bytes = Vec::new();
                write_picture(&picture, rgb, sixteen, &mut bytes).unwrap();
                let back = read_picture(&bytes, &ReadLimits::default()).unwrap();
                let step = if sixteen { 1.0 / 65535.0 } else { 1.0 / 255.0 };
                assert_eq!((back.columns, back.rows), (columns, rows));
                assert_eq!(back.bit_depth, picture.bit_depth);
                for (a, b) in back.grey.iter().zip(&grey) {
                    assert!((a - b).abs() <= step, "{a} vs {b}");
                }
                assert_eq!(back.alpha.is_some(), with_alpha);
                if let Some(back_alpha) = back.alpha {
                    assert_eq!(back_alpha, alpha);
                }
            }
        }
    }
    // Hostile input: truncated pictures and a header claiming a huge size are errors.
    let picture = Picture {
        columns,
        rows,
        grey,
        alpha: None,
        bit_depth: 8,
    };
    let mut bytes = Vec::new();
    write_picture(&picture, false, false, &mut bytes).unwrap();
    // (Cut before the 12-byte IEND chunk: the pixels are all there after it.)
    for cut in 0..bytes.len() - 12 {
        assert!(
            read_picture(&bytes[..cut], &ReadLimits::default()).is_err(),
            "cut at {cut}"
        );
    }
    let tiny = ReadLimits {
        max_bytes: 1 << 20,
        max_pixels: 10,
    };
    assert!(read_picture(&bytes, &tiny).is_err());
}
