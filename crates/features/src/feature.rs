//! The feature table: every fitted feature with position, shape, uncertainty and time.

use std::io::Write;

use dhct_scan::ScanPass;
use serde::{Deserialize, Serialize};

use crate::{FitStatus, LineLevelling};

/// One fitted feature. Positions are in the controller frame of its image (display
/// orientation; x = column, y = row; metres = px · pitch).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Feature {
    /// Index within its feature set.
    pub id: usize,
    /// Image the feature was found in.
    pub pass: ScanPass,
    /// Fitted centre x (column), pixels (sub-pixel).
    pub x_px: f64,
    /// Fitted centre y (row), pixels (sub-pixel).
    pub y_px: f64,
    /// Fitted centre x, metres.
    pub x_m: f64,
    /// Fitted centre y, metres.
    pub y_m: f64,
    /// 1σ uncertainty of the centre x from the fit covariance, pixels.
    pub x_sigma_px: f64,
    /// 1σ uncertainty of the centre y from the fit covariance, pixels.
    pub y_sigma_px: f64,
    /// Gaussian width along the major axis, pixels (major ≥ minor).
    pub sigma_major_px: f64,
    /// Gaussian width along the minor axis, pixels.
    pub sigma_minor_px: f64,
    /// Angle of the major axis from +x towards +y (display frame), radians.
    pub theta_rad: f64,
    /// Fitted Gaussian amplitude, z units, positive for the chosen polarity.
    pub amplitude: f64,
    /// Signed apparent height (z units): +amplitude for bright, −amplitude for dark features.
    pub height: f64,
    /// Fitted background level z0, z units (of the image the fit saw: after the line
    /// levelling).
    pub z0: f64,
    /// What the lattice line levelling subtracted at the centre before the fit (line
    /// offsets and the height steps a line crosses), z units: `z0 + removed_level` is the
    /// local background as recorded (less the background surface). 0 when the lines were
    /// not levelled against the lattice.
    #[serde(default)]
    pub removed_level: f64,
    /// RMS residual of the fit, z units.
    pub residual_rms: f64,
    /// Pixels in the fitted region.
    pub pixel_count: usize,
    /// Peak normalised cross-correlation of the region.
    pub ncc_peak: f64,
    /// How the Gaussian fit ended.
    pub status: FitStatus,
    /// Levenberg–Marquardt iterations the fit took.
    pub fit_iterations: usize,
    /// Acquisition time since frame start, seconds (from the sub-pixel centre).
    pub time_s: f64,
    /// Time since the start of the feature's scan line, seconds.
    pub line_time_s: f64,
}

/// Why a candidate region did not become a feature.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Rejection {
    /// Region area below median/√10.
    AreaTooSmall,
    /// Region area above median·√10.
    AreaTooLarge,
    /// The fit failed (too few pixels, singular, non-finite).
    FitFailed,
    /// The centre ran onto the bound of its region: not a feature here.
    CentreOnBound,
    /// Width or amplitude at its bound: not feature-shaped.
    BadShape,
    /// Centre closer to the image border than the kernel radius.
    EdgeCut,
    /// Another fit of the same feature was kept.
    Duplicate,
    /// Shallower than the options' `min_relative_height` of the deepest features allow.
    TooShallow,
    /// The fit window straddles a height step (a terrace edge or a tip change within a
    /// line): the Gaussian with a constant background cannot follow it, so the centre is
    /// not where the atom is.
    OnStep,
}

/// A candidate region that was not accepted, with where it was and why.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RejectedCandidate {
    /// Where the candidate was, x (column), pixels.
    pub x_px: f64,
    /// Where the candidate was, y (row), pixels.
    pub y_px: f64,
    /// Why it was rejected.
    pub reason: Rejection,
}

/// Counts of rejected candidates by reason.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct RejectionCounts {
    /// [`Rejection::AreaTooSmall`].
    pub area_too_small: usize,
    /// [`Rejection::AreaTooLarge`].
    pub area_too_large: usize,
    /// [`Rejection::FitFailed`].
    pub fit_failed: usize,
    /// [`Rejection::CentreOnBound`].
    pub centre_on_bound: usize,
    /// [`Rejection::BadShape`].
    pub bad_shape: usize,
    /// [`Rejection::EdgeCut`].
    pub edge_cut: usize,
    /// [`Rejection::Duplicate`].
    pub duplicate: usize,
    /// [`Rejection::TooShallow`].
    #[serde(default)]
    pub too_shallow: usize,
    /// [`Rejection::OnStep`].
    #[serde(default)]
    pub on_step: usize,
}

