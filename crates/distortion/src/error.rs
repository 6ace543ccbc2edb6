//! Typed errors of the distortion pipeline.

use thiserror::Error;

/// Everything that can go wrong in neighbour analysis, the model fit or the correction.
#[derive(Debug, Error)]
pub enum DistortionError {
    /// Too few features survived selection to fit the model.
    #[error(
        "too few features to fit the {what}: {found} usable, at least {needed} needed \
         (check the lattice choice and its constant, the NN window, the mask, and that \
         the feature finder found the atoms)"
    )]
    TooFewFeatures {
        /// Which fit or step.
        what: &'static str,
        /// How many were usable.
        found: usize,
        /// How many are needed.
        needed: usize,
    },
    /// A least-squares fit did not produce finite parameters.
    #[error("the {0} fit failed to converge to finite parameters")]
    FitFailed(&'static str),
    /// A mask or image does not match the scan geometry.
    #[error(
        "{what} is {columns} x {rows} px but the scan geometry is {geometry_columns} x {geometry_rows} px"
    )]
    ShapeMismatch {
        /// What was given.
        what: &'static str,
        /// Its width.
        columns: usize,
        /// Its height.
        rows: usize,
        /// The geometry's width.
        geometry_columns: usize,
        /// The geometry's height.
        geometry_rows: usize,
    },
    /// The features could not be indexed against the lattice for the global registration.
    #[error("the features cannot be indexed for the global registration: {0}")]
    Indexing(#[source] dhct_lattice::LatticeFitError),
    /// The series' one model leaves a frame's features much farther off their sites than
    /// the frame's own model does: the frames were not placed right (a lattice period off)
    /// or the session is not one continuous drift.
    #[error(
        "the series model does not explain frame {frame}: its features lie {series_pm:.1} pm \
         rms off their sites against {own_pm:.1} pm with the frame's own model (more than \
         {limit}×). The frame was likely placed a lattice period off: the drift carried from \
         the frame before was wrong by half a period or more (a slow-axis pixel-size error \
         looks like a drift within one frame and is carried as error × frame height), or the \
         drift is not continuous there (a move the headers do not record, a tip change). \
         Fit the frames before and after it as separate series, or correct the scanner's \
         calibration first"
    )]
    SeriesNotExplained {
        /// The frame (time order).
        frame: usize,
        /// Its features' RMS deviation under the series model, picometres.
        series_pm: f64,
        /// Under its own single-frame model, picometres.
        own_pm: f64,
        /// The largest ratio accepted.
        limit: f64,
    },
    /// The series fit ended at a scanner y gain no scanner has (a mirrored or collapsed
    /// slow axis traded against a drift near the slow-scan speed).
    #[error(
        "the series fit ended at a scanner y gain of {gain:.3} relative to x, outside \
         {low}…{high}: a drift near the slow-scan speed traded against the slow axis, not a \
         scanner. The frames' placement or timing is likely wrong; check the frames' start \
         times and scan directions, or fit fewer frames"
    )]
    ImplausibleGain {
        /// The gain fitted.
        gain: f64,
        /// The lowest gain accepted.
        low: f64,
        /// The highest gain accepted.
        high: f64,
    },
    /// An argument is out of range.
    #[error("invalid parameter: {0}")]
    BadParameter(String),
    /// The corrected image of the whole scan would be far larger than the scan: the model
    /// moves pixels further than a frame (not a drift a scan shows).
    #[error(
        "the corrected image of every pixel would be {columns} x {rows} px, more than \
         {limit} times the scan's {scan_columns} x {scan_rows}: the model moves pixels \
         further than a frame"
    )]
    ExtentTooLarge {
        /// Columns the extent needs.
        columns: usize,
        /// Rows the extent needs.
        rows: usize,
        /// The scan's columns.
        scan_columns: usize,
        /// The scan's rows.
        scan_rows: usize,
        /// The largest growth per side allowed.
        limit: usize,
    },
}
