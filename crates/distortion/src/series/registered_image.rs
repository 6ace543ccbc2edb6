//! A frame's image registered into the session frame: every pixel placed by the series
//! fit, resampled onto one common grid (the first frame's pixel grid turned into the
//! instrument frame), so the frames of a session stack pixel on pixel.

use dhct_scan::{ScanGeometry, ScanPass};
use ndarray::Array2;
use rayon::prelude::*;

use super::fit::SeriesFit;
use super::frame::SeriesFeature;
use super::image_drift::ImageRegistration;
use crate::DistortionError;
use crate::correction::{image_shape, resample_onto};

/// What places a frame's pixels in the session frame: the tip's sample position when it
/// was at a given controller position and time (instrument frame, metres).
pub trait SessionPlacement: Sync {
    /// Where the tip was relative to the sample at `f`.
    fn position_of(&self, f: &SeriesFeature) -> [f64; 2];
}

impl SessionPlacement for SeriesFit {
    fn position_of(&self, f: &SeriesFeature) -> [f64; 2] {
        SeriesFit::position_of(self, f)
    }
}

/// The drift, with trace and retrace set apart by the offset the images show between them
/// (half each way): no hysteresis law, the files' pixel size (what image comparisons
/// cannot measure).
impl SessionPlacement for ImageRegistration {
    fn position_of(&self, f: &SeriesFeature) -> [f64; 2] {
        let d = self.fit.drift.displacement(f.time_s);
        let half = match f.pass {
            ScanPass::Trace => -0.5,
            ScanPass::Retrace => 0.5,
        };
        [
            f.controller_m[0] + d[0] + half * self.retrace_offset_m[0],
            f.controller_m[1] + d[1] + half * self.retrace_offset_m[1],
        ]
    }
}

/// `z` (an image of `pass` of a frame of `geometry` that started `start_s` into the
/// session) resampled onto the grid of `grid` (the common frame: output pixel `(c, r)` is
/// the instrument-frame point `grid.to_instrument((c·pitch_x, r·pitch_y))` displaced by
/// nothing: the session frame fixed to the sample at the first frame's start). NaN where the
/// frame did not reach.
pub fn register_image(
    fit: &dyn SessionPlacement,
    geometry: &ScanGeometry,
    start_s: f64,
    pass: ScanPass,
    z: &Array2<f64>,
    grid: &ScanGeometry,
) -> Result<Array2<f64>, DistortionError> {
    image_shape(geometry, z)?;
    let (rows, columns) = z.dim();
    // Every pixel placed once, lines side by side (the resampling reads each line twice:
    // for the rows it covers, then for its quads).
    let mut placed = vec![[0.0f64; 2]; rows * columns];
    placed
        .par_chunks_mut(columns.max(1))
        .enumerate()
        .for_each(|(r, line)| {
            for (c, at) in line.iter_mut().enumerate() {
                let f = SeriesFeature::at_pixel(geometry, start_s, pass, c as f64, r as f64);
                let q = grid.from_instrument(fit.position_of(&f));
                *at = [q[0] / grid.pitch_x(), q[1] / grid.pitch_y()];
            }
        });
    let place = |r: usize, xs: &mut [f64], ys: &mut [f64]| {
        let line = &placed[r * columns..(r + 1) * columns];
        for ((x, y), at) in xs.iter_mut().zip(ys.iter_mut()).zip(line) {
            [*x, *y] = *at;
        }
    };
    Ok(resample_onto(&place, z, (grid.rows(), grid.columns())))
}
