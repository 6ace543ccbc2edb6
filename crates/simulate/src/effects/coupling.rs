//! Geometric cross-talk of the scanner: slow↔fast coupling (effect 5) and the lateral shift
//! that follows the z extension (T_fz, effect 11).

use dhct_scan::Axis;
use nalgebra::Vector2;
use serde::{Deserialize, Serialize};

use super::{AcquisitionContext, Effect, EffectConfig, vector};
use crate::SimulationError;
use crate::error::{finite, finite2, parameter_count};

/// Linear coupling between the scan axes, independent of time and pass.
///
/// With `f`, `s` the controller coordinates (metres) along the fast and slow *axes*
/// (display-frame signs: +x, +y), measured from the image centre:
///
/// * `d_fast = T_sf·s`: the slow motion leaks into the fast axis, so successive lines are
///   shifted progressively along the fast axis (columns tilt, a shear of the frame);
/// * `d_slow = T_fs·f`: the fast motion leaks into the slow axis, so every scan line is
///   tilted in the sample by `atan(T_fs)`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScanCoupling {
    /// `T_sf`, dimensionless (metres along fast per metre along slow).
    #[serde(default)]
    pub slow_to_fast: f64,
    /// `T_fs`, dimensionless (metres along slow per metre along fast).
    #[serde(default)]
    pub fast_to_slow: f64,
}

impl ScanCoupling {
    /// Checks both coefficients are finite.
    pub fn validate(&self, field: &str) -> Result<(), SimulationError> {
        finite(&format!("{field}.slow_to_fast"), self.slow_to_fast)?;
        finite(&format!("{field}.fast_to_slow"), self.fast_to_slow)
    }
}

impl Effect for ScanCoupling {
    fn name(&self) -> &'static str {
        "scan-coupling"
    }

    fn displacement(&self, at: &AcquisitionContext) -> Vector2<f64> {
        let g = at.geometry;
        let centre = Vector2::new(
            0.5 * (g.columns() as f64 - 1.0) * g.pitch_x(),
            0.5 * (g.rows() as f64 - 1.0) * g.pitch_y(),
        );
        let r = at.controller - centre;
        match g.fast_axis() {
            Axis::Horizontal => Vector2::new(self.slow_to_fast * r.y, self.fast_to_slow * r.x),
            Axis::Vertical => Vector2::new(self.fast_to_slow * r.y, self.slow_to_fast * r.x),
        }
    }

    fn parameter_names(&self) -> Vec<&'static str> {
        vec!["slow_to_fast", "fast_to_slow"]
    }

    fn parameters(&self) -> Vec<f64> {
        vec![self.slow_to_fast, self.fast_to_slow]
    }

    fn with_parameters(&self, p: &[f64]) -> Result<Box<dyn Effect>, SimulationError> {
        parameter_count(self.name(), p, 2)?;
        let effect = ScanCoupling {
            slow_to_fast: p[0],
            fast_to_slow: p[1],
        };
        effect.validate(self.name())?;
        Ok(Box::new(effect))
    }

    fn config(&self) -> EffectConfig {
        EffectConfig::ScanCoupling(self.clone())
    }
}

/// Lateral shift proportional to the height the z piezo follows (`T_fz`, tube-scanner
/// bending): `d = T·z` with `z` the terrace height under the tip
/// ([`AcquisitionContext::surface_height`]). Invisible on a flat terrace; across a step
/// edge the upper terrace is shifted by `T·h` relative to the lower one.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HeightCoupling {
    /// `[T_xz, T_yz]`, dimensionless (lateral metres per metre of height).
    pub lateral_per_height: [f64; 2],
}

impl HeightCoupling {
    /// Checks both coefficients are finite.
    pub fn validate(&self, field: &str) -> Result<(), SimulationError> {
        finite2(
            &format!("{field}.lateral_per_height"),
            self.lateral_per_height,
        )
    }
}

impl Effect for HeightCoupling {
    fn name(&self) -> &'static str {
        "height-coupling"
    }

    fn displacement(&self, at: &AcquisitionContext) -> Vector2<f64> {
        vector(self.lateral_per_height) * at.surface_height
    }

    fn parameter_names(&self) -> Vec<&'static str> {
        vec!["lateral_per_height_x", "lateral_per_height_y"]
    }

    fn parameters(&self) -> Vec<f64> {
        self.lateral_per_height.to_vec()
    }

    fn with_parameters(&self, p: &[f64]) -> Result<Box<dyn Effect>, SimulationError> {
        parameter_count(self.name(), p, 2)?;
        let effect = HeightCoupling {
            lateral_per_height: [p[0], p[1]],
        };
        effect.validate(self.name())?;
        Ok(Box::new(effect))
    }

    fn uses_surface_height(&self) -> bool {
        true
    }

    fn config(&self) -> EffectConfig {
        EffectConfig::HeightCoupling(self.clone())
    }
}
