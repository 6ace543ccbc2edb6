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
use dhct_numerics::series::ln_1p_small;
use dhct_scan::{AcquisitionTime, ScanGeometry, ScanPass};
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
    let positions = RowPositions::new(model, geometry, pass);
    let mut x = Array2::<f64>::zeros((rows, columns));
    let mut y = Array2::<f64>::zeros((rows, columns));
    let contiguous = "a new array is contiguous";
    x.as_slice_mut()
        .expect(contiguous)
        .par_chunks_mut(columns.max(1))
        .zip(
            y.as_slice_mut()
                .expect(contiguous)
                .par_chunks_mut(columns.max(1)),
        )
        .enumerate()
        .for_each(|(r, (x_row, y_row))| positions.fill(r, x_row, y_row));
    (x, y)
}

/// Writes the sample-frame positions (output pixels) of input row `r` to `(xs, ys)`.
pub type RowPositionsFn<'a> = dyn Fn(usize, &mut [f64], &mut [f64]) + Sync + 'a;

/// A range (output rows) holding the y positions of every pixel of input row `r`.
type RowYRangeFn<'a> = dyn Fn(usize) -> (f64, f64) + Sync + 'a;

/// Computes the sample-frame positions (output pixels) of one input row at a time.
struct RowPositions<'a> {
    model: &'a DistortionModel,
    geometry: &'a ScanGeometry,
    pass: ScanPass,
    /// `(time since line start, hysteresis lag)` of each fast index: pixels share the lag
    /// of their fast index, so it is tabulated once (and used only where a pixel's line
    /// time is bit-identical to the tabulated one).
    lags: Vec<(f64, f64)>,
}

impl<'a> RowPositions<'a> {
    fn new(model: &'a DistortionModel, geometry: &'a ScanGeometry, pass: ScanPass) -> Self {
        let pixel_period = geometry.pixel_period();
        let lags = (0..geometry.fast_len())
            .map(|k| {
                let tau = (k as f64 + 0.5) * pixel_period;
                (tau, model.hysteresis_lag(geometry, pass, tau))
            })
            .collect();
        RowPositions {
            model,
            geometry,
            pass,
            lags,
        }
    }

    /// Writes the positions of the pixels of row `r` (display orientation) to `xs`, `ys`.
    ///
    /// The creep's `ln(1 + t/t0)` is taken from the row's first pixel:
    /// `ln(1 + t_a/t0) + ln(1 + (t − t_a)/(t0 + t_a))`, the second term by its series where
    /// small ([`ln_1p_small`]: a row spans a tiny part of `t0 + t` unless `t0` is short).
    fn fill(&self, r: usize, xs: &mut [f64], ys: &mut [f64]) {
        let t0 = self.model.drift.t0_s;
        let mut anchor: Option<(f64, f64)> = None;
        for (c, (x, y)) in xs.iter_mut().zip(ys.iter_mut()).enumerate() {
            let time = self.time(c, r);
            let t = time.since_frame_start;
            let (t_a, log_a) = *anchor.get_or_insert_with(|| (t, (t / t0).ln_1p()));
            let log = log_a + ln_1p_small((t - t_a) / (t0 + t_a));
            (*x, *y) = self.position_at(c, r, time, log);
        }
    }

    /// The acquisition time of pixel `(c, r)` (display orientation).
    #[inline]
    fn time(&self, c: usize, r: usize) -> AcquisitionTime {
        self.geometry
            .acquisition_time(self.pass, c as f64, r as f64)
    }

    /// The position (output pixels) of pixel `(c, r)` (display orientation).
    fn position(&self, c: usize, r: usize) -> (f64, f64) {
        let time = self.time(c, r);
        let log = (time.since_frame_start / self.model.drift.t0_s).ln_1p();
        self.position_at(c, r, time, log)
    }

