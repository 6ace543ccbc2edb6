//! How a lattice's tracked features look in an STM image, so that feature finding can be
//! set up for it without the user knowing the details.

use serde::{Deserialize, Serialize};

/// The appearance of the tracked features.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FeatureAppearance {
    /// Depressions (e.g. the corner holes of Si(111)-7×7) rather than protrusions.
    pub dark: bool,
    /// Gaussian width σ of a feature as a fraction of the nearest-neighbour distance;
    /// `None`: the DHCT kernel (σ ≈ NN/4), right for close-packed atoms but far too wide for
    /// a small feature in a large cell.
    pub width_fraction: Option<f64>,
    /// Features shallower (or dimmer) than this fraction of the deepest (brightest) are
    /// another kind and are dropped (0 = keep all).
    pub min_relative_height: f64,
    /// Radius of the disc each Gaussian fit uses, as a fraction of the nearest-neighbour
    /// distance; `None`: the default 0.4, which on a large cell reaches the neighbouring
    /// features of another kind (the adatoms around a 7×7 corner hole) and spoils the fit.
    pub fit_radius_fraction: Option<f64>,
}
