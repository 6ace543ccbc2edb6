//! Errors of the chain, each naming the stage that failed and what to try.

use dhct_distortion::DistortionError;
use dhct_features::{FeatureError, Polarity};
use dhct_lattice::{LatticeError, LatticeFitError};
use dhct_unitcell::UnitCellError;
use thiserror::Error;

/// Everything that can stop [`crate::run`].
#[derive(Debug, Error)]
pub enum PipelineError {
    /// Finding or fitting the features failed.
    #[error("feature finding: {0}")]
    Features(#[from] FeatureError),
    /// Too few features were found to analyse the lattice.
    #[error(
        "only {found} features found in the {pass} image (at least {needed} needed){}: \
         check the nearest-neighbour distance, the features' polarity, and that the image is \
         atomically resolved",
        opposite_note(*.opposite_polarity)
    )]
    TooFewFeatures {
        /// Which image.
        pass: String,
        /// How many were found.
        found: usize,
        /// How many are needed.
        needed: usize,
        /// When the image's features of the other polarity (minima for bright atoms,
        /// maxima for dark) are enough: that polarity and how many it gives.
        opposite_polarity: Option<(Polarity, usize)>,
    },
    /// Features were found but too few sit in the lattice's neighbour pattern.
    #[error(
        "only {usable} of {found} features have the lattice's full nearest-neighbour shell, \
         at least {needed} needed. The features found are typically {:.3} Å apart while the \
         lattice's nearest-neighbour distance is {:.3} Å{suggestion}",
        .median_nn_m * 1e10,
        .expected_nn_m * 1e10
    )]
    LatticeMismatch {
        /// Features found (trace).
        found: usize,
        /// Features with a full NN shell.
        usable: usize,
        /// Needed for the model fit.
        needed: usize,
        /// Median distance from each found feature to its nearest other feature, metres.
        median_nn_m: f64,
        /// The lattice's NN distance, metres.
        expected_nn_m: f64,
        /// What to try.
        suggestion: String,
    },
    /// The distortion model could not be fitted.
    #[error("distortion model: {0}")]
    Distortion(#[from] DistortionError),
    /// The lattice (its constant or shape) is invalid.
    #[error("lattice: {0}")]
    Lattice(#[from] LatticeError),
    /// No region could be indexed by the whole-image lattice fit.
    #[error(
        "lattice fit: no region could be indexed ({0}); check the lattice type and its \
         nearest-neighbour distance, or restrict the analysis to one domain with a mask"
    )]
    LatticeFit(LatticeFitError),
    /// The unit-cell analysis failed.
    #[error("unit cells: {0}")]
    UnitCell(#[from] UnitCellError),
    /// The mask does not match the image.
    #[error("the mask is {mask_columns} x {mask_rows} px but the image is {columns} x {rows} px")]
    MaskShape {
        /// Mask width.
        mask_columns: usize,
        /// Mask height.
        mask_rows: usize,
        /// Image width.
        columns: usize,
        /// Image height.
        rows: usize,
    },
    /// The mask selects no pixel.
    #[error("the mask selects no pixel (is it inverted?)")]
    EmptyMask,
    /// The lattice or its constant cannot be what the image shows (measured from the
    /// image's Fourier transform before any feature is found).
    #[error("{0}")]
    Calibration(Box<dhct_calibrate::CalibrationError>),
    /// Every corrected image shows the lattice at one other scale than the lattice given,
    /// the same along x and y: the constant given is not the image's (the calibration
    /// matched the image's peaks as other orders of the lattice given).
    #[error(
        "every corrected image shows the {lattice} lattice {:.1} % as large as given ({}): its \
         nearest-neighbour distance in them is {} where {} was given, so the constant given \
         is not the one the image shows (its peaks were matched as other orders of the \
         lattice given)",
        100.0 * .scale,
        .passes.join(", "),
        dhct_calibrate::length(.given_nn_m * .scale),
        dhct_calibrate::length(*.given_nn_m)
    )]
    CorrectedScale {
        /// The lattice given.
        lattice: String,
        /// Its nearest-neighbour distance as given, metres.
        given_nn_m: f64,
        /// The scale every corrected image shows it at (shown / given; mean of x and y).
        scale: f64,
        /// Each pass's measurement, in words ("trace 70.72 % × 70.70 %").
        passes: Vec<String>,
    },
    /// An option is out of range.
    #[error("invalid option: {0}")]
    BadOption(String),
}

/// "; its minima give 41 features (the atoms may appear dark)" or nothing.
fn opposite_note(opposite: Option<(Polarity, usize)>) -> String {
    match opposite {
        Some((Polarity::Dark, n)) => {
            format!("; its minima give {n} features (the atoms may appear dark)")
        }
        Some((Polarity::Bright, n)) => {
            format!("; its maxima give {n} features (the atoms may appear bright)")
        }
        None => String::new(),
    }
}
