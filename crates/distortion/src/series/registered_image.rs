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
    /// The part of the placement that depends only on the pass and the time into the line
    /// (`line_time_s`, seconds): the hysteresis lag, seconds of fast-axis travel; 0 for a
    /// placement without one.
    fn lag_s(&self, pass: ScanPass, line_time_s: f64) -> f64;

    /// Where the tip was relative to the sample at `f`, given `lag_s(f.pass, f.line_time_s)`.
    fn position_with_lag(&self, f: &SeriesFeature, lag_s: f64) -> [f64; 2];

    /// Where the tip was relative to the sample at `f`.
    fn position_of(&self, f: &SeriesFeature) -> [f64; 2] {
        self.position_with_lag(f, self.lag_s(f.pass, f.line_time_s))
    }
}

impl SessionPlacement for SeriesFit {
    fn lag_s(&self, pass: ScanPass, line_time_s: f64) -> f64 {
        self.hysteresis_lag_s(pass, line_time_s)
    }
    fn position_with_lag(&self, f: &SeriesFeature, lag_s: f64) -> [f64; 2] {
        SeriesFit::position_with_lag(self, f, lag_s)
    }
}

/// The drift, with trace and retrace set apart by the offset the images show between them
/// (half each way): no hysteresis law, the files' pixel size (what image comparisons
/// cannot measure).
impl SessionPlacement for ImageRegistration {
    fn lag_s(&self, _pass: ScanPass, _line_time_s: f64) -> f64 {
        0.0
    }
    fn position_with_lag(&self, f: &SeriesFeature, _lag_s: f64) -> [f64; 2] {
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
    let lags = LagByPosition::new(fit, geometry, pass);
    // Every pixel placed once, lines side by side (the resampling reads each line twice:
    // for the rows it covers, then for its quads).
    let mut placed = vec![[0.0f64; 2]; rows * columns];
    placed
        .par_chunks_mut(columns.max(1))
        .enumerate()
        .for_each(|(r, line)| {
            for (c, at) in line.iter_mut().enumerate() {
                let f = SeriesFeature::at_pixel(geometry, start_s, pass, c as f64, r as f64);
                let q = grid.from_instrument(fit.position_with_lag(&f, lags.at(fit, &f)));
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

/// A placement's hysteresis lag at every pixel position along a line of one pass, computed
/// once: pixel `k` of a line is read `(k + ½)` pixel periods into it on every line.
struct LagByPosition {
    pass: ScanPass,
    pixel_period_s: f64,
    lags: Vec<f64>,
}

impl LagByPosition {
    fn new(fit: &dyn SessionPlacement, geometry: &ScanGeometry, pass: ScanPass) -> Self {
        let pixel_period_s = geometry.pixel_period();
        let length = geometry.rows().max(geometry.columns());
        let lags = (0..length)
            .map(|k| fit.lag_s(pass, (k as f64 + 0.5) * pixel_period_s))
            .collect();
        LagByPosition {
            pass,
            pixel_period_s,
            lags,
        }
    }

    /// `f`'s lag: the stored one when `f` lies on a pixel of the line (to rounding), else
    /// computed.
    fn at(&self, fit: &dyn SessionPlacement, f: &SeriesFeature) -> f64 {
        // On pixel k the time is (k + ½) periods: truncation finds k, without the library
        // call `f64::round` is on the baseline x86-64 target.
        let k = (f.line_time_s / self.pixel_period_s) as usize;
        let on_pixel = ((k as f64 + 0.5) * self.pixel_period_s - f.line_time_s).abs()
            <= 1e-9 * self.pixel_period_s;
        match self.lags.get(k) {
            Some(&lag) if f.pass == self.pass && on_pixel => lag,
            _ => fit.lag_s(f.pass, f.line_time_s),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use dhct_scan::ScanDirection;

    /// A placement with a lag that varies along the line and a drift in time, in metres.
    struct Lagging {
        /// Recompute the lag itself, ignoring the one given.
        ignore_given: bool,
    }

    impl SessionPlacement for Lagging {
        fn lag_s(&self, pass: ScanPass, line_time_s: f64) -> f64 {
            let sign = if pass == ScanPass::Trace { 1.0 } else { -1.0 };
            sign * 3e-3 * (-line_time_s / 4e-3).exp()
        }
        fn position_with_lag(&self, f: &SeriesFeature, lag_s: f64) -> [f64; 2] {
            let lag = if self.ignore_given {
                self.lag_s(f.pass, f.line_time_s)
            } else {
                lag_s
            };
            [
                f.controller_m[0] + 1e-10 * lag / 3e-3 + 2e-12 * f.time_s,
                f.controller_m[1] - 1e-12 * f.time_s,
            ]
        }
    }

    /// A placement that counts how often its lag is computed.
    struct Counting(std::sync::atomic::AtomicUsize);

    impl SessionPlacement for Counting {
        fn lag_s(&self, _pass: ScanPass, line_time_s: f64) -> f64 {
            self.0.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            line_time_s * line_time_s
        }
        fn position_with_lag(&self, f: &SeriesFeature, _lag_s: f64) -> [f64; 2] {
            f.controller_m
        }
    }

    /// Every pixel of every line reads its lag from the store; a time between pixels
    /// computes it.
    #[test]
    fn pixels_read_the_stored_lag_and_other_times_compute_it() {
        use std::sync::atomic::Ordering::Relaxed;
        let geometry = ScanGeometry::new(
            24,
            16,
            1e-10,
            1e-10,
            3e-4,
            ScanDirection::Left,
            ScanDirection::Up,
        )
        .unwrap();
        let fit = Counting(0.into());
        for pass in [ScanPass::Trace, ScanPass::Retrace] {
            let lags = LagByPosition::new(&fit, &geometry, pass);
            fit.0.store(0, Relaxed);
            for (r, c) in (0..16).flat_map(|r| (0..24).map(move |c| (r, c))) {
                let f = SeriesFeature::at_pixel(&geometry, 2.0, pass, c as f64, r as f64);
                assert_eq!(lags.at(&fit, &f), f.line_time_s * f.line_time_s);
            }
            assert_eq!(
                fit.0.load(Relaxed),
                0,
                "{pass:?}: every pixel's lag was stored"
            );
            let mut between = SeriesFeature::at_pixel(&geometry, 2.0, pass, 3.5, 1.0);
            between.line_time_s += 0.25 * geometry.pixel_period();
            lags.at(&fit, &between);
            assert_eq!(fit.0.load(Relaxed), 1);
        }
    }

    /// Registering with the lag stored per position along the line gives what computing it
    /// at every pixel gives, in both passes and with the fast axis along either image axis.
    #[test]
    fn lags_stored_per_line_position_place_pixels_as_computed_ones() {
        for (fast, slow) in [
            (ScanDirection::Right, ScanDirection::Down),
            (ScanDirection::Down, ScanDirection::Left),
        ] {
            let geometry = ScanGeometry::new(48, 40, 1e-10, 1e-10, 2e-4, fast, slow).unwrap();
            let z = Array2::from_shape_fn((40, 48), |(r, c)| (0.3 * r as f64).sin() + c as f64);
            for pass in [ScanPass::Trace, ScanPass::Retrace] {
                let register = |ignore_given| {
                    let fit = Lagging { ignore_given };
                    register_image(&fit, &geometry, 5.0, pass, &z, &geometry).unwrap()
                };
                let (stored, computed) = (register(false), register(true));
                assert!(stored.iter().any(|v| v.is_finite()));
                for (a, b) in stored.iter().zip(&computed) {
                    assert!(a == b || (a.is_nan() && b.is_nan()), "{fast:?} {pass:?}");
                }
            }
        }
    }
}
