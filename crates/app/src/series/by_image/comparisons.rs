//! What two consecutive frames without a resolved lattice show of the drift: the frame is
//! first placed on the one before as a whole ([`correlation::frame_offset`]: defects,
//! molecules, steps), then band by band of scan lines
//! ([`placement::image_shift_over`], sub-pixel, with gain, offset and tilt fitted
//! alongside). Each band names one sample area scanned twice: by the frame before at one
//! moment and by this frame at another, so it measures the difference of the drift
//! between those two moments ([`DriftDifference`]).

use dhct_distortion::series::DriftDifference;
use dhct_scan::{Axis, ScanGeometry, ScanPass};
use ndarray::Array2;
use serde::Serialize;

use crate::series::{correlation, placement};

/// Blur (pixels) of the whole-frame correlation: noise down, anything larger than a few
/// pixels (molecules, defects, steps) kept.
const WHOLE_FRAME_BLUR_PX: f64 = 2.0;

/// The whole-frame correlation's best peak must stand this many noise standard deviations
/// above the next best (outside its width). A pattern with a period (molecules on lattice
/// sites, partly occupied) correlates with itself at every period, less well than at the
/// true shift: what counts is by how much, against noise. Over the few hundred
/// independent shifts of a frame noise alone reaches 5σ with a chance of about 10⁻⁴.
const MIN_MARGIN_SIGMAS: f64 = 5.0;

/// The smooth background taken out of each frame before it is compared ([`prepared`]):
/// a Gaussian of this σ, pixels.
const BACKGROUND_PX: f64 = 8.0;

/// Lines per band at least; a frame has between [`MIN_BANDS`] and [`MAX_BANDS`].
const LINES_PER_BAND: usize = 32;
const MIN_BANDS: usize = 2;
const MAX_BANDS: usize = 16;

/// A band's shift is re-searched from a new whole-pixel start at most this many times
/// when it lies more than [`placement::MAX_SHIFT_PX`] from the last.
const BAND_RESTARTS: usize = 3;

/// One frame and where it sits on the session clock.
pub struct FrameImage<'a> {
    /// Its geometry (size, pitch, scan angle, offset, timing).
    pub geometry: &'a ScanGeometry,
    /// Its start, seconds since the first frame's.
    pub start_s: f64,
    /// Its trace image (z units; NaN where missing).
    pub trace: &'a Array2<f64>,
}

/// What one consecutive pair showed.
#[derive(Debug, Clone, Serialize)]
pub struct PairComparison {
    /// The later frame (time order); compared with the one before.
    pub frame: usize,
    /// The later frame's whole shift against the one before, pixels `(columns, rows)`: it
    /// shows at `p` what the frame before showed at `p + s`.
    pub whole_shift_px: [f64; 2],
    /// The whole-frame correlation's peak over what noise reaches (standard deviations).
    pub significance: f64,
    /// Bands of lines compared.
    pub bands: usize,
    /// Bands whose shift was measured.
    pub bands_measured: usize,
}

/// Why a pair could not be compared.
#[derive(Debug, Clone, thiserror::Error)]
pub enum ComparisonError {
    /// No correlation peak stands out.
    #[error(
        "frames {before} and {frame} show no common structure at any shift that keeps 40 % \
         of the frame in common (no correlation peak stands 5 noise standard deviations \
         above every other): they are not of one area, the area changed between them, or \
         they show a perfect lattice (then register them by it)"
    )]
    NoCommonStructure {
        /// The frame before.
        before: usize,
        /// The frame.
        frame: usize,
    },
}

/// What is compared of a frame: each scan line minus its median (line offsets gone), less
/// its own blur over [`BACKGROUND_PX`] (terrace levels, a bow, the slow z drift: smooth
/// structure whose correlation is broad and moves with the frame's edges, not with the
/// sample); what is left are the edges of steps, islands, molecules and defects. NaN kept.
pub fn prepared(z: &Array2<f64>, fast_axis: Axis) -> Array2<f64> {
    let lines = levelled(z, fast_axis);
    let filled = lines.mapv(|v| if v.is_finite() { v } else { 0.0 });
    let background = dhct_features::gaussian_blur(&filled, BACKGROUND_PX);
    let mut out = lines;
    out.zip_mut_with(&background, |v, b| *v -= b);
    out
}

/// Each scan line minus its median (line offsets gone; NaN kept).
fn levelled(z: &Array2<f64>, fast_axis: Axis) -> Array2<f64> {
    let mut out = z.clone();
    let mut level = |mut line: ndarray::ArrayViewMut1<f64>| {
        let mut finite: Vec<f64> = line.iter().copied().filter(|v| v.is_finite()).collect();
        let middle = finite.len() / 2;
        let median = if finite.is_empty() {
            0.0
        } else {
            *finite.select_nth_unstable_by(middle, f64::total_cmp).1
        };
        line.mapv_inplace(|v| v - median);
    };
    match fast_axis {
        Axis::Horizontal => out.rows_mut().into_iter().for_each(&mut level),
        Axis::Vertical => out.columns_mut().into_iter().for_each(&mut level),
    }
    out
}

