//! The image view below one feature: how far each scan line's slice of a feature is
//! displaced from the feature's own fitted shape.
//!
//! A feature spans several scan lines, and its fitted centre averages the tip's
//! displacement over all of them, so an effect faster than one line pair per feature
//! (a vibration of tens of Hz, line jitter) leaves the feature *positions* nearly untouched
//! while it shears every feature line by line. Here every slice (one feature × one line)
//! gets its own displacement `d` from the image: the residual of the slice against the
//! feature's fitted 2-D Gaussian is, to first order, `∇m · d` (`m` the fitted shape; the
//! image at a pixel shows the sample at controller + `d`), solved by least squares per
//! slice. What the Gaussian does not describe of the true feature shape is the same for
//! every feature, so it is removed as the median displacement of the slices at the same
//! offset from their feature's centre. The displacements, at the slices' acquisition times,
//! go through the same Lomb–Scargle periodogram as the position residuals.
//!
//! Frames and units: displacements are metres in the display frame (x right, y down),
//! sample = controller + `d` as in the simulator; times are seconds since frame start.

use std::collections::HashMap;

use dhct_features::{Feature, FitStatus};
use dhct_scan::{Axis, ScanGeometry, ScanPass};
use ndarray::ArrayView2;
use serde::{Deserialize, Serialize};

use crate::evidence::spectrum::{
    LevelWindow, SIGNIFICANT_FALSE_ALARM, false_alarm_probability, local_maxima,
    local_noise_levels, periodogram_at, tail_false_alarm_probability,
};

/// One pass's image as the feature fits saw it but with each line's level kept
/// ([`dhct_features::signed_flattened`]: `rows × columns`, display orientation,
/// features positive) and the features found in it.
#[derive(Debug, Clone, Copy)]
pub struct PassImage<'a> {
    /// Trace or retrace.
    pub pass: ScanPass,
    /// The fitted image.
    pub image: ArrayView2<'a, f64>,
    /// Its features.
    pub features: &'a [Feature],
}

/// A periodic displacement found in the slices.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SliceVibration {
    /// Frequency, Hz.
    pub frequency_hz: f64,
    /// Peak amplitude along the scan lines (the fast axis), metres: the slices' shift.
    pub amplitude_along_m: f64,
    /// Peak amplitude across the scan lines (the slow axis), metres, when it can be read
    /// ([`SubFeatureView::across_measured`]). Approximate (within a factor of about two):
    /// it is read from how bright each line's slice is, which the line levelling of the
    /// feature fits also changes.
    pub amplitude_across_m: Option<f64>,
    /// Periods of the vibration within one scan line. Below
    /// [`MIN_PERIODS_PER_LINE_ACROSS`] each line moves across as a whole, which its slices
    /// cannot tell from the line's level, so the amplitude across is not read.
    #[serde(default)]
    pub periods_per_line: f64,
    /// Whether the frequency is a harmonic of the line-pair frequency (within two
    /// frequency resolutions): there, a displacement that varies with time cannot be told
    /// from a pattern fixed along the lines (every line pair starts at the same phase), so
    /// it is not reported as a vibration.
    #[serde(default)]
    pub raster_locked: bool,
    /// The slices' robust scatter along the lines about this sinusoid, in units of their
    /// fit noise. A vibration explains why the slices scatter; above
    /// [`MAX_SCATTER_LEFT`] something else moves them (step edges, defects, a tip that
    /// changes within features), and a peak among them is not named a vibration.
    #[serde(default)]
    pub scatter_left_along: f64,
    /// χ² reduction of one sinusoid per axis at that frequency over the local noise level
    /// of the periodogram (≈ χ²₄ under noise).
    pub power: f64,
    /// Probability that noise alone gives a peak this high anywhere in the searched band.
    pub false_alarm_probability: f64,
    /// Frequencies searched.
    pub searched: usize,
    /// How well trace and retrace agree on it: the χ² reduction of one sinusoid shared by
    /// both passes over the sum of each pass's own (1 when they see the same motion at the
    /// same times; about ½ or less for a pattern tied to the lattice rather than to time,
    /// which the two scan directions turn into different phases). `None` with one pass.
    pub pass_agreement: Option<f64>,
}

