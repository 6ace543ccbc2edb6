//! The float TIFF with a pixel size: resolution tags, ImageJ header and dhct's own block.

use std::io::Cursor;

use dhct_scan::{ImageChannel, ValueSource};
use dhct_sm4_io::{WriteError, tiff_file};
use ndarray::Array2;
use tiff::decoder::Decoder;
use tiff::tags::Tag;

fn channel() -> ImageChannel {
    let z = Array2::from_shape_fn((6, 9), |(r, c)| (r * 9 + c) as f64 * 1e-11);
    ImageChannel::new("Topography (corrected)", "m", z)
}

/// A rational tag as a number.
fn rational(decoder: &mut Decoder<Cursor<&[u8]>>, tag: Tag) -> f64 {
    let value = decoder.get_tag(tag).unwrap();
    let [n, d] = value.into_u32_vec().unwrap()[..] else {
        panic!("{tag:?} is not one rational");
    };
    f64::from(n) / f64::from(d)
}

#[test]
fn the_pixel_size_is_stored_in_centimetres_and_for_imagej() {
    let pitch = [1.953125e-11, 2.5e-11];
    let mut bytes = Vec::new();
    tiff_file::write_f32_with_pixel_size(&channel(), pitch, &mut bytes).unwrap();
    let mut decoder = Decoder::new(Cursor::new(bytes.as_slice())).unwrap();
    assert_eq!(
        decoder.get_tag_u32(Tag::ResolutionUnit).unwrap(),
        3,
        "centimetre"
    );
    for (tag, pitch) in [(Tag::XResolution, pitch[0]), (Tag::YResolution, pitch[1])] {
        let metres_per_pixel = 0.01 / rational(&mut decoder, tag);
        assert!(
            (metres_per_pixel / pitch - 1.0).abs() < 1e-9,
            "{tag:?}: {metres_per_pixel:e} m per pixel, written {pitch:e}"
        );
    }
    let description = decoder.get_tag_ascii_string(Tag::ImageDescription).unwrap();
    assert!(description.starts_with("ImageJ="), "{description}");
    assert!(description.contains("\nunit=um\n"), "{description}");
    // dhct's reader still restores the name and the z unit (not ImageJ's length unit).
    let file = tiff_file::read(&bytes).unwrap();
    let image = file.pairs[0].trace().unwrap();
    assert_eq!(image.name, "Topography (corrected)");
    assert_eq!(image.unit, "m");
    assert_eq!(image.z[[5, 8]], (53.0f64 * 1e-11) as f32 as f64);
    // ... and the pixel size, as stated.
    let geometry = file.pairs[0].geometry();
    assert_eq!(geometry.scale_source(), ValueSource::Stated);
    for (read, written) in [
        (geometry.pitch_x(), pitch[0]),
        (geometry.pitch_y(), pitch[1]),
    ] {
        assert!(
            (read / written - 1.0).abs() < 1e-9,
            "{read:e} vs {written:e}"
        );
    }
    assert!(!file.metadata.contains_key("assumed scale"));
}

#[test]
fn a_screen_resolution_without_a_length_unit_is_no_pixel_size() {
    // A plain grey TIFF with 72 dpi (what many programs write): the pitch stays assumed.
    let mut bytes = Vec::new();
    {
        let mut encoder = tiff::encoder::TiffEncoder::new(Cursor::new(&mut bytes)).unwrap();
        let mut image = encoder
            .new_image::<tiff::encoder::colortype::Gray32Float>(9, 6)
            .unwrap();
        image.resolution(
            tiff::tags::ResolutionUnit::Inch,
            tiff::encoder::Rational { n: 72, d: 1 },
        );
        let data: Vec<f32> = (0..54).map(|v| v as f32).collect();
        image.write_data(&data).unwrap();
    }
    let file = tiff_file::read(&bytes).unwrap();
    assert_eq!(
        file.pairs[0].geometry().scale_source(),
        ValueSource::Assumed
    );
    assert!(file.metadata.contains_key("assumed scale"));
}

#[test]
fn pixel_sizes_that_are_no_tiff_resolution_are_refused() {
    for pitch in [0.0, -1e-10, f64::NAN, f64::INFINITY, 1e-15] {
        let error =
            tiff_file::write_f32_with_pixel_size(&channel(), [pitch, 1e-10], &mut Vec::new())
                .unwrap_err();
        assert!(
            matches!(error, WriteError::Unrepresentable { .. }),
            "{pitch}: {error}"
        );
    }
    // Large pixels are fine (a few pixels per centimetre).
    let mut bytes = Vec::new();
    tiff_file::write_f32_with_pixel_size(&channel(), [1e-3, 2e-3], &mut bytes).unwrap();
    let mut decoder = Decoder::new(Cursor::new(bytes.as_slice())).unwrap();
    assert!((rational(&mut decoder, Tag::YResolution) - 5.0).abs() < 1e-9);
}

#[test]
fn pages_of_one_size_are_written_in_order_each_with_the_pixel_size() {
    let dx = channel();
    let dy = ImageChannel::new("dy", "m", dx.z.mapv(|v| -v));
    let mut bytes = Vec::new();
    tiff_file::write_f32_pages_with_pixel_size(&[&dx, &dy], [2e-11, 2e-11], &mut bytes).unwrap();
    let mut decoder = Decoder::new(Cursor::new(bytes.as_slice())).unwrap();
    let mut firsts = Vec::new();
    loop {
        let metres_per_pixel = 0.01 / rational(&mut decoder, Tag::XResolution);
        assert!((metres_per_pixel / 2e-11 - 1.0).abs() < 1e-9);
        let tiff::decoder::DecodingResult::F32(data) = decoder.read_image().unwrap() else {
            panic!("not f32");
        };
        firsts.push(data[1]);
        if !decoder.more_images() {
            break;
        }
        decoder.next_image().unwrap();
    }
    assert_eq!(firsts, [1e-11f32, -1e-11f32]);
}
