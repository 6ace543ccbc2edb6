//! Options of the whole chain (serialisable: the CLI writes the resolved options next to
//! the results so a run can be repeated).

use dhct_distortion::DhctOptions;
use dhct_features::{FeatureOptions, KernelChoice, LineCorrection, Polarity};
use dhct_lattice::{Lattice, LatticeFitOptions, LocalDistortionMethod, PlaneGroup};
use serde::{Deserialize, Serialize};

use crate::PipelineError;

/// Options of [`crate::run`]. Unknown keys are errors when deserialising, and
/// [`PipelineOptions::validate`] checks every number against its documented range.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
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
    /// lines are levelled before feature finding against a model of the lattice made from
    /// the image itself (`LineCorrection::Lattice`; real scans carry line offsets and slow
    /// z drifts: without levelling the Pb/Pt(111) file yields no lattice, and the
    /// simulated headline case's model parameters miss their truth by up to 9.5 σ), and
    /// not at all when the lines vary no more than pixel noise allows; the corrected image
    /// itself is never levelled. Unlike a per-line median it keeps the rows' own
    /// modulation, so the positions do not take on the row period (headline: 3.91 →
    /// 1.93 pm vs truth; `"median"` is the previous default, about 0.15 s faster at
    /// 2048²). The local distortion is the affine map for every
    /// lattice, less biased than the paper's algebraic ellipse fit on noisy real data (HOPG
    /// terrace: a = 2.458 × 2.384 Å affine vs 2.422 × 2.220 Å ellipse); set `dhct.method` to
    /// `ellipse` for the paper's method.
    pub fn for_lattice(lattice: &dyn Lattice) -> PipelineOptions {
        let mut options = PipelineOptions {
            features: FeatureOptions::for_neighbour_distance(lattice.nearest_neighbour_distance()),
            ..PipelineOptions::default()
        };
        options.features.line_correction = LineCorrection::Lattice;
        options.dhct.method = Some(LocalDistortionMethod::Affine);
        let appearance = lattice.feature_appearance();
        if appearance.dark {
            options.features.polarity = Polarity::Dark;
        }
        if let Some(fraction) = appearance.width_fraction {
            options.features.kernel = KernelChoice::FractionOfNeighbourDistance { fraction };
        }
        options.features.min_relative_height = appearance.min_relative_height;
        if let Some(fraction) = appearance.fit_radius_fraction {
            options.features.fit_radius_fraction = fraction;
        }
        options
    }

    /// Checks every numeric option of every stage against its documented range, in one
    /// place: [`FeatureOptions::validate`], [`DhctOptions::validate`],
    /// [`LatticeFitOptions::validate`], then this crate's own (regions, unit cells). The
    /// error names the key (e.g. `dhct.neighbours.rdf_shells`), the value and the range.
    pub fn validate(&self) -> Result<(), PipelineError> {
        self.features
            .validate()
            .map_err(|e| PipelineError::BadOption(format!("features.{}", bare(&e.to_string()))))?;
        self.dhct
            .validate()
            .map_err(|e| PipelineError::BadOption(format!("dhct.{}", bare(&e.to_string()))))?;
        self.lattice_fit
            .validate()
            .map_err(|e| PipelineError::BadOption(e.to_string()))?;
        let n = self.regions.min_features;
        if !(1..=10_000_000).contains(&n) {
            return Err(PipelineError::BadOption(format!(
                "regions.min_features = {n} is outside 1..=10000000"
            )));
        }
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

/// A stage's "invalid parameter: key = value is outside range" without its prefix.
fn bare(message: &str) -> &str {
    message
        .split_once(": ")
        .filter(|(prefix, _)| prefix.starts_with("invalid"))
        .map_or(message, |(_, rest)| rest)
}

/// Which features a region's lattice fit uses.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
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
#[serde(default, deny_unknown_fields)]
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
#[serde(default, deny_unknown_fields)]
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Every numeric option that memory or time depend on is refused out of range, by a
    /// message naming the key, the value and the range.
    #[test]
    fn every_numeric_option_is_checked_with_key_value_and_range() {
        type Edit = fn(&mut PipelineOptions);
        let cases: [(&str, Edit); 12] = [
            ("features.threshold = inf", |o| {
                o.features.threshold = f64::INFINITY
            }),
            ("features.neighbour_distance = 1", |o| {
                o.features.neighbour_distance = 1.0
            }),
            ("features.fit_radius_fraction = NaN", |o| {
                o.features.fit_radius_fraction = f64::NAN
            }),
            ("features.kernel.sigma_px = 100000", |o| {
                o.features.kernel = KernelChoice::GaussianSigma { sigma_px: 1e5 }
            }),
            ("dhct.neighbours.rdf_shells = 10000", |o| {
                o.dhct.neighbours.rdf_shells = 10_000
            }),
            ("dhct.neighbours.bin_fraction = 0.000000001", |o| {
                o.dhct.neighbours.bin_fraction = 1e-9
            }),
            ("dhct.neighbours.window = -1", |o| {
                o.dhct.neighbours.window = -1.0
            }),
            ("dhct.fit.robust_rounds = 1000000", |o| {
                o.dhct.fit.robust_rounds = 1_000_000
            }),
            ("lattice_fit.initial_radius = NaN", |o| {
                o.lattice_fit.initial_radius = f64::NAN
            }),
            ("lattice_fit.nn_window = 3", |o| {
                o.lattice_fit.nn_window = 3.0
            }),
            ("regions.min_features = 0", |o| o.regions.min_features = 0),
            ("unit_cell.resolution", |o| o.unit_cell.resolution = 1 << 20),
        ];
        let graphite = dhct_lattice::Hexagonal::graphite();
        assert!(PipelineOptions::for_lattice(&graphite).validate().is_ok());
        for (expected, edit) in cases {
            let mut options = PipelineOptions::for_lattice(&graphite);
            edit(&mut options);
            let message = options.validate().expect_err(expected).to_string();
            assert!(message.contains(expected), "{expected}: {message}");
            assert!(
                message.contains("..=") || message.contains("in 8..=1024"),
                "{expected}: no range in {message}"
            );
        }
    }
}