/// The most [`SliceVibration::scatter_left_along`] of a vibration reported as found: on
/// clean rendered scans the slices scatter 1.0–1.7 × their fit noise along the lines
/// (shape detail, correlated noise); beside step edges 4–16 ×.
pub const MAX_SCATTER_LEFT: f64 = 3.0;

/// The least [`SliceVibration::pass_agreement`] of a vibration reported as found.
pub const MIN_PASS_AGREEMENT: f64 = 0.75;

/// The sub-feature view of one scan.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SubFeatureView {
    /// Slices (feature × scan line) measured.
    pub slices: usize,
    /// Slices with a reading left out of the spectrum as an outlier (beyond
    /// [`OUTLIER_READING`] × their scatter along either axis: a slice beside a step edge,
    /// a defect, a tip change within a feature).
    #[serde(default)]
    pub outlier_slices: usize,
    /// Robust 1σ spread of the slice displacements about their offset medians in units of
    /// their fit uncertainty, `[x, y]`: ≈ 1 when nothing but noise moves the lines.
    pub spread_over_noise: [f64; 2],
    /// The strongest periodic displacement, when the periodogram has a peak.
    pub strongest: Option<SliceVibration>,
    /// Whether [`SubFeatureView::strongest`] is a vibration ([`SliceVibration::is_found`]).
    pub vibration_found: bool,
    /// Whether the amplitude across the lines can be read: the slices' scatter across the
    /// lines is at most [`ACROSS_SCATTER_LIMIT`] × their fit noise (line levels a model
    /// does not remove make a slice's brightness, and so its across reading, scatter far
    /// more on real files: Pb/Pt(111) 108×), and the vibration is fast enough to move
    /// within one line ([`SliceVibration::periods_per_line`]).
    #[serde(default = "measured")]
    pub across_measured: bool,
}

/// Above this scatter across the lines (in units of the slices' fit noise) the across
/// amplitude of a slice vibration is not reported.
pub const ACROSS_SCATTER_LIMIT: f64 = 10.0;

/// The least [`SliceVibration::periods_per_line`] whose amplitude across the lines is
/// read. Each line's mean displacement across is taken out with its level, which keeps
/// only what varies within the line: at one period per line most of the motion is kept;
/// at 0.1 (a 0.9 Hz vibration on 0.12 s lines) under a tenth is.
pub const MIN_PERIODS_PER_LINE_ACROSS: f64 = 1.0;

fn measured() -> bool {
    true
}

/// Slices spanning fewer pixels than this are not measured.
const MIN_SLICE_PIXELS: usize = 5;
/// Offset bins (pixels across the line) for the shape-mismatch median.
const OFFSET_BIN_PX: f64 = 0.25;
/// Bins of the feature centre's position within its pixel along the lines.
const ALONG_PHASE_BINS: f64 = 4.0;

/// One slice's displacement.
#[derive(Debug, Clone, Copy)]
struct Slice {
    /// Seconds since frame start (the slice's centre).
    time_s: f64,
    /// Displacement `[x, y]`, pixels.
    d_px: [f64; 2],
    /// Its 1σ, pixels.
    sigma_px: [f64; 2],
    /// Bin key: pass, the line's offset from the feature centre and the centre's phase
    /// within its pixel along the lines.
    bin: (bool, i64, i64),
    /// Line key: pass and line number.
    line: (bool, i64),
}

/// The fitted Gaussian of a feature: value and gradient (z units per pixel) at a pixel.
struct Shape {
    centre: [f64; 2],
    height: f64,
    /// Inverse covariance `[a, b, c]` of the Gaussian, px⁻².
    q: [f64; 3],
}

