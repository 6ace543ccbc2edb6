//! Options of the whole chain (serialisable: the CLI writes the resolved options next to
//! the results so a run can be repeated).

use dhct_distortion::DhctOptions;
use dhct_features::{FeatureOptions, KernelChoice, LineCorrection, Polarity};
use dhct_lattice::{Lattice, LatticeFitOptions, LocalDistortionMethod, PlaneGroup};
use serde::{Deserialize, Serialize};

use crate::PipelineError;

/// Options of [`crate::run`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct PipelineOptions {
    /// Feature finding (`neighbour_distance` NaN = the lattice's NN distance).
    pub features: FeatureOptions,
    /// Neighbours, local distortion and the model fit.
    pub dhct: DhctOptions,
    /// The whole-image lattice fit (per region).
    pub lattice_fit: LatticeFitOptions,
    /// Which features each region's lattice fit uses.
    pub regions: RegionOptions,
    /// Local cells, averaged and symmetry-averaged unit cell.
    pub unit_cell: UnitCellOptions,
    /// Keep the normalised cross-correlation maps in the result (for plots).
    pub keep_correlation: bool,
    /// The lattice the image shows, measured before anything else: checks the inputs,
    /// seeds the kernel and neighbour search, gives the affine floor.
    pub calibration: crate::CalibrationOptions,
}

impl Default for PipelineOptions {
    fn default() -> Self {
        PipelineOptions {
            features: FeatureOptions::default(),
            dhct: DhctOptions::default(),
            lattice_fit: LatticeFitOptions::default(),
            regions: RegionOptions::default(),
            unit_cell: UnitCellOptions::default(),
            keep_correlation: true,
            calibration: crate::CalibrationOptions::default(),
        }
    }
}

impl PipelineOptions {
    /// Recommended defaults for `lattice`: its NN distance sets the feature kernel; scan
    /// lines are levelled by their median before feature finding (real scans carry line
    /// offsets and slow z drifts: without it the Pb/Pt(111) file yields no lattice, and
    /// the simulated headline case's model parameters miss their truth by up to 9.5 σ
    /// instead of 1.3 σ); the corrected image itself is never levelled. On images without
    /// line offsets set `features.line_correction = "none"`: a per-line median also
    /// subtracts the lattice's own row modulation and shifts positions along the slow axis
    /// (simulated graphene: 0.9 px). The local distortion is the affine map for every
    /// lattice, less biased than the paper's algebraic ellipse fit on noisy real data (HOPG
    /// terrace: a = 2.458 × 2.384 Å affine vs 2.422 × 2.220 Å ellipse); set `dhct.method` to
    /// `ellipse` for the paper's method.
    pub fn for_lattice(lattice: &dyn Lattice) -> PipelineOptions {
        let mut options = PipelineOptions {
            features: FeatureOptions::for_neighbour_distance(lattice.nearest_neighbour_distance()),
            ..PipelineOptions::default()
        };
        options.features.line_correction = LineCorrection::Median;
        options.dhct.method = Some(LocalDistortionMethod::Affine);
        let appearance = lattice.feature_appearance();
        if appearance.dark {
            options.features.polarity = Polarity::Dark;
        }
        if let Some(fraction) = appearance.width_fraction {
            options.features.kernel = KernelChoice::FractionOfNeighbourDistance { fraction };
        }
        options
    }

    /// Checks the options this crate adds (the stages check their own).
    pub fn validate(&self) -> Result<(), PipelineError> {
        self.calibration.validate()?;
        let r = self.unit_cell.resolution;
        if r < 8 || !r.is_multiple_of(2) || r > 1024 {
            return Err(PipelineError::BadOption(format!(
                "unit_cell.resolution must be an even number of samples in 8..=1024, got {r}"
            )));
        }
        let m = self.regions.edge_margin_nn;
        if !(m.is_finite() && (0.0..=20.0).contains(&m)) {
            return Err(PipelineError::BadOption(format!(
                "regions.edge_margin_nn must be in 0..=20 nearest-neighbour distances, got {m}"
            )));
        }
        if let Some(k) = self.unit_cell.selection.exclude_outliers_sigma
            && !(k.is_finite() && k > 0.0)
        {
            return Err(PipelineError::BadOption(format!(
                "unit_cell.selection.exclude_outliers_sigma must be positive, got {k}"
            )));
        }
        for (name, range) in [
            ("height_m", self.unit_cell.selection.height_m),
            ("width_px", self.unit_cell.selection.width_px),
        ] {
            if let Some([lo, hi]) = range
                && !(lo.is_finite() && hi.is_finite() && lo <= hi)
            {
                return Err(PipelineError::BadOption(format!(
                    "unit_cell.selection.{name} must be [low, high] with low <= high, got [{lo}, {hi}]"
                )));
            }
        }
        Ok(())
    }
}

/// Which features a region's lattice fit uses.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct RegionOptions {
    /// Features closer than this many NN distances to the edge of their mask region are
    /// not used (they are corrected but not indexed). Ignored without a mask.
    pub edge_margin_nn: f64,
    /// Regions with fewer trace features than this are skipped.
    pub min_features: usize,
}

impl Default for RegionOptions {
    fn default() -> Self {
        RegionOptions {
            edge_margin_nn: 1.0,
            min_features: 30,
        }
    }
}

/// Local cells and the averaged unit cell.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct UnitCellOptions {
    /// Samples along each cell vector of the averaged cell (even).
    pub resolution: usize,
    /// Plane group of the symmetry average; `None` = the lattice's own.
    pub plane_group: Option<PlaneGroup>,
    /// Which local cells are averaged.
    pub selection: CellSelection,
}

impl Default for UnitCellOptions {
    fn default() -> Self {
        UnitCellOptions {
            resolution: 48,
            plane_group: None,
            selection: CellSelection::default(),
        }
    }
}

/// Selection of local cells by the properties of their four corner features (paper §V:
/// "cell selection by height, width, presence of a defect").
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(default)]
pub struct CellSelection {
    /// Keep a cell only if every corner's fitted height (z units of the image, metres for
    /// topography) lies in `[low, high]`.
    pub height_m: Option<[f64; 2]>,
    /// Keep a cell only if every corner's Gaussian width (major σ, pixels) lies in
    /// `[low, high]`.
    pub width_px: Option<[f64; 2]>,
    /// Drop cells with a defect-like corner: height or width farther than this many robust
    /// standard deviations (1.4826 × MAD) from the median of all features.
    pub exclude_outliers_sigma: Option<f64>,
}
