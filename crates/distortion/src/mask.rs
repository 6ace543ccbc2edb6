//! Boolean masks (rows × columns, display orientation, `true` = use) that restrict which
//! features are used for the distortion measurement. Unmasked areas are still corrected.
//! Files: [`read_mask`] (PNG by lightness or alpha, NPY/TIFF by non-zero values).

use std::path::Path;

use dhct_scan::{FileFormat, ImageChannel};
use dhct_sm4_io::ReadLimits;
use dhct_sm4_io::png_file::{Picture, read_picture};
use ndarray::Array2;

use crate::DistortionError;

/// A mask that is true where the pixel centre `(column, row)` lies inside `polygon`
/// (vertices in pixels, `[x = column, y = row]`, even-odd rule), or outside it when
/// `inside` is false.
pub fn polygon_mask(
    rows: usize,
    columns: usize,
    polygon: &[[f64; 2]],
    inside: bool,
) -> Array2<bool> {
    Array2::from_shape_fn((rows, columns), |(r, c)| {
        point_in_polygon(c as f64, r as f64, polygon) == inside
    })
}

/// Even-odd point-in-polygon test.
pub fn point_in_polygon(x: f64, y: f64, polygon: &[[f64; 2]]) -> bool {
    let n = polygon.len();
    let mut inside = false;
    let mut j = n.wrapping_sub(1);
    for i in 0..n {
        let ([xi, yi], [xj, yj]) = (polygon[i], polygon[j]);
        if (yi > y) != (yj > y) && x < (xj - xi) * (y - yi) / (yj - yi) + xi {
            inside = !inside;
        }
        j = i;
    }
    inside
}

/// A mask from an image: true where the value is finite and above `threshold`.
pub fn mask_from_channel(channel: &ImageChannel, threshold: f64) -> Array2<bool> {
    channel.z.mapv(|v| v.is_finite() && v > threshold)
}

/// A mask from a decoded PNG picture: `true` (use) where the pixel is opaque (alpha above
/// one half) when the picture has an alpha channel that is not uniformly opaque; otherwise
/// where it is light (grey level above one half of full scale: white = use, black = ignore;
/// colour pictures by the mean of red, green and blue). An all-white picture selects
/// everything.
pub fn mask_from_picture(picture: &Picture) -> Array2<bool> {
    let use_alpha = picture
        .alpha
        .as_ref()
        .is_some_and(|alpha| alpha.iter().any(|&a| a < 1.0));
    let values: Vec<bool> = match (&picture.alpha, use_alpha) {
        (Some(alpha), true) => alpha.iter().map(|&a| a > 0.5).collect(),
        _ => picture.grey.iter().map(|&g| g > 0.5).collect(),
    };
    Array2::from_shape_vec((picture.rows, picture.columns), values)
        .unwrap_or_else(|_| Array2::from_elem((picture.rows, picture.columns), false))
}

/// A mask from a data image (NPY, TIFF, ...: bool, integer or float samples): `true` where
/// the value is finite and non-zero (NumPy's truth value; NaN counts as false). So a bool
/// array, 0/1, 0/255 and 0.0/1.0 masks all work, and an all-ones mask selects everything.
pub fn mask_from_values(channel: &ImageChannel) -> Array2<bool> {
    channel.z.mapv(|v| v.is_finite() && v != 0.0)
}