impl Shape {
    fn of(f: &Feature) -> Option<Shape> {
        let (s1, s2) = (f.sigma_major_px, f.sigma_minor_px);
        if !(s1.is_finite() && s2.is_finite() && s1 > 0.0 && s2 > 0.0 && f.amplitude.is_finite()) {
            return None;
        }
        let (sn, cs) = f.theta_rad.sin_cos();
        let (i1, i2) = (1.0 / (s1 * s1), 1.0 / (s2 * s2));
        Some(Shape {
            centre: [f.x_px, f.y_px],
            height: f.amplitude,
            q: [
                cs * cs * i1 + sn * sn * i2,
                cs * sn * (i1 - i2),
                sn * sn * i1 + cs * cs * i2,
            ],
        })
    }

    /// `(m − z0, ∂m/∂x, ∂m/∂y)` at pixel `(x, y)`.
    fn at(&self, x: f64, y: f64) -> (f64, f64, f64) {
        let (dx, dy) = (x - self.centre[0], y - self.centre[1]);
        let [a, b, c] = self.q;
        let g = self.height * (-0.5 * (a * dx * dx + 2.0 * b * dx * dy + c * dy * dy)).exp();
        (g, -g * (a * dx + b * dy), -g * (b * dx + c * dy))
    }
}

/// The sub-feature view of the given passes; `None` when too few slices can be measured
/// (fewer than 64, or no feature with a usable fit).
pub fn sub_feature_view(passes: &[PassImage], geometry: &ScanGeometry) -> Option<SubFeatureView> {
    let mut slices: Vec<Slice> = passes
        .iter()
        .flat_map(|p| pass_slices(p, geometry))
        .collect();
    if slices.len() < 64 {
        return None;
    }
    remove_line_levels(&mut slices);
    let spread_over_noise = remove_shape_mismatch(&mut slices);
    // The test is against the scatter the slices show, never a smaller one: line levels,
    // tip noise and shape detail all add to what the fits' σ accounts for.
    for s in &mut slices {
        for (sigma, spread) in s.sigma_px.iter_mut().zip(spread_over_noise) {
            if spread > 1.0 {
                *sigma *= spread;
            }
        }
    }
    let outlier_slices = drop_outlier_readings(&mut slices);
    let pitch = [geometry.pitch_x(), geometry.pitch_y()];
    let f_min = 1.0 / feature_duration_s(passes, geometry)?;
    let along_x = geometry.fast_axis() == Axis::Horizontal;
    let strongest = strongest_vibration(
        &slices,
        pitch,
        f_min,
        along_x,
        geometry.line_period(),
        spread_over_noise[usize::from(!along_x)],
    );
    let vibration_found = strongest.as_ref().is_some_and(SliceVibration::is_found);
    let across_spread = spread_over_noise[usize::from(along_x)];
    let across_measured = across_spread <= ACROSS_SCATTER_LIMIT
        && strongest
            .as_ref()
            .is_none_or(|v| v.amplitude_across_m.is_some());
    Some(SubFeatureView {
        slices: slices.len(),
        outlier_slices,
        spread_over_noise,
        strongest,
        vibration_found,
        across_measured,
    })
}

/// How long a typical feature takes to scan (its fit disc's lines × the line-pair
/// period), seconds. Slower displacements move a feature as a whole: the fitted centre
/// takes them, the positions see them, and the slices are blind to them.
fn feature_duration_s(passes: &[PassImage], geometry: &ScanGeometry) -> Option<f64> {
    let diameters = passes
        .iter()
        .flat_map(|p| p.features)
        .map(|f| 2.0 * (f.pixel_count as f64 / std::f64::consts::PI).sqrt());
    let lines = dhct_numerics::robust::finite_median(diameters)?;
    Some(lines * 2.0 * geometry.line_period()).filter(|d| *d > 0.0)
}

