//! The stages of [`crate::run`], for progress reporting, and their wall times.

use serde::{Deserialize, Serialize};

/// Wall time of each stage, seconds.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct StageTimings {
    /// Measuring the lattice the images show (Fourier transform) and checking the inputs.
    #[serde(default)]
    pub calibration_s: f64,
    /// Feature finding and fitting (both images).
    pub features_s: f64,
    /// Neighbours, local distortion and model fit.
    pub model_s: f64,
    /// Correction of features and images.
    pub correction_s: f64,
    /// Lattice fits, indices and ellipses.
    pub lattice_fit_s: f64,
    /// Local cells, averaged and symmetry-averaged cell.
    pub unit_cells_s: f64,
    /// Everything.
    pub total_s: f64,
}

/// The stage that is about to start (for progress reporting).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Stage {
    /// Measuring the lattice the image shows.
    Calibration,
    /// Finding and fitting features.
    Features,
    /// Neighbours, local distortion, model fit.
    Model,
    /// Correcting features and images.
    Correction,
    /// Lattice fit per region.
    LatticeFit,
    /// Unit cells.
    UnitCells,
}

impl Stage {
    /// Short description for a progress line.
    pub fn describe(self) -> &'static str {
        match self {
            Stage::Calibration => "measuring the lattice the image shows",
            Stage::Features => "finding and fitting features",
            Stage::Model => "fitting drift, creep and hysteresis",
            Stage::Correction => "correcting features and images",
            Stage::LatticeFit => "fitting the lattice",
            Stage::UnitCells => "averaging unit cells",
        }
    }
}
