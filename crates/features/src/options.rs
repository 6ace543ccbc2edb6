use serde::{Deserialize, Serialize};

use crate::Kernel;

/// The error of an option outside its range: `key = value is outside range`.
fn out_of_range(key: &str, value: f64, range: &str) -> crate::FeatureError {
    crate::FeatureError::BadParameter(format!("{key} = {value} is outside {range}"))
}

/// Whether features are protrusions (atoms, molecules) or depressions (holes, e.g. the
/// Si(111)-7×7 corner holes).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Polarity {
    /// Features are maxima of z (protrusions).
    #[default]
    Bright,
    /// Features are minima of z (depressions).
    Dark,
}

/// Background removed before feature finding (the image handed to the correction is never
/// altered; this only changes what the correlation and the Gaussian fits see).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(
    rename_all = "kebab-case",
    tag = "kind",
    content = "order",
    deny_unknown_fields
)]
pub enum Background {
    /// Leave z as it is.
    None,
    /// Least-squares plane (over the mask, if given).
    #[default]
    Plane,
    /// Least-squares polynomial of the given total order (1 = plane, at most 6).
    Polynomial(u8),
}

/// Per-line offset removal along the fast axis (scan-line noise).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum LineCorrection {
    /// Leave the lines as they are.
    #[default]
    None,
    /// Subtract each line's median.
    Median,
    /// Subtract each line's median weighted by a window that falls to zero at both line
    /// ends (see `line_level.rs`): removes line offsets as robustly as the median with
    /// less of the lattice's row period imprinted on the image.
    Tapered,
    /// Level each line against a model of the lattice made from the image's own average
    /// atom, then refit (see `lattice_levels.rs`): removes line offsets without removing
    /// the rows' modulation, even for rows nearly parallel to the lines; lines whose
    /// levels vary no more than pixel noise allows are left as recorded. Where only an
    /// image is at hand (no fitted features: [`crate::correct_lines`]) it is the median.
    Lattice,
    /// Subtract each line's least-squares straight line.
    Linear,
}

impl LineCorrection {
    /// The name a config file gives it (`none`, `median`, `tapered`, `lattice`, `linear`).
    pub fn name(self) -> &'static str {
        match self {
            LineCorrection::None => "none",
            LineCorrection::Median => "median",
            LineCorrection::Tapered => "tapered",
            LineCorrection::Lattice => "lattice",
            LineCorrection::Linear => "linear",
        }
    }
}

/// Which correlation template to use.
///
/// Every variant holds fields (`{}` where none): serde ignores unknown keys beside the tag
/// of a unit variant, and a misspelt key must be an error.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", tag = "kind", deny_unknown_fields)]
pub enum KernelChoice {
    /// The DHCT kernel sized from the nearest-neighbour distance.
    FromNeighbourDistance {},
    /// An isotropic Gaussian of a given σ.
    GaussianSigma {
        /// σ, pixels.
        sigma_px: f64,
    },
    /// An isotropic Gaussian whose σ is a fraction of the nearest-neighbour distance (a
    /// small feature in a large cell, e.g. a Si(111)-7×7 corner hole: 0.1).
    FractionOfNeighbourDistance {
        /// σ over the nearest-neighbour distance.
        fraction: f64,
    },
    /// A user template.
    Custom {
        /// The template.
        kernel: Kernel,
    },
}

impl Default for KernelChoice {
    fn default() -> KernelChoice {
        KernelChoice::FromNeighbourDistance {}
    }
}

/// Parameters of feature finding. Only `neighbour_distance` has no default.
/// [`FeatureOptions::validate`] checks every number against its documented range.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FeatureOptions {
    /// Expected nearest-neighbour distance, metres (e.g. 2.46e-10 for graphite).
    pub neighbour_distance: f64,
    /// Whether features are bright (protrusions) or dark (depressions).
    pub polarity: Polarity,
    /// NCC threshold in [−1, 1]; pixels at or below it belong to no feature.
    pub threshold: f64,
    /// The correlation template.
    pub kernel: KernelChoice,
    /// Background removed before correlation and fitting.
    pub background: Background,
    /// Per-line offset removal before correlation and fitting.
    pub line_correction: LineCorrection,
    /// After fitting, fit each scan line's level jointly with every feature (see
    /// `line_relevel.rs`) and move every centre by what those levels change, to first
    /// order: removes much of what line offsets, and the row-period imprint of
    /// `line_correction = "median"`, do to the positions, without a refit. Off by default:
    /// on the headline simulation it improves positions (3.91 → 2.71 pm vs truth) but moves
    /// the drift and creep parameters by up to 5 σ.
    pub line_levels_from_fits: bool,
    /// Drop regions whose area is outside `median/√10 .. median·√10` (the DHCT area filter).
    pub area_filter: bool,
    /// Two fits closer than this fraction of the NN distance are one feature fitted twice.
    pub duplicate_fraction: f64,
    /// Radius of the disc of pixels each Gaussian fit uses, as a fraction of the NN distance.
    /// 0.4 (Atomap's default) keeps the precision within 5 % of the Cramér–Rao bound for
    /// white noise and is ~20 % faster than 0.5, which averages correlated (1/f, line) noise
    /// slightly better.
    pub fit_radius_fraction: f64,
    /// An image whose accepted features have a median peak NCC below this is rejected as
    /// lattice-free (noise blobs give ≈ 0.2, atoms ≳ 0.5). Set 0 to accept anything.
    pub min_median_ncc: f64,
    /// Features whose fitted amplitude is below this fraction of the 90th percentile of all
    /// amplitudes are dropped (0 = keep all): a large cell whose tracked feature is the
    /// deepest or brightest of several kinds (the Si(111)-7×7 corner holes among shallower
    /// minima) keeps only that kind. NCC alone cannot tell them apart: it ignores depth.
    pub min_relative_height: f64,
    /// Rows of the correlation map computed at once (0 = automatic: eight kernel heights,
    /// at least 256 rows, and images up to twice that in one piece). The correlation's
    /// transforms need memory for one strip, not the image; the map agrees with the
    /// one-piece map to single-precision rounding (~1e-6) whatever the value.
    pub correlation_strip_rows: usize,
}