/// Every measurable slice of every converged feature of one pass.
fn pass_slices(p: &PassImage, geometry: &ScanGeometry) -> Vec<Slice> {
    let lines_along_x = geometry.fast_axis() == Axis::Horizontal;
    p.features
        .iter()
        .filter(|f| {
            matches!(
                f.status,
                FitStatus::Converged | FitStatus::ConvergedCircular
            )
        })
        .filter(|f| f.residual_rms.is_finite() && f.residual_rms > 0.0)
        .filter_map(|f| Shape::of(f).map(|s| (f, s)))
        .flat_map(|(f, shape)| {
            // The disc the fit used (its pixel count is its area).
            let reach = (f.pixel_count as f64 / std::f64::consts::PI).sqrt();
            let (along, across) = if lines_along_x {
                (f.x_px, f.y_px)
            } else {
                (f.y_px, f.x_px)
            };
            let lines = (across - reach).ceil() as i64..=(across + reach).floor() as i64;
            lines
                .filter_map(|line| {
                    let half = (reach * reach - (line as f64 - across).powi(2))
                        .max(0.0)
                        .sqrt();
                    let span = ((along - half).ceil() as i64, (along + half).floor() as i64);
                    let slice = measure_slice(p, geometry, f, &shape, line, span)?;
                    Some(slice)
                })
                .collect::<Vec<_>>()
        })
        .collect()
}

/// The displacement of one slice: least squares of the residual on the shape's gradient.
fn measure_slice(
    p: &PassImage,
    geometry: &ScanGeometry,
    f: &Feature,
    shape: &Shape,
    line: i64,
    span: (i64, i64),
) -> Option<Slice> {
    let (rows, columns) = p.image.dim();
    let lines_along_x = geometry.fast_axis() == Axis::Horizontal;
    let (n_lines, n_along) = if lines_along_x {
        (rows, columns)
    } else {
        (columns, rows)
    };
    if line < 0 || line as usize >= n_lines {
        return None;
    }
    let (lo, hi) = (span.0.max(0), span.1.min(n_along as i64 - 1));
    if hi - lo + 1 < MIN_SLICE_PIXELS as i64 {
        return None;
    }
    // Least squares of r = gx·dx + gy·dy. A line's level offset adds to r evenly along the
    // slice: no bias on dx (gx is odd), noise on dy.
    let mut a = nalgebra::Matrix2::<f64>::zeros();
    let mut b = nalgebra::Vector2::<f64>::zeros();
    for k in lo..=hi {
        let (x, y) = if lines_along_x {
            (k as f64, line as f64)
        } else {
            (line as f64, k as f64)
        };
        let z = p.image[[y as usize, x as usize]];
        if !z.is_finite() {
            return None;
        }
        let (m, gx, gy) = shape.at(x, y);
        let row = nalgebra::Vector2::new(gx, gy);
        a += row * row.transpose();
        b += (z - f.z0 - m) * row;
    }
    let inverse = a.try_inverse()?;
    let solution = inverse * b;
    let s = f.residual_rms;
    let (dx, dy) = (solution[0], solution[1]);
    let sigma_px = [s * inverse[(0, 0)].sqrt(), s * inverse[(1, 1)].sqrt()];
    let (cx, cy) = (f.x_px, f.y_px);
    let (tx, ty) = if lines_along_x {
        (cx, line as f64)
    } else {
        (line as f64, cy)
    };
    let along_centre = if lines_along_x { cx } else { cy };
    let offset = if lines_along_x {
        line as f64 - cy
    } else {
        line as f64 - cx
    };
    Some(Slice {
        time_s: geometry.acquisition_time(p.pass, tx, ty).since_frame_start,
        d_px: [dx, dy],
        sigma_px,
        bin: (
            p.pass == ScanPass::Trace,
            (offset / OFFSET_BIN_PX).round() as i64,
            ((along_centre - along_centre.floor()) * ALONG_PHASE_BINS).floor() as i64,
        ),
        line: (p.pass == ScanPass::Trace, line),
    })
    .filter(|s| s.d_px.iter().chain(&s.sigma_px).all(|v| v.is_finite()))
}

