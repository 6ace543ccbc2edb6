//! The fitted model rendered forward as an image and compared with the measured image.
//!
//! The position views compare where features are with where the model puts them; this
//! view compares pixels. Each pass's *model image* is the atom as the image shows it
//! ([`dhct_features::lattice_model_image`]: the image's mean by offset from the nearest
//! centre, so whatever shape the atoms have) placed where the final model (the base fit
//! and the named effects) predicts every indexed feature. The *residual image* is the
//! measured image minus the model, each line's median taken out (line levels are the
//! feature finder's business, [`dhct_features::LineLevelling`]). What it shows:
//!
//! - **by fast phase**: its rms over the pixel noise in bins of the time since line start
//!   τ/T: where along the lines the model misses;
//! - **line by line**: each line's rms over the pixel noise against its acquisition time;
//!   runs of lines far above the rest (a tip switching between apexes, telegraph noise, a
//!   glitch) are listed as time windows; lines tilted or shifted one by one (line jitter)
//!   are read in [`crate::image_view::line_departures`];
//! - **along the lines**: the lines' mean power spectrum in Hz ([`crate::image_view::along_line`]),
//!   where a height signal faster than a feature (electrical pickup, a vibration in z),
//!   which no position sees, is told from the lattice's own lines, from a lateral
//!   vibration's sidebands and from a pattern on the sample.
//!
//! The pixel noise is the image's high-frequency content: the MAD scale of successive
//! residual differences along the lines over √2, which no slow effect can hide in.
//! Frames and units: pixels in display orientation (rows × columns), heights in the
//! image's z units, times in seconds since frame start, frequencies in Hz.

use dhct_features::{FeatureSet, lattice_model_image};
use dhct_numerics::robust::{finite_median, mad_sigma_about};
use dhct_scan::{ScanGeometry, ScanPass};
use ndarray::{Array2, ArrayView2};
use serde::{Deserialize, Serialize};

use crate::image_view::along_line::{
    AlongLinePeak, LinesSpectrum, along_line_peak, power_over_level_near, z_value,
};
use crate::image_view::line_departures::{line_shifts, line_tilt_evidence};
use crate::image_view::pass_phases::pass_phases;
use crate::report::gap::FeatureResidual;

/// Bins of the fast phase τ/T.
pub const FAST_PHASE_BINS: usize = 16;

/// A line is in excess when its rms over the pixel noise exceeds the lines' median by this
/// many robust spreads (MAD scale) and by [`EXCESS_LINE_FACTOR`].
pub const EXCESS_LINE_SPREADS: f64 = 6.0;

/// … and is above the lines' median rms by at least this factor.
pub const EXCESS_LINE_FACTOR: f64 = 1.5;

/// The [`PassResidual::line_tilt_evidence`] above which the lines are said to tilt one by
/// one (the line levels' own evidence threshold, [`dhct_features::LineLevelling`]).
pub const LINE_TILT_EVIDENCE: f64 = 4.0;

/// The [`PassResidual::line_shifts_over_noise`] above which the lines are said to jitter.
pub const LINE_JITTER_EVIDENCE: f64 = 4.0;

/// Most excess-line windows listed.
const MAX_WINDOWS: usize = 8;

/// The residual image of one pass.
#[derive(Debug, Clone)]
pub struct ResidualImage {
    /// Trace or retrace.
    pub pass: ScanPass,
    /// Measured minus model, each line's median removed (`rows × columns`, display
    /// orientation, z units; NaN where no predicted site is within reach).
    pub residual: Array2<f64>,
    /// Its summary.
    pub summary: PassResidual,
    /// Its lines' mean power spectrum (the other pass reads the peak's bin from it).
    spectrum: Option<LinesSpectrum>,
}