impl Default for FeatureOptions {
    fn default() -> Self {
        FeatureOptions {
            neighbour_distance: f64::NAN,
            polarity: Polarity::Bright,
            threshold: 0.1,
            kernel: KernelChoice::FromNeighbourDistance {},
            background: Background::Plane,
            line_correction: LineCorrection::None,
            line_levels_from_fits: false,
            area_filter: true,
            duplicate_fraction: 0.5,
            fit_radius_fraction: 0.4,
            min_median_ncc: 0.3,
            min_relative_height: 0.0,
            correlation_strip_rows: 0,
        }
    }
}

impl FeatureOptions {
    /// Checks every numeric option against its range; the error names the key, the value
    /// and the range: `neighbour_distance` NaN (the lattice's, filled in by the caller) or
    /// 1 pm..=1 µm; `threshold` −1..=0.99; a Gaussian kernel's `sigma_px` 0.5..=256;
    /// `background` polynomial order 1..=6; `duplicate_fraction` 0..=1;
    /// `fit_radius_fraction` 0.1..=1; `min_median_ncc` −1..=1; `min_relative_height` 0..=1;
    /// a kernel's `fraction` 0.02..=1.
    pub fn validate(&self) -> Result<(), crate::FeatureError> {
        let d = self.neighbour_distance;
        if !(d.is_nan() || (1e-12..=1e-6).contains(&d)) {
            return Err(out_of_range(
                "neighbour_distance",
                d,
                "NaN (the lattice's) or 1e-12..=1e-6 m",
            ));
        }
        let mut checks = vec![
            ("threshold", self.threshold, -1.0, 0.99),
            ("duplicate_fraction", self.duplicate_fraction, 0.0, 1.0),
            ("fit_radius_fraction", self.fit_radius_fraction, 0.1, 1.0),
            ("min_median_ncc", self.min_median_ncc, -1.0, 1.0),
            ("min_relative_height", self.min_relative_height, 0.0, 1.0),
        ];
        if let KernelChoice::FractionOfNeighbourDistance { fraction } = &self.kernel {
            checks.push(("kernel.fraction", *fraction, 0.02, 1.0));
        }
        if let KernelChoice::GaussianSigma { sigma_px } = &self.kernel {
            checks.push(("kernel.sigma_px", *sigma_px, 0.5, 256.0));
        }
        if let Background::Polynomial(order) = self.background {
            checks.push(("background.order", f64::from(order), 1.0, 6.0));
        }
        for (key, value, low, high) in checks {
            if !(value.is_finite() && (low..=high).contains(&value)) {
                return Err(out_of_range(key, value, &format!("{low}..={high}")));
            }
        }
        Ok(())
    }

    /// Defaults for a lattice whose nearest-neighbour distance is `neighbour_distance` metres.
    pub fn for_neighbour_distance(neighbour_distance: f64) -> FeatureOptions {
        FeatureOptions {
            neighbour_distance,
            ..FeatureOptions::default()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A kernel choice read from a config: a misspelt key beside any variant's tag is an
    /// error, and a custom template passes [`Kernel::custom`]'s checks.
    #[test]
    fn kernel_choices_from_a_config_are_checked() {
        let read = |json: &str| serde_json::from_str::<KernelChoice>(json);
        assert_eq!(
            read(r#"{"kind": "from-neighbour-distance"}"#).unwrap(),
            KernelChoice::default()
        );
        let misspelt = read(r#"{"kind": "from-neighbour-distance", "sigma": 2}"#).unwrap_err();
        assert!(misspelt.to_string().contains("unknown field"), "{misspelt}");
        let template = |data: &str| {
            format!(
                r#"{{"kind": "custom", "kernel": {{"values": {{"v": 1, "dim": [3, 3], "data": {data}}}}}}}"#
            )
        };
        let good = read(&template("[0, 1, 0, 1, 2, 1, 0, 1, 0]")).unwrap();
        assert!(matches!(good, KernelChoice::Custom { .. }));
        let constant = read(&template("[1, 1, 1, 1, 1, 1, 1, 1, 1]")).unwrap_err();
        assert!(constant.to_string().contains("constant"), "{constant}");
        let even = read(
            r#"{"kind": "custom", "kernel": {"values": {"v": 1, "dim": [2, 2], "data": [0, 1, 1, 0]}}}"#,
        )
        .unwrap_err();
        assert!(even.to_string().contains("odd"), "{even}");
    }
}
