//! Where the first neighbour search looks: the raw positions undone by the affine map the
//! image's Fourier peaks measured (a miscalibrated head, and the mean drift over the frame,
//! stretch and shear the raw lattice by tens of percent; the NN window around the lattice's
//! spacing would then miss most neighbours).

use dhct_scan::{Axis, HysteresisLaw, ScanDirection, ScanGeometry};
use serde::{Deserialize, Serialize};

use crate::{DistortionModel, DriftCreep};

/// An affine map measured from the image: file metres per sample metres,
/// `K = [[kx, kxy], [ky_x, ky]]` (row-major, display frame x right, y down), applied about
/// the frame centre. [`SeedMap::to_sample_like`] applies `K⁻¹`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SeedMap {
    /// `K`, file metres per sample metres.
    pub file_per_sample: [[f64; 2]; 2],
}

impl SeedMap {
    /// A seed from `K`; `None` when `K` is singular or not finite.
    pub fn new(file_per_sample: [[f64; 2]; 2]) -> Option<SeedMap> {
        let [[a, b], [c, d]] = file_per_sample;
        let det = a * d - b * c;
        (det.is_finite() && det.abs() > 1e-12).then_some(SeedMap { file_per_sample })
    }

    /// `K⁻¹` applied to `point_m` (metres) about `centre_m` (metres): where the point would
    /// be if the measured map were undone. Positions stay in the frame's coordinates.
    pub fn to_sample_like(&self, point_m: [f64; 2], centre_m: [f64; 2]) -> [f64; 2] {
        let [[a, b], [c, d]] = self.file_per_sample;
        let det = a * d - b * c;
        let (dx, dy) = (point_m[0] - centre_m[0], point_m[1] - centre_m[1]);
        [
            centre_m[0] + (d * dx - b * dy) / det,
            centre_m[1] + (-c * dx + a * dy) / det,
        ]
    }
}

impl SeedMap {
    /// `K⁻¹` as a distortion model: the x scale as a constant hysteresis stretch (power law
    /// with `n = 0`, `S = 2 − 1/kx`), the y scale and the shear as constant drift along the
    /// slow axis. Exact along both axes but for the drift's share within each line (`v·τ`,
    /// at most `|1/ky − 1|/2` pixel across a line). `None` for a vertical fast axis, a map
    /// with a y-by-x term, or `kx ≤ ½`.
    pub fn as_model(&self, geometry: &ScanGeometry) -> Option<DistortionModel> {
        let [[kx, kxy], [kyx, ky]] = self.file_per_sample;
        if geometry.fast_axis() != Axis::Horizontal || kx <= 0.5 || kyx != 0.0 || ky <= 0.0 {
            return None;
        }
        let (shear, inverse_ky) = (-kxy / (kx * ky), 1.0 / ky);
        // Slow-axis velocity of the commanded y (m/s, display frame).
        let slow = match geometry.slow_direction() {
            ScanDirection::Up => -geometry.slow_speed(),
            _ => geometry.slow_speed(),
        };
        let drift = DriftCreep {
            velocity_m_per_s: [shear * slow, (inverse_ky - 1.0) * slow],
            ..DriftCreep::none()
        };
        Some(DistortionModel::new(
            drift,
            HysteresisLaw::Power {
                k: 2.0 - 1.0 / kx,
                n: 0.0,
            },
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn undoes_the_map_about_the_centre() {
        let k = [[1.2, 0.3], [0.0, 0.8]];
        let seed = SeedMap::new(k).expect("regular");
        let centre = [5.0, 4.0];
        let sample = [7.0, 1.0];
        let d = [sample[0] - centre[0], sample[1] - centre[1]];
        let file = [
            centre[0] + k[0][0] * d[0] + k[0][1] * d[1],
            centre[1] + k[1][0] * d[0] + k[1][1] * d[1],
        ];
        let back = seed.to_sample_like(file, centre);
        assert!((back[0] - sample[0]).abs() < 1e-12 && (back[1] - sample[1]).abs() < 1e-12);
        assert_eq!(seed.to_sample_like(centre, centre), centre);
        assert!(SeedMap::new([[1.0, 2.0], [0.5, 1.0]]).is_none());
        assert!(SeedMap::new([[f64::NAN, 0.0], [0.0, 1.0]]).is_none());
    }
}