/// A line's level offset reads as a slow-axis displacement of every slice on it (a
/// slice's height tells its y, and so does the line's level): the slow-axis displacement
/// is taken relative to its line's weighted mean, which keeps what varies within a line
/// (faster than one line) and drops the rest. Slices alone on their line lose their y.
fn remove_line_levels(slices: &mut [Slice]) {
    let mut lines: HashMap<(bool, i64), (f64, f64, usize)> = HashMap::new();
    for s in slices.iter() {
        let w = s.sigma_px[1].powi(-2);
        let entry = lines.entry(s.line).or_insert((0.0, 0.0, 0));
        *entry = (entry.0 + w * s.d_px[1], entry.1 + w, entry.2 + 1);
    }
    for s in slices.iter_mut() {
        let (sum, weight, count) = lines[&s.line];
        if count < 2 {
            s.sigma_px[1] = f64::INFINITY;
            s.d_px[1] = 0.0;
        } else {
            s.d_px[1] -= sum / weight;
        }
    }
}

/// Subtracts, per pass and offset bin, the median displacement (what the Gaussian misses
/// of the true shape, the same for every feature); drops slices whose bin has fewer than
/// eight members or whose displacement is determined along neither axis (σ over one
/// pixel; the other axis then only gets a small weight). Returns the
/// robust spread of what is left in units of each slice's σ, per axis.
fn remove_shape_mismatch(slices: &mut Vec<Slice>) -> [f64; 2] {
    slices.retain(|s| s.sigma_px.iter().any(|v| *v < 1.0));
    let mut bins: HashMap<(bool, i64, i64), Vec<usize>> = HashMap::new();
    for (i, s) in slices.iter().enumerate() {
        bins.entry(s.bin).or_default().push(i);
    }
    let mut keep = vec![false; slices.len()];
    for members in bins.values().filter(|m| m.len() >= 8) {
        for axis in 0..2 {
            let values: Vec<f64> = members.iter().map(|&i| slices[i].d_px[axis]).collect();
            let centre =
                dhct_numerics::robust::finite_median(values.iter().copied()).unwrap_or(0.0);
            for &i in members {
                slices[i].d_px[axis] -= centre;
            }
        }
        for &i in members {
            keep[i] = true;
        }
    }
    let mut k = 0;
    slices.retain(|_| {
        k += 1;
        keep[k - 1]
    });
    std::array::from_fn(|axis| {
        let normalised: Vec<f64> = slices
            .iter()
            .filter(|s| s.sigma_px[axis].is_finite())
            .map(|s| s.d_px[axis] / s.sigma_px[axis])
            .collect();
        dhct_numerics::robust::mad_sigma(&normalised).unwrap_or(f64::NAN)
    })
}

/// A slice's reading further than this many of its (scatter-raised) σ from its offset's
/// median is left out of the spectrum. A vibration moves every slice by a few σ at most;
/// a slice beside a step edge or a defect can read tens of σ, and a few such readings, at
/// whatever times they fall, would weigh more in the spectrum than all the others. (Where
/// many slices are broken, as beside the step edges of a rendered scan that scatter 7 × 87
/// their fit noise, this is not enough: [`MAX_SCATTER_LEFT`] is what keeps a peak among
/// them from being named.)
pub const OUTLIER_READING: f64 = 5.0;

/// Leaves out of the spectrum each reading (one axis of a slice) beyond
/// [`OUTLIER_READING`] σ; returns how many slices lost a reading.
fn drop_outlier_readings(slices: &mut [Slice]) -> usize {
    let mut count = 0;
    for s in slices.iter_mut() {
        let mut dropped = false;
        for (d, sigma) in s.d_px.iter_mut().zip(s.sigma_px.iter_mut()) {
            if (*d / *sigma).abs() > OUTLIER_READING {
                *d = 0.0;
                *sigma = f64::INFINITY;
                dropped = true;
            }
        }
        count += usize::from(dropped);
    }
    count
}

/// Peaks of the periodogram tried, highest (over the local level) first.
const PEAKS_TRIED: usize = 5;

