//! Boolean masks (rows × columns, display orientation, `true` = use) that restrict which
//! features are used for the distortion measurement. Unmasked areas are still corrected.

use std::path::Path;

use dhct_scan::ImageChannel;
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

/// Reads a mask from a PNG or NPY file (any format `dhct-sm4-io` reads; the first image of
/// the first channel): true where the value is above half its range.
pub fn read_mask(path: &Path) -> Result<Array2<bool>, DistortionError> {
    let file = dhct_sm4_io::read_path(path).map_err(|e| {
        DistortionError::BadParameter(format!("cannot read mask {}: {e}", path.display()))
    })?;
    let channel = file
        .pairs
        .first()
        .and_then(|p| p.images().next().map(|(_, c)| c.clone()))
        .ok_or_else(|| {
            DistortionError::BadParameter(format!("{} holds no image", path.display()))
        })?;
    let (lo, hi) = channel.finite_range().unwrap_or((0.0, 1.0));
    Ok(mask_from_channel(&channel, 0.5 * (lo + hi)))
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
}
