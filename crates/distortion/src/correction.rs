//! Applying a fitted model: every feature and every pixel from the controller frame to the
//! sample frame, and resampling onto a regular grid.
//!
//! Each point's time is the exact one from [`ScanGeometry::acquisition_time`] (within-line
//! time, retrace delay, turnaround, any scan direction, non-square images), so a feature
//! and the pixels around it move together: the corrected image and the corrected feature
//! table agree (tested).
//!
//! Resampling is a structured-grid inverse mapping: the input pixel grid, moved to the
//! sample frame, is a deformed quadrilateral mesh; each quad is split into two triangles,
//! and every output pixel centre inside a triangle gets the barycentric (linear)
//! interpolation of its three corners' z. This equals Delaunay-barycentric interpolation of
//! the scattered points wherever the mesh is not folded, costs O(pixels), and leaves
//! pixels outside the mesh NaN (unlike griddata's convex hull, it does not fill concave
//! edges).

use dhct_features::Feature;
use dhct_scan::{ScanGeometry, ScanPass};
use ndarray::Array2;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::DistortionError;
use crate::model::DistortionModel;

/// A feature moved to the sample frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CorrectedFeature {
    /// Index in the input slice.
    pub index: usize,
    /// Its pass.
    pub pass: ScanPass,
    /// Sample-frame position, metres (display frame, same origin as the controller frame).
    pub x_m: f64,
    /// Sample-frame position, metres.
    pub y_m: f64,
    /// The same in output pixels (`x_m/pitch_x`, `y_m/pitch_y`).
    pub x_px: f64,
    /// The same in output pixels.
    pub y_px: f64,
}

/// Moves every feature to the sample frame: `p_s = p_c + d(t(p_c), pass)`.
pub fn correct_features(
    model: &DistortionModel,
    geometry: &ScanGeometry,
    features: &[Feature],
) -> Vec<CorrectedFeature> {
    features
        .iter()
        .enumerate()
        .map(|(index, f)| {
            let [x, y] = model.to_sample(geometry, f.pass, f.x_px, f.y_px);
            CorrectedFeature {
                index,
                pass: f.pass,
                x_m: x,
                y_m: y,
                x_px: x / geometry.pitch_x(),
                y_px: y / geometry.pitch_y(),
            }
        })
        .collect()
}

/// Sample-frame positions of every pixel of `pass`, in output pixels: `(x, y)` arrays of
/// shape `rows × columns`.
pub fn pixel_sample_positions(
    model: &DistortionModel,
    geometry: &ScanGeometry,
    pass: ScanPass,
) -> (Array2<f64>, Array2<f64>) {
    let (rows, columns) = (geometry.rows(), geometry.columns());
    let (px, py) = (geometry.pitch_x(), geometry.pitch_y());
    let positions: Vec<[f64; 2]> = (0..rows * columns)
        .into_par_iter()
        .map(|k| {
            let (r, c) = (k / columns, k % columns);
            let [x, y] = model.to_sample(geometry, pass, c as f64, r as f64);
            [x / px, y / py]
        })
        .collect();
    let x = Array2::from_shape_fn((rows, columns), |(r, c)| positions[r * columns + c][0]);
    let y = Array2::from_shape_fn((rows, columns), |(r, c)| positions[r * columns + c][1]);
    (x, y)
}

/// The corrected image of `pass`: `z` (rows × columns, display orientation, controller
/// frame) resampled onto the sample-frame grid with the same pitch, size and origin
/// (output pixel `(c, r)` is the sample point `(c·pitch_x, r·pitch_y)`). Pixels no input
/// triangle covers are NaN; z values are not changed.
pub fn correct_image(
    model: &DistortionModel,
    geometry: &ScanGeometry,
    pass: ScanPass,
    z: &Array2<f64>,
) -> Result<Array2<f64>, DistortionError> {
    let (rows, columns) = z.dim();
    if rows != geometry.rows() || columns != geometry.columns() {
        return Err(DistortionError::ShapeMismatch {
            what: "image",
            columns,
            rows,
            geometry_columns: geometry.columns(),
            geometry_rows: geometry.rows(),
        });
    }
    let (xs, ys) = pixel_sample_positions(model, geometry, pass);
    Ok(resample_mesh(&xs, &ys, z, rows, columns))
}