/// Reads a mask file (`true` = use the pixel), detected by content:
///
/// * PNG (grey 1–16 bit, grey + alpha, RGB, RGBA, palette): see [`mask_from_picture`];
/// * NPY (bool, integer or float arrays), TIFF (8–64 bit grey) and any other image format
///   `dhct-sm4-io` reads (the first image): see [`mask_from_values`].
///
/// Only regular files are read (a FIFO or device is refused before opening), under
/// `dhct-sm4-io`'s default read limits. A mask that selects no pixel is an error that says
/// so (an all-ones mask is valid and selects everything).
pub fn read_mask(path: &Path) -> Result<Array2<bool>, DistortionError> {
    let cannot = |e: dhct_sm4_io::ReadError| {
        DistortionError::BadParameter(format!("cannot read mask {}: {e}", path.display()))
    };
    let limits = ReadLimits::default();
    let bytes = dhct_sm4_io::limits::read_regular_file(path, limits.max_bytes).map_err(cannot)?;
    let (mask, kind) = if dhct_sm4_io::detect_format(&bytes) == Some(FileFormat::Png) {
        let picture = read_picture(&bytes, &limits).map_err(cannot)?;
        let kind = if picture.alpha.is_some() {
            "PNG: opaque and light pixels"
        } else {
            "PNG: light pixels"
        };
        (mask_from_picture(&picture), kind)
    } else {
        let file = dhct_sm4_io::read_bytes_limited(&bytes, &limits).map_err(cannot)?;
        let channel = file
            .pairs
            .first()
            .and_then(|p| p.images().next().map(|(_, c)| c.clone()))
            .ok_or_else(|| {
                DistortionError::BadParameter(format!("mask {} holds no image", path.display()))
            })?;
        (mask_from_values(&channel), "non-zero values")
    };
    if !mask.iter().any(|&v| v) {
        return Err(DistortionError::BadParameter(format!(
            "mask {} selects no pixel: all its {} x {} pixels are off (a mask uses {kind}; \
             is it inverted?)",
            path.display(),
            mask.ncols(),
            mask.nrows()
        )));
    }
    Ok(mask)
}

