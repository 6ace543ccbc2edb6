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
    register_image_sampled(fit, geometry, start_s, pass, z, grid, 1)
}

/// [`register_image`] from every `step`-th pixel of every `step`-th line of `z` only (each
/// placed where the fit puts that pixel): for a coarser `grid`, at about `1/step²` of the
/// cost. Content finer than `2·step` pixels of `z` folds into coarser content (no
/// smoothing), so keep features wider than that. `step` ≥ 1.
pub fn register_image_sampled(
    fit: &dyn SessionPlacement,
    geometry: &ScanGeometry,
    start_s: f64,
    pass: ScanPass,
    z: &Array2<f64>,
    grid: &ScanGeometry,
    step: usize,
) -> Result<Array2<f64>, DistortionError> {
    image_shape(geometry, z)?;
    let step = step.max(1);
    let sampled;
    let z = if step == 1 {
        z
    } else {
        sampled = z.slice(ndarray::s![..;step, ..;step]).to_owned();
        &sampled
    };
    let (rows, columns) = z.dim();
    let lags = LagByPosition::new(fit, geometry, pass);
    let place_pixel = |r: usize, c: usize| {
        let (x, y) = ((step * c) as f64, (step * r) as f64);
        let f = SeriesFeature::at_pixel(geometry, start_s, pass, x, y);
        let q = grid.from_instrument(fit.position_with_lag(&f, lags.at(fit, &f)));
        [q[0] / grid.pitch_x(), q[1] / grid.pitch_y()]
    };
    let reaching = rows_reaching_grid(&place_pixel, (rows, columns), (grid.rows(), grid.columns()));
    // Every pixel of a row that can reach the grid placed once, lines side by side (the
    // resampling reads each line twice: for the rows it covers, then for its quads); the
    // other rows are NaN, which the resampling leaves out.
    let mut placed = vec![[f64::NAN; 2]; rows * columns];
    placed
        .par_chunks_mut(columns.max(1))
        .enumerate()
        .filter(|(r, _)| reaching[*r])
        .for_each(|(r, line)| {
            for (c, at) in line.iter_mut().enumerate() {
                *at = place_pixel(r, c);
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

/// Rows and columns apart of the pixels [`rows_reaching_grid`] places.
const SAMPLE_STEP: usize = 16;

/// Which rows of an image of `(rows, columns)` pixels, placed by `place_pixel(row, column)`
/// in output pixels, can reach an output grid of `(out_rows, out_columns)` (a frame the
/// drift carried away from the first frame's grid covers little or none of it). The
/// placement is sampled every [`SAMPLE_STEP`] rows and columns and at the last of each; the
/// rows between two sampled rows reach the grid when the box around both rows' samples,
/// widened by two sample steps at the largest spacing between neighbouring samples, meets
/// it (the placement, a scan's smooth drift, bends far less than that within a step). All
/// rows when a sample is not finite or only one row is sampled.
fn rows_reaching_grid(
    place_pixel: &(dyn Fn(usize, usize) -> [f64; 2] + Sync),
    (rows, columns): (usize, usize),
    (out_rows, out_columns): (usize, usize),
) -> Vec<bool> {
    let sampled = |n: usize| -> Vec<usize> {
        let mut at: Vec<usize> = (0..n).step_by(SAMPLE_STEP).collect();
        if n > 0 && at.last() != Some(&(n - 1)) {
            at.push(n - 1);
        }
        at
    };
    let (sample_rows, sample_columns) = (sampled(rows), sampled(columns));
    if sample_rows.len() < 2 {
        return vec![true; rows];
    }
    let samples: Vec<Vec<[f64; 2]>> = sample_rows
        .par_iter()
        .map(|&r| sample_columns.iter().map(|&c| place_pixel(r, c)).collect())
        .collect();
    if samples
        .iter()
        .flatten()
        .any(|p| !(p[0].is_finite() && p[1].is_finite()))
    {
        return vec![true; rows];
    }
    let spacing = largest_sample_spacing(&samples, &sample_rows, &sample_columns);
    let margin = 2.0 * SAMPLE_STEP as f64 * spacing + 1.0;
    let mut reaching = vec![false; rows];
    for (k, pair) in sample_rows.windows(2).enumerate() {
        let corners = samples[k].iter().chain(&samples[k + 1]);
        let (lo, hi) = corners.fold(
            ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]),
            |(lo, hi), p| {
                (
                    [lo[0].min(p[0]), lo[1].min(p[1])],
                    [hi[0].max(p[0]), hi[1].max(p[1])],
                )
            },
        );
        let meets = hi[0] + margin >= 0.0
            && lo[0] - margin <= out_columns as f64
            && hi[1] + margin >= 0.0
            && lo[1] - margin <= out_rows as f64;
        if meets {
            reaching[pair[0]..=pair[1]].fill(true);
        }
    }
    reaching
}

/// The largest distance between neighbouring samples (along a sampled row or column),
/// per pixel of the image between them, in output pixels.
fn largest_sample_spacing(samples: &[Vec<[f64; 2]>], rows: &[usize], columns: &[usize]) -> f64 {
    let per_pixel = |a: [f64; 2], b: [f64; 2], pixels: usize| {
        (a[0] - b[0]).hypot(a[1] - b[1]) / pixels.max(1) as f64
    };
    let along_rows = samples.iter().flat_map(|line| {
        line.windows(2)
            .zip(columns.windows(2))
            .map(|(p, c)| per_pixel(p[0], p[1], c[1] - c[0]))
    });
    let along_columns = samples
        .windows(2)
        .zip(rows.windows(2))
        .flat_map(|(pair, r)| {
            pair[0]
                .iter()
                .zip(&pair[1])
                .map(move |(a, b)| per_pixel(*a, *b, r[1] - r[0]))
        });
    along_rows.chain(along_columns).fold(0.0, f64::max)
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

    /// A frame moved by `shift_m` (instrument frame), drifting in time, with a bump along
    /// y of height `bump_m` between `bump_s.0` and `bump_s.1` (a sin² in time, zero
    /// outside): between two sampled rows, what sampling every 16th row cannot see.
    struct Moved {
        shift_m: [f64; 2],
        bump_m: f64,
        bump_s: (f64, f64),
    }

    impl SessionPlacement for Moved {
        fn lag_s(&self, _pass: ScanPass, _line_time_s: f64) -> f64 {
            0.0
        }
        fn position_with_lag(&self, f: &SeriesFeature, _lag_s: f64) -> [f64; 2] {
            let (from, to) = self.bump_s;
            let bump = if (from..to).contains(&f.time_s) {
                self.bump_m
                    * (std::f64::consts::PI * (f.time_s - from) / (to - from))
                        .sin()
                        .powi(2)
            } else {
                0.0
            };
            [
                f.controller_m[0] + self.shift_m[0] + 3e-12 * f.time_s,
                f.controller_m[1] + self.shift_m[1] - 2e-12 * f.time_s + bump,
            ]
        }
    }

    /// A scan of `columns × rows` px of `pitch_m` (both axes), `period_s` a pixel, the fast
    /// axis to the right and the slow axis down.
    fn right_then_down(columns: usize, rows: usize, pitch_m: f64, period_s: f64) -> ScanGeometry {
        ScanGeometry::new(
            columns,
            rows,
            pitch_m,
            pitch_m,
            period_s,
            ScanDirection::Right,
            ScanDirection::Down,
        )
        .unwrap()
    }

    /// A placement without drift or lag: the controller's position.
    struct Still;

    impl SessionPlacement for Still {
        fn lag_s(&self, _pass: ScanPass, _line_time_s: f64) -> f64 {
            0.0
        }
        fn position_with_lag(&self, f: &SeriesFeature, _lag_s: f64) -> [f64; 2] {
            f.controller_m
        }
    }

    /// From every second pixel and line onto a grid of twice the pitch over the same area,
    /// a plane registers as the plane: each coarse pixel holds the value at its place.
    #[test]
    fn a_sampled_registration_onto_a_coarser_grid_reads_each_pixel_at_its_place() {
        let fine = right_then_down(64, 48, 1e-10, 2e-4);
        let coarse = right_then_down(32, 24, 2e-10, 4e-4);
        let plane = |x: f64, y: f64| 0.3 * x - 0.7 * y + 2.0;
        let z = Array2::from_shape_fn((48, 64), |(r, c)| plane(c as f64, r as f64));
        for pass in [ScanPass::Trace, ScanPass::Retrace] {
            let registered =
                register_image_sampled(&Still, &fine, 1.0, pass, &z, &coarse, 2).unwrap();
            assert_eq!(registered.dim(), (24, 32));
            let mut finite = 0;
            for ((r, c), v) in registered.indexed_iter().filter(|(_, v)| v.is_finite()) {
                let q = coarse.to_instrument([c as f64 * 2e-10, r as f64 * 2e-10]);
                let p = fine.from_instrument(q);
                let expected = plane(p[0] / 1e-10, p[1] / 1e-10);
                assert!(
                    (v - expected).abs() < 1e-9,
                    "{pass:?} ({r}, {c}): {v} {expected}"
                );
                finite += 1;
            }
            assert!(finite >= 22 * 30, "{pass:?}: {finite} pixels");
        }
    }

    /// Registering places only the rows that can reach the grid; the image is the one
    /// every row placed gives, for a frame on the grid, partly off it along either axis,
    /// just off it (within the margin), and far off it (no row placed).
    #[test]
    fn rows_that_cannot_reach_the_grid_are_left_out_without_changing_the_image() {
        let geometry = right_then_down(80, 70, 1e-10, 2e-4);
        let z = Array2::from_shape_fn((70, 80), |(r, c)| (0.3 * r as f64).sin() + c as f64);
        let (start_s, pass) = (3.0, ScanPass::Trace);
        let line_start = |r: f64| SeriesFeature::at_pixel(&geometry, start_s, pass, 0.0, r).time_s;
        let bump_s = (line_start(48.0), line_start(64.0));
        for (shift_px, bump_px, reaching_rows) in [
            ([0.0, 0.0], 0.0, 70..=70),
            ([0.0, 40.5], 0.0, 1..=69),
            ([-50.3, 60.0], 0.0, 1..=69),
            ([0.0, -90.0], 0.0, 0..=69),
            ([0.0, -140.0], 0.0, 0..=0),
            ([150.0, 0.0], 0.0, 0..=0),
            // Only rows between sampled ones (48 and 64) reach the grid: the margin's work.
            ([0.0, -72.0], 20.0, 1..=69),
        ] {
            let fit = Moved {
                shift_m: [shift_px[0] * 1e-10, shift_px[1] * 1e-10],
                bump_m: bump_px * 1e-10,
                bump_s,
            };
            let registered = register_image(&fit, &geometry, start_s, pass, &z, &geometry).unwrap();
            let place_pixel = |r: usize, c: usize| {
                let f = SeriesFeature::at_pixel(&geometry, start_s, pass, c as f64, r as f64);
                let q = geometry.from_instrument(fit.position_of(&f));
                [q[0] / geometry.pitch_x(), q[1] / geometry.pitch_y()]
            };
            let every_row = |r: usize, xs: &mut [f64], ys: &mut [f64]| {
                for (c, (x, y)) in xs.iter_mut().zip(ys.iter_mut()).enumerate() {
                    [*x, *y] = place_pixel(r, c);
                }
            };
            let reference = resample_onto(&every_row, &z, (70, 80));
            if bump_px > 0.0 {
                assert!(reference.iter().any(|v| v.is_finite()), "the bump reaches");
            }
            for (a, b) in registered.iter().zip(&reference) {
                assert!(a == b || (a.is_nan() && b.is_nan()), "{shift_px:?}");
            }
            let reaching = rows_reaching_grid(&place_pixel, (70, 80), (70, 80));
            let count = reaching.iter().filter(|r| **r).count();
            assert!(reaching_rows.contains(&count), "{shift_px:?}: {count} rows");
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
