//! What [`crate::run`] returns: every stage's result, kept for plots, tables and reports.

use dhct_distortion::{CorrectedFeature, DhctResult, Rdf};
use dhct_features::FeatureSet;
use dhct_lattice::{AngularDistribution, LatticeFit, PlaneGroup};
use dhct_scan::ScanPass;
use dhct_unitcell::{AveragedCell, ConfidenceEllipse, LocalCell, SymmetryResidual};
use ndarray::Array2;
use serde::{Deserialize, Serialize};

use crate::{AffineComparison, CorrectedImageCheck, Warning};
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

/// One image's results.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct PassOutput {
    /// Trace or retrace.
    pub pass: ScanPass,
    /// Features in the controller frame.
    pub features: FeatureSet,
    /// The normalised cross-correlation map (rows × columns), when kept (single precision:
    /// it is kept for plots).
    #[serde(skip)]
    pub correlation: Option<Array2<f32>>,
    /// Every feature moved to the sample frame (same order as `features.features`).
    pub corrected: Vec<CorrectedFeature>,
    /// The image resampled onto the sample-frame grid (z unchanged; NaN = no data).
    #[serde(skip)]
    pub corrected_image: Array2<f64>,
    /// Each feature's lattice site, if it was indexed (same order as the features).
    pub indices: Vec<Option<FeatureIndex>>,
    /// RDF of the corrected features, on the bins of the raw RDF.
    pub rdf_corrected: Option<Rdf>,
}

/// A feature's lattice site and its deviation from it (sample frame).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FeatureIndex {
    /// Region (index into [`Analysis::regions`]).
    pub region: usize,
    /// Cell index along a1.
    pub n: i64,
    /// Cell index along a2.
    pub m: i64,
    /// Motif site.
    pub site: usize,
    /// Corrected position − fitted site, metres.
    pub deviation_m: [f64; 2],
}

/// The lattice fit of one mask region (one domain).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct RegionFit {
    /// Region number (by size, largest first).
    pub region: usize,
    /// Pixels in the region.
    pub pixels: usize,
    /// The fit; point set `k` is `members[k]`'s pass.
    pub fit: LatticeFit,
    /// Pass of each point set.
    pub passes: Vec<ScanPass>,
    /// Feature indices (into the pass's feature list) of each point set.
    pub members: Vec<Vec<usize>>,
    /// Deviations from the whole-image fit, all sets pooled (σ_z from feature heights).
    pub whole_ellipse: ConfidenceEllipse,
    /// Local cells of each point set.
    pub local_cells: Vec<Vec<LocalCell>>,
    /// Corner deviations from the local cell fits, all sets pooled.
    pub local_ellipse: Option<ConfidenceEllipse>,
    /// Bond-angle distribution of the corrected features of set 0.
    pub adf: Option<AngularDistribution>,
}

/// A region that was not fitted.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SkippedRegion {
    /// Region number.
    pub region: usize,
    /// Pixels in the region.
    pub pixels: usize,
    /// Trace features usable in it.
    pub features: usize,
    /// Why it was skipped.
    pub reason: String,
}

/// Averaged and symmetry-averaged unit cell.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct UnitCellAnalysis {
    /// The plane group of the symmetry average.
    pub group: PlaneGroup,
    /// Translational average of the selected cells (fractional grid, `values[[i, j]]` at
    /// `u = j/R`, `v = i/R`).
    pub averaged: AveragedCell,
    /// `averaged` averaged over the group's operations.
    pub symmetrized: AveragedCell,
    /// How far `averaged` is from every group compatible with the lattice.
    pub residuals: Vec<SymmetryResidual>,
    /// The group's asymmetric unit, fractional coordinates.
    pub asymmetric_unit: Vec<[f64; 2]>,
    /// Local cells found (all regions and passes).
    pub cells_available: usize,
    /// Local cells kept by the selection.
    pub cells_selected: usize,
}

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