    /// [`RowPositions::position`] with the pixel's acquisition `time` and the creep's
    /// `ln(1 + t/t0)` given.
    #[inline]
    fn position_at(&self, c: usize, r: usize, time: AcquisitionTime, log: f64) -> (f64, f64) {
        let geometry = self.geometry;
        let (xc, yc) = (c as f64, r as f64);
        let tau = time.since_line_start;
        let k = (tau / geometry.pixel_period() - 0.5).round();
        let lag = match self.lags.get(k as usize) {
            Some(&(tabulated, lag)) if k >= 0.0 && tabulated == tau => lag,
            _ => self.model.hysteresis_lag(geometry, self.pass, tau),
        };
        let d =
            self.model
                .displacement_with_lag_and_log(geometry, time.since_frame_start, lag, log);
        let (px, py) = (geometry.pitch_x(), geometry.pitch_y());
        ((xc * px + d[0]) / px, (yc * py + d[1]) / py)
    }

    /// A range (output rows) holding the y position of every pixel of row `r`, from every
    /// [`Y_RANGE_STEP`]-th pixel and the last, widened by twice the largest change between
    /// neighbouring samples plus one row. Along a row the displacement is smooth (drift and
    /// creep) plus a lag monotone in the line time, so between two samples it leaves their
    /// range by less than one sample step. Only used to skip rows that cannot touch a band:
    /// a wider range costs time, never pixels. `(∞, −∞)` when no sample is finite.
    fn y_range(&self, r: usize, columns: usize) -> (f64, f64) {
        let samples = (0..columns)
            .step_by(Y_RANGE_STEP)
            .chain(
                (columns > 0 && !(columns - 1).is_multiple_of(Y_RANGE_STEP)).then_some(columns - 1),
            )
            .map(|c| self.position(c, r).1)
            .filter(|y| y.is_finite());
        let (mut lo, mut hi, mut step) = (f64::INFINITY, f64::NEG_INFINITY, 0.0f64);
        let mut previous: Option<f64> = None;
        for y in samples {
            lo = lo.min(y);
            hi = hi.max(y);
            if let Some(p) = previous {
                step = step.max((y - p).abs());
            }
            previous = Some(y);
        }
        let margin = 2.0 * step + 1.0;
        (lo - margin, hi + margin)
    }
}

/// Pixels between the samples of [`RowPositions::y_range`].
const Y_RANGE_STEP: usize = 16;

/// The corrected image of `pass`: `z` (rows × columns, display orientation, controller
/// frame) resampled onto the sample-frame grid with the same pitch, size and origin
/// (output pixel `(c, r)` is the sample point `(c·pitch_x, r·pitch_y)`). Pixels no input
/// triangle covers are NaN; z values are not changed.
///
/// Memory beyond the output is a few rows per thread: the pixel positions are computed
/// row by row where they are used, not stored for the whole image.
pub fn correct_image(
    model: &DistortionModel,
    geometry: &ScanGeometry,
    pass: ScanPass,
    z: &Array2<f64>,
) -> Result<Array2<f64>, DistortionError> {
    let (rows, columns) = image_shape(geometry, z)?;
    let positions = RowPositions::new(model, geometry, pass);
    Ok(resample_mesh(
        &|r, xs, ys| positions.fill(r, xs, ys),
        &|r| positions.y_range(r, columns),
        z,
        (rows, columns),
    ))
}

/// `z`'s `(rows, columns)`, an error unless they are `geometry`'s.
pub(crate) fn image_shape(
    geometry: &ScanGeometry,
    z: &Array2<f64>,
) -> Result<(usize, usize), DistortionError> {
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
    Ok((rows, columns))
}

/// A corrected image on a grid that holds every corrected pixel (the paper's frame: no
/// pixel cropped, no-data around them).
#[derive(Debug, Clone, PartialEq)]
pub struct ExtendedImage {
    /// The values, rows × columns, NaN = no data.
    pub z: Array2<f64>,
    /// The sample-frame pixel (of the scan's own grid) at this grid's pixel `(0, 0)`:
    /// `[column, row]`, negative where the grid reaches left of or above the scan's.
    pub origin_px: [i64; 2],
}

/// Largest growth per side of an [`ExtendedImage`] over its scan.
const MAX_EXTENT_GROWTH: usize = 3;