/// The strongest periodic displacement at or above `f_min` (Hz) on lines of
/// `line_period_s` seconds: of the highest periodogram peaks (over the local level), each
/// refined on a fine grid, the first that is significant, seen alike by trace and retrace
/// and not locked to the raster, else the highest.
fn strongest_vibration(
    slices: &[Slice],
    pitch_m: [f64; 2],
    f_min: f64,
    along_x: bool,
    line_period_s: f64,
    spread_along: f64,
) -> Option<SliceVibration> {
    let times: Vec<f64> = slices.iter().map(|s| s.time_s).collect();
    let weighted: Vec<f64> = slices
        .iter()
        .flat_map(|s| [s.d_px[0] / s.sigma_px[0], s.d_px[1] / s.sigma_px[1]])
        .collect();
    let p: Vec<(f64, f64)> = periodogram_at(&times, &weighted)
        .into_iter()
        .filter(|(f, _)| *f >= f_min)
        .collect();
    let levels = local_noise_levels(&p, LevelWindow::Points);
    let normalised: Vec<(f64, f64)> = p
        .iter()
        .zip(&levels)
        .map(|(&(f, power), level)| (f, power / level))
        .collect();
    let searched = p.len().div_ceil(2).max(1);
    let spectrum: Vec<f64> = normalised.iter().map(|(_, power)| *power).collect();
    let step = if p.len() > 1 { p[1].0 - p[0].0 } else { 0.0 };
    let span_s = times.iter().copied().fold(f64::NEG_INFINITY, f64::max)
        - times.iter().copied().fold(f64::INFINITY, f64::min);
    let tried: Vec<SliceVibration> = local_maxima(&normalised, PEAKS_TRIED)
        .into_iter()
        .map(|k| {
            let frequency_hz = refine_peak(slices, p[k].0, step);
            let (amplitude_px, raw_power) = sinusoid_fit(slices, frequency_hz);
            let power = raw_power / levels[k];
            let amplitude_m = [amplitude_px[0] * pitch_m[0], amplitude_px[1] * pitch_m[1]];
            let periods_per_line = frequency_hz * line_period_s;
            SliceVibration {
                frequency_hz,
                amplitude_along_m: amplitude_m[usize::from(!along_x)],
                amplitude_across_m: (periods_per_line >= MIN_PERIODS_PER_LINE_ACROSS)
                    .then_some(amplitude_m[usize::from(along_x)]),
                periods_per_line,
                raster_locked: is_raster_locked(frequency_hz, line_period_s, span_s),
                power,
                // The tail is judged on the grid's own powers, among all grid points.
                false_alarm_probability: false_alarm_probability(power, searched).max(
                    tail_false_alarm_probability(&spectrum, spectrum[k], spectrum.len())
                        .unwrap_or(0.0),
                ),
                searched,
                pass_agreement: pass_agreement(slices, frequency_hz, raw_power),
                scatter_left_along: scatter_left_along(
                    slices,
                    frequency_hz,
                    usize::from(!along_x),
                    spread_along,
                ),
            }
        })
        .collect();
    let found = tried.iter().position(SliceVibration::is_found).unwrap_or(0);
    tried.into_iter().nth(found)
}

/// Frequency resolutions (1 / the slices' time span) within which a frequency counts as
/// a harmonic of the line-pair frequency.
const RASTER_LOCK_RESOLUTIONS: f64 = 2.0;

/// Whether `f` (Hz) is a harmonic of the line-pair frequency `1 / (2 line_period_s)`,
/// within [`RASTER_LOCK_RESOLUTIONS`] of the resolution of a `span_s`-second record.
fn is_raster_locked(f: f64, line_period_s: f64, span_s: f64) -> bool {
    let pair_f = 0.5 / line_period_s;
    let harmonic = (f / pair_f).round();
    harmonic >= 1.0 && (f - harmonic * pair_f).abs() * span_s < RASTER_LOCK_RESOLUTIONS
}

impl SliceVibration {
    /// Significant ([`SIGNIFICANT_FALSE_ALARM`]), seen alike by trace and retrace
    /// ([`MIN_PASS_AGREEMENT`]), not locked to the raster
    /// ([`SliceVibration::raster_locked`]) and what explains the slices' scatter
    /// ([`MAX_SCATTER_LEFT`]). With one pass a periodic pattern cannot be told
    /// from one tied to the lattice, so nothing is found (see
    /// [`SliceVibration::is_significant`]).
    pub fn is_found(&self) -> bool {
        self.is_significant()
            && !self.raster_locked
            && self.scatter_left_along <= MAX_SCATTER_LEFT
            && self.pass_agreement.is_some_and(|a| a >= MIN_PASS_AGREEMENT)
    }