/// The drift differences `frame` (index `k`) shows against `before` (both [`prepared`],
/// one size, pitch and scan angle).
pub fn compare(
    k: usize,
    before: &FrameImage,
    frame: &FrameImage,
) -> Result<(PairComparison, Vec<DriftDifference>), ComparisonError> {
    let whole = correlation::best_correlation(before.trace, frame.trace, WHOLE_FRAME_BLUR_PX)
        .filter(|o| o.margin_sigmas() >= MIN_MARGIN_SIGMAS)
        .ok_or(ComparisonError::NoCommonStructure {
            before: k - 1,
            frame: k,
        })?;
    let g = frame.geometry;
    let (lines, fast_axis) = match g.fast_axis() {
        Axis::Horizontal => (g.rows(), Axis::Horizontal),
        Axis::Vertical => (g.columns(), Axis::Vertical),
    };
    let bands = (lines / LINES_PER_BAND).clamp(MIN_BANDS, MAX_BANDS);
    let differences: Vec<DriftDifference> = (0..bands)
        .filter_map(|b| {
            let range = (b * lines / bands, (b + 1) * lines / bands);
            let (centre, shift) =
                band_shift(before.trace, frame.trace, whole.shift_px, range, fast_axis)?;
            Some(difference(before, frame, centre, shift))
        })
        .collect();
    Ok((
        PairComparison {
            frame: k,
            whole_shift_px: whole.shift_px,
            significance: whole.significance,
            bands,
            bands_measured: differences.len(),
        },
        differences,
    ))
}

/// `s` (pixels, `(columns, rows)`) where `retrace` shows at `p` what `trace` (of the same
/// frame, both [`prepared`]) showed at `p + s`: the passes' hysteresis differs (their drift
/// differs by one line time only). `None` when no correlation peak stands out.
pub fn pass_shift(trace: &Array2<f64>, retrace: &Array2<f64>, fast_axis: Axis) -> Option<[f64; 2]> {
    let whole = correlation::best_correlation(trace, retrace, WHOLE_FRAME_BLUR_PX)
        .filter(|o| o.margin_sigmas() >= MIN_MARGIN_SIGMAS)?;
    let lines = match fast_axis {
        Axis::Horizontal => trace.nrows(),
        Axis::Vertical => trace.ncols(),
    };
    band_shift(trace, retrace, whole.shift_px, (0, lines), fast_axis).map(|(_, s)| s)
}

/// The shift of the band of lines `range` of `current` against `previous`, searched from
/// `start` (pixels), with the band's mean pixel `(x, y)`.
fn band_shift(
    previous: &Array2<f64>,
    current: &Array2<f64>,
    start: [f64; 2],
    range: (usize, usize),
    fast_axis: Axis,
) -> Option<([f64; 2], [f64; 2])> {
    let mut whole_px = [start[0].round(), start[1].round()];
    for _ in 0..BAND_RESTARTS {
        let reference = shifted(previous, whole_px);
        let pixels: Vec<(usize, usize)> = placement::overlap(&reference, current)
            .into_iter()
            .filter(|&(r, c)| {
                let line = if fast_axis == Axis::Horizontal { r } else { c };
                (range.0..range.1).contains(&line)
            })
            .collect();
        let d = placement::image_shift_over(&reference, current, &pixels)?;
        if d[0].abs() < placement::MAX_SHIFT_PX && d[1].abs() < placement::MAX_SHIFT_PX {
            let n = pixels.len() as f64;
            let centre = pixels.iter().fold([0.0; 2], |a, &(r, c)| {
                [a[0] + c as f64 / n, a[1] + r as f64 / n]
            });
            return Some((centre, [whole_px[0] + d[0], whole_px[1] + d[1]]));
        }
        whole_px = [whole_px[0] + d[0].round(), whole_px[1] + d[1].round()];
    }
    None
}

/// `z` moved so that pixel `p` holds `z(p + shift)` (whole pixels; NaN where that is
/// outside `z`).
fn shifted(z: &Array2<f64>, shift: [f64; 2]) -> Array2<f64> {
    let (sx, sy) = (shift[0] as i64, shift[1] as i64);
    let (rows, columns) = z.dim();
    Array2::from_shape_fn((rows, columns), |(r, c)| {
        let (i, j) = (r as i64 + sy, c as i64 + sx);
        if i >= 0 && j >= 0 && (i as usize) < rows && (j as usize) < columns {
            z[[i as usize, j as usize]]
        } else {
            f64::NAN
        }
    })
}

/// The drift difference a band shows: `frame` scanned at pixel `centre` what `before`
/// scanned at `centre + shift`, so `D(later) − D(earlier)` is where the frame before's
/// controller was there less where this frame's was (instrument frame).
fn difference(
    before: &FrameImage,
    frame: &FrameImage,
    centre: [f64; 2],
    shift: [f64; 2],
) -> DriftDifference {
    let (g0, g1) = (before.geometry, frame.geometry);
    let there = [centre[0] + shift[0], centre[1] + shift[1]];
    let time = |g: &ScanGeometry, p: [f64; 2]| g.acquisition_time(ScanPass::Trace, p[0], p[1]);
    let controller =
        |g: &ScanGeometry, p: [f64; 2]| g.to_instrument([p[0] * g.pitch_x(), p[1] * g.pitch_y()]);
    let (a, b) = (controller(g0, there), controller(g1, centre));
    DriftDifference {
        later_s: frame.start_s + time(g1, centre).since_frame_start,
        earlier_s: before.start_s + time(g0, there).since_frame_start,
        difference_m: [a[0] - b[0], a[1] - b[1]],
    }
}