/// The intersection of two masks of equal shape.
pub fn intersect(a: &Array2<bool>, b: &Array2<bool>) -> Result<Array2<bool>, DistortionError> {
    if a.dim() != b.dim() {
        return Err(DistortionError::BadParameter(format!(
            "mask shapes differ: {:?} vs {:?}",
            a.dim(),
            b.dim()
        )));
    }
    Ok(ndarray::Zip::from(a).and(b).map_collect(|x, y| *x && *y))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn polygon_mask_inside_and_outside() {
        let triangle = [[0.0, 0.0], [10.0, 0.0], [0.0, 10.0]];
        let inside = polygon_mask(12, 12, &triangle, true);
        assert!(inside[[1, 1]]);
        assert!(!inside[[9, 9]]);
        let outside = polygon_mask(12, 12, &triangle, false);
        assert!(!outside[[1, 1]] && outside[[9, 9]]);
        let both = intersect(&inside, &outside).expect("same shape");
        assert!(both.iter().all(|v| !v));
        assert!(intersect(&inside, &Array2::from_elem((3, 3), true)).is_err());
    }

    #[test]
    fn mask_from_channel_thresholds() {
        let z = Array2::from_shape_vec((1, 3), vec![0.0, 1.0, f64::NAN]).expect("shape");
        let m = mask_from_channel(&ImageChannel::new("mask", "", z), 0.5);
        assert_eq!(m.as_slice(), Some(&[false, true, false][..]));
    }

    /// A scratch directory removed when dropped.
    struct Scratch(std::path::PathBuf);

    impl Scratch {
        fn new(name: &str) -> Scratch {
            let dir = std::env::temp_dir().join(format!(
                "dhct-mask-{name}-{}-{:?}",
                std::process::id(),
                std::thread::current().id()
            ));
            std::fs::create_dir_all(&dir).expect("scratch directory");
            Scratch(dir)
        }
        fn write(&self, name: &str, bytes: &[u8]) -> std::path::PathBuf {
            let path = self.0.join(name);
            std::fs::write(&path, bytes).expect("write");
            path
        }
    }

    impl Drop for Scratch {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }

    /// The expected mask: the left two columns of a 4 x 3 image are used.
    fn left_half() -> Array2<bool> {
        Array2::from_shape_fn((3, 4), |(_, c)| c < 2)
    }

    fn png(grey: Vec<f64>, alpha: Option<Vec<f64>>, rgb: bool, sixteen: bool) -> Vec<u8> {
        let picture = Picture {
            columns: 4,
            rows: 3,
            grey,
            alpha,
            bit_depth: 8,
        };
        let mut bytes = Vec::new();
        dhct_sm4_io::png_file::write_picture(&picture, rgb, sixteen, &mut bytes).expect("png");
        bytes
    }

    fn left_levels(on: f64, off: f64) -> Vec<f64> {
        (0..12).map(|k| if k % 4 < 2 { on } else { off }).collect()
    }

    #[test]
    fn png_masks_of_every_colour_type_use_lightness_or_alpha() {
        let scratch = Scratch::new("png");
        for rgb in [false, true] {
            for sixteen in [false, true] {
                // Light = use, without alpha or with a uniformly opaque alpha.
                for alpha in [None, Some(vec![1.0; 12])] {
                    let bytes = png(left_levels(1.0, 0.0), alpha, rgb, sixteen);
                    let path = scratch.write("light.png", &bytes);
                    assert_eq!(read_mask(&path).expect("mask"), left_half());
                }
                // With transparency, opaque = use whatever the colour.
                let bytes = png(vec![0.0; 12], Some(left_levels(1.0, 0.0)), rgb, sixteen);
                let path = scratch.write("alpha.png", &bytes);
                assert_eq!(read_mask(&path).expect("mask"), left_half());
            }
        }
        // All white selects everything; all black is an error that says so.
        let path = scratch.write("white.png", &png(vec![1.0; 12], None, false, false));
        assert!(read_mask(&path).expect("all ones").iter().all(|&v| v));
        let path = scratch.write("black.png", &png(vec![0.0; 12], None, false, true));
        let error = read_mask(&path).expect_err("selects nothing").to_string();
        assert!(error.contains("selects no pixel"), "{error}");
    }

    fn npy(descr: &str, data: &[u8]) -> Vec<u8> {
        let header = format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': (3, 4), }}");
        let padded = format!("{header:<117}\n");
        let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
        bytes.extend_from_slice(&(padded.len() as u16).to_le_bytes());
        bytes.extend_from_slice(padded.as_bytes());
        bytes.extend_from_slice(data);
        bytes
    }

    #[test]
    fn npy_and_tiff_masks_use_non_zero_values() {
        let scratch = Scratch::new("npy");
        let on: Vec<u8> = (0..12).map(|k| u8::from(k % 4 < 2)).collect();
        let bools = npy("|b1", &on);
        assert_eq!(
            read_mask(&scratch.write("bool.npy", &bools)).expect("bool"),
            left_half()
        );
        let bytes: Vec<u8> = on.iter().map(|&b| b * 255).collect();
        assert_eq!(
            read_mask(&scratch.write("u8.npy", &npy("|u1", &bytes))).expect("u1"),
            left_half()
        );
        let floats: Vec<u8> = on
            .iter()
            .flat_map(|&b| f64::from(b).to_le_bytes())
            .collect();
        assert_eq!(
            read_mask(&scratch.write("f8.npy", &npy("<f8", &floats))).expect("f8"),
            left_half()
        );
        let ones = npy("|b1", &[1u8; 12]);
        assert!(
            read_mask(&scratch.write("ones.npy", &ones))
                .expect("all ones")
                .iter()
                .all(|&v| v)
        );
        let error = read_mask(&scratch.write("zeros.npy", &npy("|b1", &[0u8; 12])))
            .expect_err("selects nothing")
            .to_string();
        assert!(error.contains("selects no pixel"), "{error}");
        // TIFF (float32 as dhct writes it).
        let z = Array2::from_shape_fn((3, 4), |(_, c)| if c < 2 { 1.0 } else { 0.0 });
        let mut tiff = Vec::new();
        dhct_sm4_io::tiff_file::write_f32(&ImageChannel::new("mask", "", z), &mut tiff)
            .expect("tiff");
        assert_eq!(
            read_mask(&scratch.write("mask.tiff", &tiff)).expect("tiff"),
            left_half()
        );
        // Not a mask at all.
        let error = read_mask(&scratch.write("text.png", b"hello")).expect_err("not an image");
        assert!(error.to_string().contains("cannot read mask"), "{error}");
        assert!(read_mask(&scratch.0).is_err(), "a directory is not a mask");
    }
}