    /// Above the noise: false-alarm probability below [`SIGNIFICANT_FALSE_ALARM`].
    pub fn is_significant(&self) -> bool {
        self.false_alarm_probability < SIGNIFICANT_FALSE_ALARM
    }
}

/// [`SliceVibration::pass_agreement`] at `f` (Hz) given the joint χ² reduction.
fn pass_agreement(slices: &[Slice], f: f64, joint: f64) -> Option<f64> {
    let (trace, retrace): (Vec<Slice>, Vec<Slice>) = slices.iter().partition(|s| s.line.0);
    if trace.len() < 32 || retrace.len() < 32 {
        return None;
    }
    let separate = sinusoid_fit(&trace, f).1 + sinusoid_fit(&retrace, f).1;
    (separate > 0.0).then(|| (joint / separate).min(1.0))
}

/// The frequency within ±1 grid step of `f` (Hz) with the largest sinusoid χ² reduction.
fn refine_peak(slices: &[Slice], f: f64, step: f64) -> f64 {
    (-20..=20)
        .map(|k| f + step * k as f64 / 20.0)
        .filter(|f| *f > 0.0)
        .map(|f| (f, sinusoid_fit(slices, f).1))
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .map_or(f, |(f, _)| f)
}

/// Weighted least squares of `a·cos ωt + b·sin ωt + c` per axis: the amplitudes `√(a²+b²)`
/// (pixels) and the χ² reduction of both axes together.
fn sinusoid_fit(slices: &[Slice], f: f64) -> ([f64; 2], f64) {
    let mut amplitude = [0.0; 2];
    let mut reduction = 0.0;
    for (axis, amp) in amplitude.iter_mut().enumerate() {
        let Some((solution, b, mean_only)) = sinusoid_on_axis(slices, f, axis) else {
            continue;
        };
        *amp = solution[0].hypot(solution[1]);
        reduction += (solution.dot(&b) - mean_only).max(0.0);
    }
    (amplitude, reduction)
}

/// The weighted least squares of `[cos ωt, sin ωt, 1]` on one axis's displacements: its
/// coefficients, the right-hand side and the χ² reduction of the constant alone.
fn sinusoid_on_axis(
    slices: &[Slice],
    f: f64,
    axis: usize,
) -> Option<(nalgebra::Vector3<f64>, nalgebra::Vector3<f64>, f64)> {
    let w = std::f64::consts::TAU * f;
    let mut a = nalgebra::Matrix3::<f64>::zeros();
    let mut b = nalgebra::Vector3::<f64>::zeros();
    for s in slices {
        let (sn, cs) = (w * s.time_s).sin_cos();
        let row = nalgebra::Vector3::new(cs, sn, 1.0);
        let weight = 1.0 / (s.sigma_px[axis] * s.sigma_px[axis]);
        a += weight * row * row.transpose();
        b += weight * s.d_px[axis] * row;
    }
    let solution = a.cholesky()?.solve(&b);
    Some((solution, b, b[2] * b[2] / a[(2, 2)]))
}

/// The robust scatter of the slices along the lines (axis `along`) about the sinusoid at
/// `f` Hz, in units of their fit noise (`spread` is how far their σ were raised to the
/// scatter they showed before).
fn scatter_left_along(slices: &[Slice], f: f64, along: usize, spread: f64) -> f64 {
    let Some((c, _, _)) = sinusoid_on_axis(slices, f, along) else {
        return f64::INFINITY;
    };
    let w = std::f64::consts::TAU * f;
    let left: Vec<f64> = slices
        .iter()
        .filter(|s| s.sigma_px[along].is_finite())
        .map(|s| {
            let (sn, cs) = (w * s.time_s).sin_cos();
            (s.d_px[along] - c[0] * cs - c[1] * sn - c[2]) / s.sigma_px[along]
        })
        .collect();
    dhct_numerics::robust::mad_sigma(&left).unwrap_or(f64::INFINITY) * spread.max(1.0)
}