/// [`correct_image`] on a grid holding every corrected pixel: the smallest grid of the
/// same pitch, aligned with the scan's own, covering every pixel's sample position.
pub fn correct_image_full(
    model: &DistortionModel,
    geometry: &ScanGeometry,
    pass: ScanPass,
    z: &Array2<f64>,
) -> Result<ExtendedImage, DistortionError> {
    let (rows, columns) = image_shape(geometry, z)?;
    let positions = RowPositions::new(model, geometry, pass);
    let (mut xs, mut ys) = (vec![0.0; columns], vec![0.0; columns]);
    let (mut low, mut high) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for r in 0..rows {
        positions.fill(r, &mut xs, &mut ys);
        for (&x, &y) in xs
            .iter()
            .zip(&ys)
            .filter(|(x, y)| x.is_finite() && y.is_finite())
        {
            low = [low[0].min(x), low[1].min(y)];
            high = [high[0].max(x), high[1].max(y)];
        }
    }
    if !(low[0].is_finite() && high[0].is_finite()) {
        return Err(DistortionError::BadParameter(
            "the model gives no pixel a finite position".into(),
        ));
    }
    let origin = [low[0].floor(), low[1].floor()];
    let out_columns = (high[0].ceil() - origin[0]) as usize + 1;
    let out_rows = (high[1].ceil() - origin[1]) as usize + 1;
    if out_columns > MAX_EXTENT_GROWTH * columns || out_rows > MAX_EXTENT_GROWTH * rows {
        return Err(DistortionError::ExtentTooLarge {
            columns: out_columns,
            rows: out_rows,
            scan_columns: columns,
            scan_rows: rows,
            limit: MAX_EXTENT_GROWTH,
        });
    }
    let shifted = |r: usize, xs: &mut [f64], ys: &mut [f64]| {
        positions.fill(r, xs, ys);
        xs.iter_mut().for_each(|x| *x -= origin[0]);
        ys.iter_mut().for_each(|y| *y -= origin[1]);
    };
    let y_range = |r: usize| {
        let (lo, hi) = positions.y_range(r, columns);
        (lo - origin[1], hi - origin[1])
    };
    Ok(ExtendedImage {
        z: resample_mesh(&shifted, &y_range, z, (out_rows, out_columns)),
        origin_px: [origin[0] as i64, origin[1] as i64],
    })
}

/// Resamples `z` onto an `out_rows × out_columns` grid, given where each input pixel lands
/// on it: `row_positions(r, xs, ys)` writes the output-pixel coordinates of input row `r`.
/// Uncovered output pixels are NaN (see [`correct_image`] for the method).
pub fn resample_onto(
    row_positions: &RowPositionsFn<'_>,
    z: &Array2<f64>,
    out_shape: (usize, usize),
) -> Array2<f64> {
    let columns = z.ncols();
    let y_range = |r: usize| {
        let (mut xs, mut ys) = (vec![0.0; columns], vec![0.0; columns]);
        row_positions(r, &mut xs, &mut ys);
        ys.iter()
            .filter(|y| y.is_finite())
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &y| {
                (lo.min(y), hi.max(y))
            })
    };
    resample_mesh(row_positions, &y_range, z, out_shape)
}

