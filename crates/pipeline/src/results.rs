//! The parts of an [`crate::Analysis`]: each image's results, each region's lattice fit,
//! each feature's site, the unit cells.

use dhct_distortion::{CorrectedFeature, Rdf};
pub use dhct_features::FeatureIndex;
use dhct_features::FeatureSet;
use dhct_lattice::{AngularDistribution, LatticeFit, PlaneGroup};
use dhct_scan::ScanPass;
use dhct_unitcell::{AveragedCell, ConfidenceEllipse, LocalCell, SymmetryResidual};
use ndarray::Array2;
use serde::{Deserialize, Serialize};

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
