use nalgebra::{Matrix2, SymmetricEigen};
use serde::{Deserialize, Serialize};

use crate::UnitCellError;

/// The spread of feature positions about their fitted sites, as an ellipse.
///
/// For normally distributed deviations, the 1σ ellipse has semi-axes `sigma_major_m` and
/// `sigma_minor_m` along `angle_rad`; the 2σ ellipse is twice as large.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ConfidenceEllipse {
    /// Semi-axis of the 1σ ellipse along its major axis, metres.
    pub sigma_major_m: f64,
    /// Semi-axis of the 1σ ellipse along its minor axis, metres.
    pub sigma_minor_m: f64,
    /// Direction of the major axis from +x towards +y, radians in (−π/2, π/2].
    pub angle_rad: f64,
    /// Mean deviation (x, y), metres (≈ 0 for a least-squares fit).
    pub mean_m: [f64; 2],
    /// Standard deviation of the heights, metres, if heights were given.
    pub sigma_z_m: Option<f64>,
    /// Number of deviations.
    pub count: usize,
}

impl ConfidenceEllipse {
    /// The ellipse of `deviations` (metres), with σ_z of `heights` if given.
    pub fn from_deviations(
        deviations: &[[f64; 2]],
        heights: Option<&[f64]>,
    ) -> Result<ConfidenceEllipse, UnitCellError> {
        let n = deviations.len();
        if n < 3 {
            return Err(UnitCellError::TooFewDeviations { found: n });
        }
        let count = n as f64;
        let mean = deviations.iter().fold([0.0, 0.0], |m, d| {
            [m[0] + d[0] / count, m[1] + d[1] / count]
        });
        let mut covariance = Matrix2::zeros();
        for d in deviations {
            let (x, y) = (d[0] - mean[0], d[1] - mean[1]);
            covariance += Matrix2::new(x * x, x * y, x * y, y * y) / (count - 1.0);
        }
        let eigen = SymmetricEigen::new(covariance);
        let (major, minor) = if eigen.eigenvalues[0] >= eigen.eigenvalues[1] {
            (0, 1)
        } else {
            (1, 0)
        };
        let axis = eigen.eigenvectors.column(major);
        let mut angle = axis[1].atan2(axis[0]);
        if angle <= -std::f64::consts::FRAC_PI_2 {
            angle += std::f64::consts::PI;
        } else if angle > std::f64::consts::FRAC_PI_2 {
            angle -= std::f64::consts::PI;
        }
        let sigma_z_m = heights.filter(|h| h.len() >= 2).map(|h| {
            let m = h.iter().sum::<f64>() / h.len() as f64;
            (h.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (h.len() - 1) as f64).sqrt()
        });
        Ok(ConfidenceEllipse {
            sigma_major_m: eigen.eigenvalues[major].max(0.0).sqrt(),
            sigma_minor_m: eigen.eigenvalues[minor].max(0.0).sqrt(),
            angle_rad: angle,
            mean_m: mean,
            sigma_z_m,
            count: n,
        })
    }

    /// `points` points on the `k`σ ellipse around `centre` (metres), for drawing.
    pub fn outline(&self, centre: [f64; 2], k: f64, points: usize) -> Vec<[f64; 2]> {
        let (sin, cos) = self.angle_rad.sin_cos();
        (0..points)
            .map(|i| {
                let t = 2.0 * std::f64::consts::PI * i as f64 / points as f64;
                let (u, v) = (
                    k * self.sigma_major_m * t.cos(),
                    k * self.sigma_minor_m * t.sin(),
                );
                [centre[0] + cos * u - sin * v, centre[1] + sin * u + cos * v]
            })
            .collect()
    }
}