impl SubFeatureView {
    /// One line in plain words.
    pub fn describe(&self) -> String {
        let spread = format!(
            "slice scatter {:.2} × {:.2} (x × y) of the fit noise",
            self.spread_over_noise[0], self.spread_over_noise[1]
        );
        match (&self.strongest, self.vibration_found) {
            (Some(v), true) => format!(
                "below one feature: a vibration at {:.2} Hz moves the scan lines by {:.1} pm \
                 along {} (peak; false-alarm p {:.1e}; {} slices, {spread}); the feature \
                 positions average it out, so the corrected positions do not show it",
                v.frequency_hz,
                v.amplitude_along_m * 1e12,
                match v.amplitude_across_m.filter(|_| self.across_measured) {
                    Some(across) => format!("and about {:.0} pm across them", across * 1e12),
                    None if v.periods_per_line < MIN_PERIODS_PER_LINE_ACROSS => format!(
                        "them (across them not measured: {:.2} periods per scan line, so each \
                         line moves across as a whole, which its slices cannot tell from the \
                         line's level)",
                        v.periods_per_line
                    ),
                    None => "them (across them not measured: the slices scatter too much \
                             across the lines)"
                        .to_string(),
                },
                v.false_alarm_probability,
                self.slices
            ),
            (Some(v), false) if v.is_significant() && v.scatter_left_along > MAX_SCATTER_LEFT => {
                format!(
                    "below one feature: no vibration can be named: the slices scatter {:.1} × \
                     their fit noise along the lines beyond the strongest periodic displacement \
                     ({:.2} Hz, {:.1} pm, false-alarm p {:.1e}), so something else moves them \
                     (step edges, defects, tip changes); {} slices, {spread}",
                    v.scatter_left_along,
                    v.frequency_hz,
                    v.amplitude_along_m * 1e12,
                    v.false_alarm_probability,
                    self.slices
                )
            }
            (Some(v), false) if v.is_significant() && v.raster_locked => format!(
                "below one feature: a periodic line displacement at {:.2} Hz, {:.1} pm along the \
                 lines (false-alarm p {:.1e}; {} slices, {spread}), at a harmonic of the \
                 line-pair frequency: it cannot be told from a pattern fixed along the lines, \
                 so it is not named a vibration",
                v.frequency_hz,
                v.amplitude_along_m * 1e12,
                v.false_alarm_probability,
                self.slices
            ),
            (Some(v), false) if v.is_significant() && v.pass_agreement.is_none() => format!(
                "below one feature: a periodic line displacement at {:.2} Hz, {:.1} pm along the \
                 lines (false-alarm p {:.1e}; {} slices, {spread}), seen in one pass only: it \
                 cannot be told from a pattern tied to the lattice (a retrace would tell)",
                v.frequency_hz,
                v.amplitude_along_m * 1e12,
                v.false_alarm_probability,
                self.slices
            ),
            (Some(v), false) => format!(
                "below one feature: no periodic line displacement (strongest {:.2} Hz, \
                 {:.1} pm along the lines, false-alarm p {:.2}, trace/retrace agreement {}; \
                 {} slices, {spread})",
                v.frequency_hz,
                v.amplitude_along_m * 1e12,
                v.false_alarm_probability,
                v.pass_agreement
                    .map_or_else(|| "—".to_string(), |a| format!("{a:.2}")),
                self.slices
            ),
            (None, _) => format!(
                "below one feature: no spectrum ({} slices, {spread})",
                self.slices
            ),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn harmonics_of_the_line_pair_frequency_are_locked_to_the_raster() {
        // 0.12 s lines: line pairs at 4.1667 Hz; a 92 s record resolves 0.011 Hz.
        let (line, span) = (0.12, 92.0);
        assert!(is_raster_locked(4.1667, line, span));
        assert!(is_raster_locked(3.0 * 4.1667 + 0.01, line, span));
        assert!(!is_raster_locked(4.1667 + 0.05, line, span));
        assert!(!is_raster_locked(0.9, line, span));
        assert!(!is_raster_locked(37.0, line, span));
    }
}