/// Rasterises the quad mesh with vertices `(xs, ys)` (output pixels) and values `z` onto an
/// `out_rows × out_columns` grid by barycentric interpolation; uncovered pixels NaN.
/// Runs in parallel over horizontal bands of the output; where the mesh folds over itself
/// the quad acquired last (in row-major input order) wins.
pub fn resample_mesh(
    xs: &Array2<f64>,
    ys: &Array2<f64>,
    z: &Array2<f64>,
    out_rows: usize,
    out_columns: usize,
) -> Array2<f64> {
    let mut out = Array2::from_elem((out_rows, out_columns), f64::NAN);
    let (rows, columns) = z.dim();
    if rows < 2 || columns < 2 || out_rows == 0 || out_columns == 0 {
        return out;
    }
    // The y range covered by each row of quads.
    let quad_rows: Vec<(f64, f64)> = (0..rows - 1)
        .map(|r| {
            let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
            for rr in [r, r + 1] {
                for c in 0..columns {
                    let y = ys[[rr, c]];
                    if y.is_finite() {
                        lo = lo.min(y);
                        hi = hi.max(y);
                    }
                }
            }
            (lo, hi)
        })
        .collect();
    let band = out_rows
        .div_ceil(4 * rayon::current_num_threads().max(1))
        .max(8);
    let mut chunks: Vec<ndarray::ArrayViewMut2<f64>> =
        out.axis_chunks_iter_mut(ndarray::Axis(0), band).collect();
    chunks.par_iter_mut().enumerate().for_each(|(k, chunk)| {
        let first = k * band;
        let last = first + chunk.nrows() - 1;
        for (r, (lo, hi)) in quad_rows.iter().enumerate() {
            if *hi < first as f64 - 1.0 || *lo > last as f64 + 1.0 {
                continue;
            }
            for c in 0..columns - 1 {
                let p = |rr: usize, cc: usize| (xs[[rr, cc]], ys[[rr, cc]], z[[rr, cc]]);
                let (a, b, cc, d) = (p(r, c), p(r, c + 1), p(r + 1, c + 1), p(r + 1, c));
                for triangle in [[a, b, cc], [a, cc, d]] {
                    rasterise(triangle, chunk, first, out_columns);
                }
            }
        }
    });
    out
}

/// Writes the barycentric interpolation of one triangle into the output rows
/// `first .. first + band.nrows()`.
fn rasterise(
    vertices: [(f64, f64, f64); 3],
    band: &mut ndarray::ArrayViewMut2<f64>,
    first: usize,
    out_columns: usize,
) {
    let [(x0, y0, z0), (x1, y1, z1), (x2, y2, z2)] = vertices;
    let det = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0);
    if det.abs() < 1e-12 || !det.is_finite() {
        return;
    }
    let (lo_x, hi_x) = (x0.min(x1).min(x2), x0.max(x1).max(x2));
    let (lo_y, hi_y) = (y0.min(y1).min(y2), y0.max(y1).max(y2));
    // A little slack so grid points on an edge (up to rounding) are not lost.
    let slack = 1e-9;
    let c_lo = (lo_x - slack).ceil().max(0.0);
    let c_hi = (hi_x + slack).floor().min(out_columns as f64 - 1.0);
    let r_lo = (lo_y - slack).ceil().max(first as f64);
    let r_hi = (hi_y + slack)
        .floor()
        .min((first + band.nrows()) as f64 - 1.0);
    if c_lo > c_hi || r_lo > r_hi {
        return;
    }
    for r in r_lo as usize..=r_hi as usize {
        let y = r as f64;
        for c in c_lo as usize..=c_hi as usize {
            let x = c as f64;
            let l1 = ((x - x0) * (y2 - y0) - (x2 - x0) * (y - y0)) / det;
            let l2 = ((x1 - x0) * (y - y0) - (x - x0) * (y1 - y0)) / det;
            let l0 = 1.0 - l1 - l2;
            if l0 >= -slack && l1 >= -slack && l2 >= -slack {
                band[[r - first, c]] = l0 * z0 + l1 * z1 + l2 * z2;
            }
        }
    }
}