/// Rasterises the quad mesh whose row `r` of vertices `row_positions(r, xs, ys)` writes
/// (output pixels) and whose values are `z` onto an `out_rows × out_columns` grid by
/// barycentric interpolation; uncovered pixels NaN. Runs in parallel over horizontal bands
/// of the output, each computing the vertex rows it needs; where the mesh folds over itself
/// the quad acquired last (in row-major input order) wins.
fn resample_mesh(
    row_positions: &RowPositionsFn<'_>,
    row_y_range: &RowYRangeFn<'_>,
    z: &Array2<f64>,
    (out_rows, out_columns): (usize, usize),
) -> Array2<f64> {
    let mut out = Array2::from_elem((out_rows, out_columns), f64::NAN);
    let (rows, columns) = z.dim();
    if rows < 2 || columns < 2 || out_rows == 0 || out_columns == 0 {
        return out;
    }
    let z = z.as_standard_layout();
    let z = z.as_slice().expect("standard-layout arrays are contiguous");
    let quad_rows = quad_row_ranges(row_y_range, rows);
    let band = out_rows
        .div_ceil(4 * rayon::current_num_threads().max(1))
        .max(8);
    let out_slice = out.as_slice_mut().expect("a new array is contiguous");
    out_slice
        .par_chunks_mut(band * out_columns)
        .enumerate()
        .for_each(|(k, chunk)| {
            let rows = chunk.len() / out_columns;
            let mut target = Band {
                values: chunk,
                first: k * band,
                rows,
                columns: out_columns,
            };
            let mut vertices = VertexRows::new(columns);
            let last = target.first + target.rows - 1;
            for (r, (lo, hi)) in quad_rows.iter().enumerate() {
                if *hi < target.first as f64 - 1.0 || *lo > last as f64 + 1.0 {
                    continue;
                }
                vertices.load(r, row_positions);
                let (top, bottom) = (&z[r * columns..], &z[(r + 1) * columns..]);
                for c in 0..columns - 1 {
                    target.rasterise_quad([
                        vertices.top(c, top[c]),
                        vertices.top(c + 1, top[c + 1]),
                        vertices.bottom(c + 1, bottom[c + 1]),
                        vertices.bottom(c, bottom[c]),
                    ]);
                }
            }
        });
    out
}

/// The y range (output pixels) covered by each row of quads (vertex rows `r`, `r + 1`).
fn quad_row_ranges(row_y_range: &RowYRangeFn<'_>, rows: usize) -> Vec<(f64, f64)> {
    let vertex_rows: Vec<(f64, f64)> = (0..rows).into_par_iter().map(row_y_range).collect();
    vertex_rows
        .windows(2)
        .map(|w| (w[0].0.min(w[1].0), w[0].1.max(w[1].1)))
        .collect()
}

/// Two consecutive rows of mesh vertices (`r` on top, `r + 1` below), reused when the next
/// quad row is `r + 1`.
struct VertexRows {
    /// The top row's index, once loaded.
    row: Option<usize>,
    top: (Vec<f64>, Vec<f64>),
    bottom: (Vec<f64>, Vec<f64>),
}

impl VertexRows {
    fn new(columns: usize) -> Self {
        VertexRows {
            row: None,
            top: (vec![0.0; columns], vec![0.0; columns]),
            bottom: (vec![0.0; columns], vec![0.0; columns]),
        }
    }

    /// Makes vertex rows `r` and `r + 1` the current pair.
    fn load(&mut self, r: usize, row_positions: &RowPositionsFn<'_>) {
        if self.row == Some(r) {
            return;
        }
        if self.row.is_some_and(|previous| previous + 1 == r) {
            std::mem::swap(&mut self.top, &mut self.bottom);
        } else {
            row_positions(r, &mut self.top.0, &mut self.top.1);
        }
        row_positions(r + 1, &mut self.bottom.0, &mut self.bottom.1);
        self.row = Some(r);
    }

    /// Vertex `c` of the top row with value `z`.
    #[inline]
    fn top(&self, c: usize, z: f64) -> (f64, f64, f64) {
        (self.top.0[c], self.top.1[c], z)
    }

    /// Vertex `c` of the bottom row with value `z`.
    #[inline]
    fn bottom(&self, c: usize, z: f64) -> (f64, f64, f64) {
        (self.bottom.0[c], self.bottom.1[c], z)
    }
}

/// `floor` without a libm call (the baseline x86-64 target has no rounding instruction).
#[inline]
fn fast_floor(v: f64) -> f64 {
    let t = v as i64 as f64;
    if t > v { t - 1.0 } else { t }
}

#[inline]
fn fast_ceil(v: f64) -> f64 {
    -fast_floor(-v)
}

/// A little slack so grid points on an edge (up to rounding) are not lost.
const SLACK: f64 = 1e-9;

/// Output rows `first .. first + rows` (row-major, `columns` wide).
struct Band<'a> {
    values: &'a mut [f64],
    first: usize,
    rows: usize,
    columns: usize,
}

