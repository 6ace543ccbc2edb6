//! The template features are matched against.

use ndarray::Array2;
use serde::{Deserialize, Serialize};

use crate::FeatureError;

/// A correlation template: odd-sized, centred, in pixels. Read from a config through
/// [`Kernel::custom`]'s checks, like any user template.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "KernelValues")]
pub struct Kernel {
    values: Array2<f64>,
}

/// A kernel as a config writes it, before its checks.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct KernelValues {
    values: Array2<f64>,
}

impl TryFrom<KernelValues> for Kernel {
    type Error = FeatureError;

    fn try_from(raw: KernelValues) -> Result<Kernel, FeatureError> {
        Kernel::custom(raw.values)
    }
}

impl Kernel {
    /// The DHCT kernel for a nearest-neighbour distance of `nn_px` pixels: an isotropic
    /// Gaussian with σ = R/2, R = round(nn_px/2) (so σ is a multiple of ½ px), on a
    /// (2R+1)² = (4σ+1)² grid.
    pub fn for_neighbour_distance(nn_px: f64) -> Result<Kernel, FeatureError> {
        if !(nn_px.is_finite() && nn_px >= 2.0) {
            return Err(FeatureError::BadParameter(format!(
                "nearest-neighbour distance must be at least 2 px, got {nn_px} px: \
                 check the lattice constant and the pixel pitch"
            )));
        }
        let radius = (nn_px / 2.0).round().max(1.0);
        Kernel::gaussian(radius / 2.0)
    }

    /// An isotropic Gaussian of width `sigma` px on a (4σ+1)² grid, σ rounded to ½ px.
    pub fn gaussian(sigma: f64) -> Result<Kernel, FeatureError> {
        if !(sigma.is_finite() && sigma > 0.0 && sigma <= 256.0) {
            return Err(FeatureError::BadParameter(format!(
                "kernel width must be between 0 and 256 px, got {sigma} px"
            )));
        }
        let sigma = ((2.0 * sigma).round() / 2.0).max(0.5);
        let radius = (2.0 * sigma).round() as usize;
        let size = 2 * radius + 1;
        let values = Array2::from_shape_fn((size, size), |(r, c)| {
            let (dy, dx) = (r as f64 - radius as f64, c as f64 - radius as f64);
            (-(dx * dx + dy * dy) / (2.0 * sigma * sigma)).exp()
        });
        Ok(Kernel { values })
    }

    /// A user template; must be odd-sized in both directions, finite and not constant.
    pub fn custom(values: Array2<f64>) -> Result<Kernel, FeatureError> {
        let (h, w) = values.dim();
        if h % 2 == 0 || w % 2 == 0 {
            return Err(FeatureError::BadParameter(format!(
                "a kernel must have odd dimensions so it has a centre, got {w} x {h}"
            )));
        }
        if values.iter().any(|v| !v.is_finite()) {
            return Err(FeatureError::BadParameter(
                "kernel contains NaN or infinite values".into(),
            ));
        }
        let first = values[[0, 0]];
        if values.iter().all(|v| *v == first) {
            return Err(FeatureError::BadParameter(
                "a constant kernel cannot be correlated".into(),
            ));
        }
        Ok(Kernel { values })
    }

    /// The template values.
    pub fn values(&self) -> &Array2<f64> {
        &self.values
    }

    /// Half the kernel size along (rows, columns).
    pub fn radius(&self) -> (usize, usize) {
        (self.values.nrows() / 2, self.values.ncols() / 2)
    }
}