/// What the residual image of one pass shows.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PassResidual {
    /// Trace or retrace.
    pub pass: ScanPass,
    /// The image's z unit (SI, e.g. "m").
    pub z_unit: String,
    /// Pixel noise, z units: the MAD scale of successive residual differences along the
    /// lines over √2.
    pub pixel_noise: f64,
    /// RMS of the residual image over the pixel noise: about 1 when the model explains
    /// every pixel; above it where the atoms differ from their mean shape, where the model
    /// puts them wrongly, or where the image holds something else.
    pub rms_over_noise: f64,
    /// RMS over the pixel noise in [`FAST_PHASE_BINS`] equal bins of the fast phase τ/T
    /// (0 = line start); `None` for a bin with no modelled pixel.
    pub by_fast_phase: Vec<Option<f64>>,
    /// Lines whose rms is in excess ([`EXCESS_LINE_SPREADS`], [`EXCESS_LINE_FACTOR`]).
    pub excess_lines: usize,
    /// Lines compared.
    pub lines: usize,
    /// The longest runs of excess lines (at most eight), longest first.
    pub excess_windows: Vec<LineWindow>,
    /// How much more the lines' slopes along themselves vary from line to line than their
    /// quadratic and cubic shapes do (robust variances of the orthonormal parts): about 1
    /// for white noise, a little more for noise that rises to low frequencies; above
    /// [`LINE_TILT_EVIDENCE`] the lines tilt one by one, which `line_correction = "linear"`
    /// levels. `None` with too few lines.
    #[serde(default)]
    pub line_tilt_evidence: Option<f64>,
    /// How much the lines' shifts along themselves (each line's residual against the
    /// model's gradient) differ from one line to the next over what the pixel noise gives:
    /// about 1 without line jitter; above [`LINE_JITTER_EVIDENCE`] the lines jitter. What
    /// consecutive lines share (the features' own position errors, slow motion) is left out.
    /// `None` with too few lines.
    #[serde(default)]
    pub line_shifts_over_noise: Option<f64>,
    /// The rms of those shifts beyond the noise, metres along the lines (0 when there is
    /// none beyond it).
    #[serde(default)]
    pub line_jitter_m: Option<f64>,
    /// The strongest peak of the along-line spectrum, when it has one.
    pub along_line: Option<AlongLinePeak>,
}

/// A run of consecutive lines whose residual is in excess.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LineWindow {
    /// Start of its first line, seconds since frame start.
    pub start_s: f64,
    /// End of its last line, seconds since frame start.
    pub end_s: f64,
    /// Lines in it.
    pub lines: usize,
    /// Their mean rms over the pixel noise.
    pub rms_over_noise: f64,
}

impl PassResidual {
    /// One line of text: how far the image departs from the model, where, and what the
    /// lines' spectrum shows.
    pub fn describe(&self) -> String {
        let bin = |v: Option<&Option<f64>>| match v {
            Some(Some(v)) => format!("{v:.2} ×"),
            _ => "—".to_string(),
        };
        let mut s = format!(
            "{}: rms {:.2} × the pixel noise ({}); {} at the line start, {} at the end",
            self.pass,
            self.rms_over_noise,
            z_value(self.pixel_noise, &self.z_unit),
            bin(self.by_fast_phase.first()),
            bin(self.by_fast_phase.last()),
        );
        match self.excess_windows.first() {
            Some(w) => s.push_str(&format!(
                "; {} of {} lines depart far more than the rest, the longest run {:.2}–{:.2} s \
                 ({} line{}, {:.1} ×)",
                self.excess_lines,
                self.lines,
                w.start_s,
                w.end_s,
                w.lines,
                if w.lines == 1 { "" } else { "s" },
                w.rms_over_noise
            )),
            None => s.push_str("; no line departs far more than the rest"),
        }
        if let Some(tilt) = self.line_tilt_evidence {
            s.push_str(&format!(
                "; line slopes vary {tilt:.1} × as much as their curvatures{}",
                if tilt > LINE_TILT_EVIDENCE {
                    " (the lines tilt one by one: line_correction = \"linear\" levels each \
                     line's slope)"
                } else {
                    ""
                }
            ));
        }
        if let (Some(over), Some(jitter)) = (self.line_shifts_over_noise, self.line_jitter_m) {
            s.push_str(&format!(
                "; line shifts vary {over:.1} × what the pixel noise gives{}",
                if over > LINE_JITTER_EVIDENCE {
                    format!(" (the lines jitter: {} rms)", z_value(jitter, "m"))
                } else {
                    String::new()
                }
            ));
        }
        if let Some(peak) = &self.along_line {
            s.push_str(&format!(
                "; along the lines: {}",
                peak.describe(&self.z_unit)
            ));
        }
        s
    }
}

/// The residual images of the passes `sets` were found in, `images` their signed,
/// flattened images ([`dhct_features::signed_flattened`]) and z units in the same order, with the
/// sites predicted by the final model of `residuals`; `neighbour_distance_m` the lattice's
/// nearest-neighbour distance. A pass with fewer than 16 predicted sites, or whose pixel
/// noise cannot be told, is left out.
pub fn residual_images(
    sets: &[&FeatureSet],
    images: &[(ArrayView2<f64>, &str)],
    residuals: &[FeatureResidual],
    geometry: &ScanGeometry,
    neighbour_distance_m: f64,
) -> Vec<ResidualImage> {
    let nn_px = neighbour_distance_m / (0.5 * (geometry.pitch_x() + geometry.pitch_y()));
    let mut residuals: Vec<ResidualImage> = sets
        .iter()
        .zip(images)
        .filter_map(|(set, (image, unit))| {
            let centres = predicted_centres(set.pass, residuals, geometry);
            if centres.len() < 16 || !(nn_px.is_finite() && nn_px > 1.0) {
                return None;
            }
            let model = lattice_model_image(*image, &centres, nn_px);
            let mut residual = pass_residual(set.pass, *image, &model, geometry)?;
            residual.summary.z_unit = unit.to_string();
            Some(residual)
        })
        .collect();
    if let [a, b] = residuals.as_mut_slice() {
        compare_passes(a, b, geometry);
    }
    residuals
}

