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
