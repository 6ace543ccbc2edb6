//! Typed errors of the diagnosis.

use thiserror::Error;

/// Everything that can stop a diagnosis or a validation run.
#[derive(Debug, Error)]
pub enum DiagnoseError {
    /// Too few usable features for the step named.
    #[error(
        "too few features for the {what}: {found} usable, at least {needed} needed (check the \
         lattice, its constant and the feature finding)"
    )]
    TooFewFeatures {
        /// Which step.
        what: &'static str,
        /// How many were usable.
        found: usize,
        /// How many are needed.
        needed: usize,
    },
    /// A feature has a non-finite position or time.
    #[error("feature {index} of set {set} has a non-finite {what}")]
    NotFinite {
        /// Index of the feature set.
        set: usize,
        /// Index within the set.
        index: usize,
        /// Which quantity.
        what: &'static str,
    },
    /// An option is out of range.
    #[error("invalid option {name}: {reason}")]
    BadOption {
        /// The option.
        name: &'static str,
        /// Why.
        reason: String,
    },
    /// The base DHCT fit failed.
    #[error("the base DHCT fit failed: {0}")]
    Distortion(#[from] dhct_distortion::DistortionError),
    /// The lattice could not be fitted to the corrected features.
    #[error("the lattice fit to the corrected features failed: {0}")]
    Lattice(#[from] dhct_lattice::LatticeFitError),
    /// A simulation (validation) failed.
    #[error("simulation failed: {0}")]
    Simulation(#[from] dhct_simulate::SimulationError),
    /// Feature finding (validation, full image path) failed.
    #[error("feature finding failed: {0}")]
    Features(#[from] dhct_features::FeatureError),
    /// The position-level least-squares fit produced no finite solution.
    #[error("the position-level fit of {model} failed: {reason}")]
    FitFailed {
        /// Which model.
        model: String,
        /// Why.
        reason: String,
    },
}