/// Sets each pass's along-line peak's [`AlongLinePeak::phases`] and
/// [`AlongLinePeak::other_pass_power_over_level`] from the two passes' residual images.
fn compare_passes(a: &mut ResidualImage, b: &mut ResidualImage, geometry: &ScanGeometry) {
    let lines_a = display_lines(&a.residual, geometry);
    let lines_b = display_lines(&b.residual, geometry);
    let views_a: Vec<&[f64]> = lines_a.iter().map(Vec::as_slice).collect();
    let views_b: Vec<&[f64]> = lines_b.iter().map(Vec::as_slice).collect();
    let (trace, retrace) = match a.pass {
        ScanPass::Trace => (&views_a, &views_b),
        ScanPass::Retrace => (&views_b, &views_a),
    };
    let (spectrum_a, spectrum_b) = (a.spectrum.clone(), b.spectrum.clone());
    for (image, other) in [(&mut *a, spectrum_b), (&mut *b, spectrum_a)] {
        if let Some(peak) = image.summary.along_line.as_mut() {
            peak.phases = pass_phases(trace, retrace, peak.bin[0]);
            peak.other_pass_power_over_level = other
                .as_ref()
                .and_then(|spectrum| power_over_level_near(spectrum, peak.bin[0]));
        }
    }
}

/// The lines of `image` in display orientation (rows when the fast axis is horizontal):
/// the same pixel at the same index in trace and retrace.
fn display_lines(image: &Array2<f64>, geometry: &ScanGeometry) -> Vec<Vec<f64>> {
    match geometry.fast_axis() {
        dhct_scan::Axis::Horizontal => image.rows().into_iter().map(|r| r.to_vec()).collect(),
        dhct_scan::Axis::Vertical => image.columns().into_iter().map(|c| c.to_vec()).collect(),
    }
}

/// Where the final model puts every indexed feature of `pass`: `(x, y)` px.
fn predicted_centres(
    pass: ScanPass,
    residuals: &[FeatureResidual],
    geometry: &ScanGeometry,
) -> Vec<[f64; 2]> {
    residuals
        .iter()
        .filter(|r| r.pass == pass && !r.outlier)
        .map(|r| {
            [
                (r.controller_m[0] - r.final_m[0]) / geometry.pitch_x(),
                (r.controller_m[1] - r.final_m[1]) / geometry.pitch_y(),
            ]
        })
        .filter(|c| c[0].is_finite() && c[1].is_finite())
        .collect()
}

/// One scan line of an image in acquisition order.
struct Line {
    /// Seconds since frame start of its first pixel.
    start_s: f64,
    /// Values in acquisition order.
    values: Vec<f64>,
}

/// The lines of `image` in `pass`, each in acquisition order.
fn lines_of(image: &Array2<f64>, pass: ScanPass, geometry: &ScanGeometry) -> Vec<Line> {
    (0..geometry.slow_len())
        .map(|slow| {
            let values = (0..geometry.fast_len())
                .map(|fast| {
                    let (x, y) = geometry.position_of(pass, fast as f64, slow as f64);
                    image[[y as usize, x as usize]]
                })
                .collect();
            let (x, y) = geometry.position_of(pass, 0.0, slow as f64);
            let start_s = geometry.acquisition_time(pass, x, y).since_frame_start
                - 0.5 * geometry.pixel_period();
            Line { start_s, values }
        })
        .collect()
}

/// The residual of one pass and its summary; `None` when its pixel noise cannot be told
/// (no two neighbouring modelled pixels).
fn pass_residual(
    pass: ScanPass,
    image: ArrayView2<f64>,
    model: &Array2<f64>,
    geometry: &ScanGeometry,
) -> Option<ResidualImage> {
    let mut residual = model.clone();
    residual.zip_mut_with(&image, |m, z| *m = z - *m);
    remove_line_medians(&mut residual, geometry);
    let lines = lines_of(&residual, pass, geometry);
    let pixel_noise = Some(pixel_noise(&lines)).filter(|s| s.is_finite() && *s > 0.0)?;
    let line_rms: Vec<f64> = lines.iter().map(|l| rms(&l.values) / pixel_noise).collect();
    let rms_over_noise = rms(&residual) / pixel_noise;
    let (excess_lines, excess_windows) = excess_windows(&lines, &line_rms, geometry);
    let model_lines = lines_of(model, pass, geometry);
    let residual_lines: Vec<&[f64]> = lines.iter().map(|l| l.values.as_slice()).collect();
    let model_lines: Vec<&[f64]> = model_lines.iter().map(|l| l.values.as_slice()).collect();
    let shifts = line_shifts(&residual_lines, &model_lines, pixel_noise);
    let spectrum = LinesSpectrum::of(&residual_lines);
    let summary = PassResidual {
        pass,
        z_unit: String::new(),
        pixel_noise,
        rms_over_noise,
        by_fast_phase: by_fast_phase(&lines, pixel_noise),
        excess_lines,
        lines: lines.len(),
        excess_windows,
        line_tilt_evidence: line_tilt_evidence(&residual_lines),
        line_shifts_over_noise: shifts.map(|s| s.0),
        line_jitter_m: shifts.map(|s| s.1 * geometry.fast_pitch()),
        along_line: spectrum
            .as_ref()
            .and_then(|spectrum| along_line_peak(spectrum, &model_lines, geometry.pixel_period())),
    };
    Some(ResidualImage {
        pass,
        residual,
        summary,
        spectrum,
    })
}