impl Band<'_> {
    /// Integer grid range (columns, rows) of the bounding box of `points`, clipped to the
    /// band; `None` when it holds no grid point.
    #[inline]
    fn grid_box(&self, xs: [f64; 4], ys: [f64; 4]) -> Option<(usize, usize, usize, usize)> {
        let lo_x = xs[0].min(xs[1]).min(xs[2]).min(xs[3]);
        let hi_x = xs[0].max(xs[1]).max(xs[2]).max(xs[3]);
        let lo_y = ys[0].min(ys[1]).min(ys[2]).min(ys[3]);
        let hi_y = ys[0].max(ys[1]).max(ys[2]).max(ys[3]);
        let c_lo = fast_ceil(lo_x - SLACK).max(0.0);
        let c_hi = fast_floor(hi_x + SLACK).min(self.columns as f64 - 1.0);
        let r_lo = fast_ceil(lo_y - SLACK).max(self.first as f64);
        let r_hi = fast_floor(hi_y + SLACK).min((self.first + self.rows) as f64 - 1.0);
        // `!(a <= b)` also rejects NaN.
        if !(c_lo <= c_hi && r_lo <= r_hi) {
            return None;
        }
        Some((c_lo as usize, c_hi as usize, r_lo as usize, r_hi as usize))
    }

    /// Writes the barycentric interpolation of the quad `a b c d` (split along `a c` into
    /// the triangles `a b c` and `a c d`; a grid point on the diagonal takes `a c d`'s value,
    /// as if the triangles were drawn in that order) at every grid point it covers.
    #[inline]
    fn rasterise_quad(&mut self, corners: [(f64, f64, f64); 4]) {
        let Some((c_lo, c_hi, r_lo, r_hi)) =
            self.grid_box(corners.map(|v| v.0), corners.map(|v| v.1))
        else {
            return;
        };
        let [a, b, c, d] = corners;
        let second = Triangle::new(a, c, d);
        let first = Triangle::new(a, b, c);
        for r in r_lo..=r_hi {
            let y = r as f64;
            let out = &mut self.values[(r - self.first) * self.columns..];
            for (column, value) in out.iter_mut().enumerate().take(c_hi + 1).skip(c_lo) {
                let x = column as f64;
                if let Some(z) = second.as_ref().and_then(|t| t.interpolate(x, y)) {
                    *value = z;
                } else if let Some(z) = first.as_ref().and_then(|t| t.interpolate(x, y)) {
                    *value = z;
                }
            }
        }
    }
}

/// A non-degenerate triangle prepared for barycentric interpolation: its first vertex, the
/// edge vectors to the other two, and the z of all three.
struct Triangle {
    origin: (f64, f64),
    edge1: (f64, f64),
    edge2: (f64, f64),
    det: f64,
    z: [f64; 3],
}

impl Triangle {
    /// `None` when the triangle is degenerate or has a non-finite vertex position.
    #[inline]
    fn new(v0: (f64, f64, f64), v1: (f64, f64, f64), v2: (f64, f64, f64)) -> Option<Self> {
        let edge1 = (v1.0 - v0.0, v1.1 - v0.1);
        let edge2 = (v2.0 - v0.0, v2.1 - v0.1);
        let det = edge1.0 * edge2.1 - edge2.0 * edge1.1;
        (det.abs() >= 1e-12 && det.is_finite()).then_some(Triangle {
            origin: (v0.0, v0.1),
            edge1,
            edge2,
            det,
            z: [v0.2, v1.2, v2.2],
        })
    }

