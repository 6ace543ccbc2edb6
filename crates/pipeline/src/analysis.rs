//! What [`crate::run`] returns: every stage's result, kept for plots, tables and reports.

use dhct_distortion::DhctResult;
use serde::{Deserialize, Serialize};

use crate::{
    AffineComparison, CorrectedImageCheck, PassOutput, RegionFit, SkippedRegion, StageTimings,
    UnitCellAnalysis, Warning,
};
use dhct_calibrate::PairCalibration;

/// Everything the chain produced.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Analysis {
    /// Trace first, then retrace when present.
    pub passes: Vec<PassOutput>,
    /// Neighbours, local distortions and the fitted drift/creep/hysteresis model.
    pub dhct: DhctResult,
    /// One whole-image lattice fit per mask region (the whole image without a mask),
    /// largest region first.
    pub regions: Vec<RegionFit>,
    /// Regions that were not fitted, and why.
    pub skipped_regions: Vec<SkippedRegion>,
    /// The averaged and symmetry-averaged unit cell, when enough cells were selected.
    pub unit_cell: Option<UnitCellAnalysis>,
    /// Why there is no unit-cell analysis, if there is none.
    pub unit_cell_note: Option<String>,
    /// The lattice the images show (file units) and the calibration it gives, or why it
    /// could not be measured.
    pub calibration: Result<PairCalibration, String>,
    /// Per region: the full model against the global affine correction.
    pub affine: Vec<AffineComparison>,
    /// Which correction the results come from.
    pub correction: CorrectionSource,
    /// The fitted drift/creep/hysteresis model when the global affine correction was kept
    /// instead (`dhct.model` is then the affine map).
    pub rejected_model: Option<dhct_distortion::DistortionModel>,
    /// The lattice of each corrected image measured by FFT against the lattice given (an
    /// independent check of the result; empty when the lattice could not be measured).
    pub corrected_images: Vec<CorrectedImageCheck>,
    /// The same checks of the drift model's corrected images when they failed and the
    /// global affine correction, whose images did better, was kept instead (the model
    /// fitted the features but not the image between them); empty otherwise.
    pub rejected_model_images: Vec<CorrectedImageCheck>,
    /// What not to trust, and what to do: weak spots of the fit, implausible results,
    /// assumptions (see [`WarningCode`]).
    pub warnings: Vec<Warning>,
    /// Wall time of each stage.
    pub timings: StageTimings,
}

/// Which correction the corrected features and images come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum CorrectionSource {
    /// The fitted drift + creep + hysteresis model.
    DriftModel,
    /// The global affine correction (the model did worse than it).
    Affine,
}