/// Takes each scan line's median out of `residual` (a line's pixels are a row when the
/// fast axis is horizontal, else a column, whichever the pass's direction).
fn remove_line_medians(residual: &mut Array2<f64>, geometry: &ScanGeometry) {
    let along = match geometry.fast_axis() {
        dhct_scan::Axis::Horizontal => ndarray::Axis(1),
        dhct_scan::Axis::Vertical => ndarray::Axis(0),
    };
    for mut line in residual.lanes_mut(along) {
        if let Some(level) = finite_median(line.iter().copied()) {
            line.iter_mut().for_each(|v| *v -= level);
        }
    }
}

/// RMS of the finite values (NaN if none).
fn rms<'a>(values: impl IntoIterator<Item = &'a f64>) -> f64 {
    let (sum, n) = values
        .into_iter()
        .filter(|v| v.is_finite())
        .fold((0.0, 0usize), |(s, n), v| (s + v * v, n + 1));
    if n == 0 {
        f64::NAN
    } else {
        (sum / n as f64).sqrt()
    }
}

/// The MAD scale of successive differences along the lines over √2 (NaN if none).
fn pixel_noise(lines: &[Line]) -> f64 {
    let differences: Vec<f64> = lines
        .iter()
        .flat_map(|l| l.values.windows(2).map(|w| w[1] - w[0]))
        .filter(|d| d.is_finite())
        .collect();
    mad_sigma_about(&differences, 0.0).map_or(f64::NAN, |s| s / std::f64::consts::SQRT_2)
}

/// RMS over `noise` in [`FAST_PHASE_BINS`] bins of the position along the lines.
fn by_fast_phase(lines: &[Line], noise: f64) -> Vec<Option<f64>> {
    let length = lines.first().map_or(0, |l| l.values.len());
    (0..FAST_PHASE_BINS)
        .map(|b| {
            let (lo, hi) = (
                b * length / FAST_PHASE_BINS,
                (b + 1) * length / FAST_PHASE_BINS,
            );
            let values: Vec<f64> = lines
                .iter()
                .flat_map(|l| l.values[lo..hi].iter().copied())
                .collect();
            Some(rms(&values) / noise).filter(|v| v.is_finite())
        })
        .collect()
}

/// Lines in excess and their longest runs (consecutive lines).
fn excess_windows(
    lines: &[Line],
    line_rms: &[f64],
    geometry: &ScanGeometry,
) -> (usize, Vec<LineWindow>) {
    let finite: Vec<f64> = line_rms.iter().copied().filter(|v| v.is_finite()).collect();
    let (Some(median), Some(spread)) = (
        finite_median(finite.iter().copied()),
        dhct_numerics::robust::mad_sigma(&finite),
    ) else {
        return (0, Vec::new());
    };
    let threshold = (median + EXCESS_LINE_SPREADS * spread).max(EXCESS_LINE_FACTOR * median);
    let excess: Vec<bool> = line_rms.iter().map(|v| *v > threshold).collect();
    let mut windows = Vec::new();
    let mut k = 0;
    while k < excess.len() {
        if !excess[k] {
            k += 1;
            continue;
        }
        let start = k;
        while k < excess.len() && excess[k] {
            k += 1;
        }
        let run = &line_rms[start..k];
        windows.push(LineWindow {
            start_s: lines[start].start_s,
            end_s: lines[k - 1].start_s + geometry.line_scan_time(),
            lines: k - start,
            rms_over_noise: run.iter().sum::<f64>() / run.len() as f64,
        });
    }
    let count = excess.iter().filter(|e| **e).count();
    windows.sort_by(|a, b| b.lines.cmp(&a.lines).then(a.start_s.total_cmp(&b.start_s)));
    windows.truncate(MAX_WINDOWS);
    (count, windows)
}