    /// The interpolated z at grid point `(x, y)` if it lies inside (up to [`SLACK`]).
    #[inline]
    fn interpolate(&self, x: f64, y: f64) -> Option<f64> {
        let (dx, dy) = (x - self.origin.0, y - self.origin.1);
        let l1 = (dx * self.edge2.1 - self.edge2.0 * dy) / self.det;
        let l2 = (self.edge1.0 * dy - dx * self.edge1.1) / self.det;
        let l0 = 1.0 - l1 - l2;
        (l0 >= -SLACK && l1 >= -SLACK && l2 >= -SLACK)
            .then(|| l0 * self.z[0] + l1 * self.z[1] + l2 * self.z[2])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::DriftCreep;
    use dhct_scan::{HysteresisLaw, ScanDirection};

    /// The whole-extent image holds the frame image where they overlap, and every pixel
    /// the frame crops: a drift that carries the scan left and down by several pixels.
    #[test]
    fn the_full_extent_holds_the_frame_and_what_it_crops() {
        let geometry = ScanGeometry::new(
            40,
            30,
            1e-10,
            1e-10,
            1e-3,
            ScanDirection::Right,
            ScanDirection::Down,
        )
        .unwrap();
        let drift = DriftCreep {
            velocity_m_per_s: [-2e-10, 1e-10],
            ..DriftCreep::none()
        };
        let model = DistortionModel::new(drift, HysteresisLaw::none());
        let z = Array2::from_shape_fn((30, 40), |(r, c)| (r * 40 + c) as f64);
        for pass in ScanPass::BOTH {
            let frame = correct_image(&model, &geometry, pass, &z).unwrap();
            let full = correct_image_full(&model, &geometry, pass, &z).unwrap();
            let [ox, oy] = full.origin_px;
            assert!(ox < 0 && oy == 0, "{:?}", full.origin_px);
            let finite = |a: &Array2<f64>| a.iter().filter(|v| v.is_finite()).count();
            assert!(finite(&full.z) > finite(&frame), "nothing was cropped?");
            for ((r, c), v) in frame.indexed_iter() {
                let w = full.z[[(r as i64 - oy) as usize, (c as i64 - ox) as usize]];
                assert!(
                    (v.is_nan() && w.is_nan()) || (v - w).abs() < 1e-9,
                    "{pass} ({r}, {c}): {v} vs {w}"
                );
            }
        }
    }

    /// Every pixel's y lies in its row's sampled range, for a fast axis along y (the
    /// hysteresis lag moves pixels along y, steepest at the line start), early creep,
    /// a drift that turns back within the frame, both passes and several directions.
    #[test]
    fn sampled_row_ranges_hold_every_pixel() {
        let model = DistortionModel::new(
            DriftCreep {
                // The y velocity changes sign within the frame: y peaks between samples.
                velocity_m_per_s: [3e-11, 4e-11],
                acceleration_m_per_s2: [2e-13, -2e-11],
                creep_m: [2e-10, 1e-11],
                t0_s: 0.5,
            },
            HysteresisLaw::Power { k: 0.6, n: -0.6 },
        );
        for (fast, slow) in [
            (ScanDirection::Down, ScanDirection::Right),
            (ScanDirection::Up, ScanDirection::Left),
            (ScanDirection::Right, ScanDirection::Up),
        ] {
            let geometry =
                ScanGeometry::new(203, 77, 2e-11, 2e-11, 2e-4, fast, slow).expect("valid");
            for pass in [ScanPass::Trace, ScanPass::Retrace] {
                let positions = RowPositions::new(&model, &geometry, pass);
                let (rows, columns) = (geometry.rows(), geometry.columns());
                let (mut xs, mut ys) = (vec![0.0; columns], vec![0.0; columns]);
                for r in 0..rows {
                    positions.fill(r, &mut xs, &mut ys);
                    let (lo, hi) = positions.y_range(r, columns);
                    let outside: Vec<f64> =
                        ys.iter().copied().filter(|&y| y < lo || y > hi).collect();
                    assert!(
                        outside.is_empty(),
                        "{fast:?}/{slow:?} {pass:?} row {r}: {outside:?} outside {lo}..{hi}"
                    );
                    let span = ys.iter().fold(f64::NEG_INFINITY, |a, &y| a.max(y))
                        - ys.iter().fold(f64::INFINITY, |a, &y| a.min(y));
                    assert!(
                        hi - lo <= 3.0 * span + 2.0,
                        "{lo}..{hi} for a span of {span}"
                    );
                }
            }
        }
    }
}