impl RejectionCounts {
    /// Counts the reasons in `rejected`.
    pub fn of(rejected: &[RejectedCandidate]) -> RejectionCounts {
        let mut counts = RejectionCounts::default();
        for r in rejected {
            *match r.reason {
                Rejection::AreaTooSmall => &mut counts.area_too_small,
                Rejection::AreaTooLarge => &mut counts.area_too_large,
                Rejection::FitFailed => &mut counts.fit_failed,
                Rejection::CentreOnBound => &mut counts.centre_on_bound,
                Rejection::BadShape => &mut counts.bad_shape,
                Rejection::EdgeCut => &mut counts.edge_cut,
                Rejection::Duplicate => &mut counts.duplicate,
                Rejection::TooShallow => &mut counts.too_shallow,
                Rejection::OnStep => &mut counts.on_step,
            } += 1;
        }
        counts
    }

    /// Total number rejected.
    pub fn total(&self) -> usize {
        self.area_too_small
            + self.area_too_large
            + self.fit_failed
            + self.centre_on_bound
            + self.bad_shape
            + self.edge_cut
            + self.duplicate
            + self.too_shallow
            + self.on_step
    }
}

impl std::fmt::Display for RejectionCounts {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} area too small, {} area too large, {} fit failed, {} centre on bound, \
             {} bad shape, {} edge-cut, {} duplicate, {} too shallow, {} on a step",
            self.area_too_small,
            self.area_too_large,
            self.fit_failed,
            self.centre_on_bound,
            self.bad_shape,
            self.edge_cut,
            self.duplicate,
            self.too_shallow,
            self.on_step
        )
    }
}

/// Wall-clock time spent in each stage of [`crate::find_features`], seconds.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct StageTimings {
    /// Line correction and background removal.
    pub preprocess_s: f64,
    /// Normalised cross-correlation.
    pub correlation_s: f64,
    /// Watershed and area filter.
    pub segmentation_s: f64,
    /// Gaussian fits.
    pub fitting_s: f64,
    /// Edge and duplicate checks, times, table.
    pub bookkeeping_s: f64,
}

/// All features of one image, with what was rejected and why.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FeatureSet {
    /// The image the features were found in: trace or retrace.
    pub pass: ScanPass,
    /// Accepted features, ordered by acquisition time.
    pub features: Vec<Feature>,
    /// Candidate regions that were not accepted.
    pub rejected: Vec<RejectedCandidate>,
    /// Number of watershed regions above the threshold.
    pub candidates: usize,
    /// σ of the correlation kernel used, pixels (NaN for a custom kernel).
    pub kernel_sigma_px: f64,
    /// Factor per axis `[x, y]` by which the fits' centre uncertainties were raised
    /// because the pixel noise is correlated (measured on the image minus the lattice
    /// model; 1 where the noise is white or it could not be measured).
    #[serde(default = "unit_factors")]
    pub correlated_noise_factor: [f64; 2],
    /// How the scan lines were levelled before the fits, and on what evidence.
    #[serde(default)]
    pub line_levelling: LineLevelling,
    /// Time spent per stage (for benchmarks and reports; not deterministic).
    pub timings: StageTimings,
}

fn unit_factors() -> [f64; 2] {
    [1.0; 2]
}

impl FeatureSet {
    /// Counts of rejected candidates by reason.
    pub fn rejection_counts(&self) -> RejectionCounts {
        RejectionCounts::of(&self.rejected)
    }

    /// Writes the whole set (features, rejections with reasons, kernel, timings) as JSON.
    pub fn write_json<W: Write>(&self, w: &mut W) -> std::io::Result<()> {
        serde_json::to_writer_pretty(&mut *w, self).map_err(std::io::Error::other)?;
        writeln!(w)
    }
}
