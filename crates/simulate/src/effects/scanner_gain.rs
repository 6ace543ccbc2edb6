//! A miscalibrated scanner: each piezo axis moves the tip by a fixed factor times what it
//! was told, so the pixel size a file states is wrong along that axis. In a scan turned by a
//! scan angle the error acts along the instrument's axes, not the image's.

use nalgebra::Vector2;
use serde::{Deserialize, Serialize};

use super::{AcquisitionContext, Effect, EffectConfig, vector};
use crate::SimulationError;
use crate::error::{finite, parameter_count, positive};

/// The scanner's gain per instrument axis: the tip commanded to instrument position
/// `q = O + R(φ)(p − c)` (see [`dhct_scan::ScanGeometry::to_instrument`]) goes to
/// `O + G·R(φ)(p − c)`, `G = diag(g_x, g_y)`. Seen in the image's display frame the
/// displacement is `d = R(−φ)(G − I)R(φ)(p − c)`: zero at the image centre, growing
/// linearly towards the edges.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScannerGain {
    /// `[g_x, g_y]`: true over stated displacement along the instrument's x and y (> 0).
    pub gain: [f64; 2],
    /// `φ`: the scan angle of the frame, radians counter-clockwise on screen.
    #[serde(default)]
    pub scan_angle_rad: f64,
}

impl ScannerGain {
    /// Checks the gains positive and the angle finite.
    pub fn validate(&self, field: &str) -> Result<(), SimulationError> {
        positive(&format!("{field}.gain[0]"), self.gain[0])?;
        positive(&format!("{field}.gain[1]"), self.gain[1])?;
        finite(&format!("{field}.scan_angle_rad"), self.scan_angle_rad)
    }
}

impl Effect for ScannerGain {
    fn name(&self) -> &'static str {
        "scanner-gain"
    }

    fn displacement(&self, at: &AcquisitionContext) -> Vector2<f64> {
        let g = at.geometry;
        let c = g.centre();
        let p = [at.controller.x - c[0], at.controller.y - c[1]];
        let (s, co) = self.scan_angle_rad.sin_cos();
        // R(φ)·p, then (G − I), then R(−φ) (the formulas of ScanGeometry's vector maps).
        let q = [co * p[0] + s * p[1], -s * p[0] + co * p[1]];
        let e = [(self.gain[0] - 1.0) * q[0], (self.gain[1] - 1.0) * q[1]];
        vector([co * e[0] - s * e[1], s * e[0] + co * e[1]])
    }

    fn parameter_names(&self) -> Vec<&'static str> {
        vec!["gain_x", "gain_y", "scan_angle_rad"]
    }

    fn parameters(&self) -> Vec<f64> {
        vec![self.gain[0], self.gain[1], self.scan_angle_rad]
    }

    fn with_parameters(&self, p: &[f64]) -> Result<Box<dyn Effect>, SimulationError> {
        parameter_count(self.name(), p, 3)?;
        let effect = ScannerGain {
            gain: [p[0], p[1]],
            scan_angle_rad: p[2],
        };
        effect.validate(self.name())?;
        Ok(Box::new(effect))
    }

    fn config(&self) -> EffectConfig {
        EffectConfig::ScannerGain(self.clone())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use dhct_scan::{ScanDirection, ScanGeometry, ScanPass};

    #[test]
    fn the_gain_acts_along_the_instruments_axes() {
        let g = ScanGeometry::new(
            11,
            11,
            1.0,
            1.0,
            1e-3,
            ScanDirection::Right,
            ScanDirection::Down,
        )
        .unwrap();
        let at = |x: f64, y: f64| AcquisitionContext::at_pixel(&g, ScanPass::Trace, x, y, 0.0);
        // Instrument x 10 % long. At 0° the image's x is the instrument's x.
        let plain = ScannerGain {
            gain: [1.1, 1.0],
            scan_angle_rad: 0.0,
        };
        let d = plain.displacement(&at(10.0, 5.0));
        assert!((d.x - 0.5).abs() < 1e-12 && d.y.abs() < 1e-12, "{d:?}");
        // At 90° the image's y (down) is the instrument's x: the image stretches along y.
        let turned = ScannerGain {
            gain: [1.1, 1.0],
            scan_angle_rad: std::f64::consts::FRAC_PI_2,
        };
        let d = turned.displacement(&at(5.0, 10.0));
        assert!(d.x.abs() < 1e-12 && (d.y - 0.5).abs() < 1e-12, "{d:?}");
        let d = turned.displacement(&at(10.0, 5.0));
        assert!(d.norm() < 1e-12, "{d:?}");
    }
}
