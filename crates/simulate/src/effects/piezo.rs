//! Piezo non-linearity: the scanner's displacement is not proportional to its drive, so
//! each axis maps the commanded position onto the sample through a curve. It depends on
//! where the tip is commanded, not on when: trace and retrace see the same distortion at
//! the same place (unlike hysteresis, which mirrors between them, or drift, which follows
//! time).

use nalgebra::Vector2;
use serde::{Deserialize, Serialize};

use super::{AcquisitionContext, Effect, EffectConfig};
use crate::SimulationError;
use crate::error::{finite2, parameter_count};

/// Per-axis position non-linearity of the scanner, in the controller position normalised
/// to `ξ, η ∈ [−1, 1]` across the image:
///
/// `d_x = q_x·(ξ² − 1/3) + c_x·(ξ³ − 3ξ/5)`, `d_y = q_y·(η² − 1/3) + c_y·(η³ − 3η/5)`,
///
/// the quadratic (a gain that grows towards one end) and cubic (an S-shaped gain) terms
/// of each axis's own drive, each without the mean and linear parts a uniform scan would
/// see as a shift or a calibration error. `q` and `c` are metres: `d` at the image edge is
/// `2q/3` and `2c/5`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PiezoNonlinearity {
    /// `[q_x, q_y]`, metres.
    pub quadratic_m: [f64; 2],
    /// `[c_x, c_y]`, metres.
    #[serde(default)]
    pub cubic_m: [f64; 2],
}

impl PiezoNonlinearity {
    /// Checks every value finite.
    pub fn validate(&self, field: &str) -> Result<(), SimulationError> {
        finite2(&format!("{field}.quadratic_m"), self.quadratic_m)?;
        finite2(&format!("{field}.cubic_m"), self.cubic_m)
    }

    /// The largest displacement over the image, metres, per axis.
    pub fn largest_displacement_m(&self) -> [f64; 2] {
        [0, 1].map(|a| {
            (0..=200)
                .map(|k| {
                    let u = -1.0 + k as f64 / 100.0;
                    shape(self.quadratic_m[a], self.cubic_m[a], u).abs()
                })
                .fold(0.0, f64::max)
        })
    }
}

/// `q·(u² − 1/3) + c·(u³ − 3u/5)`.
fn shape(q: f64, c: f64, u: f64) -> f64 {
    q * (u * u - 1.0 / 3.0) + c * (u * u * u - 0.6 * u)
}

impl Effect for PiezoNonlinearity {
    fn name(&self) -> &'static str {
        "piezo-nonlinearity"
    }

    fn displacement(&self, at: &AcquisitionContext) -> Vector2<f64> {
        let [xi, eta] = at.normalised_position();
        Vector2::new(
            shape(self.quadratic_m[0], self.cubic_m[0], xi),
            shape(self.quadratic_m[1], self.cubic_m[1], eta),
        )
    }

    fn parameter_names(&self) -> Vec<&'static str> {
        vec!["quadratic_x_m", "quadratic_y_m", "cubic_x_m", "cubic_y_m"]
    }

    fn parameters(&self) -> Vec<f64> {
        vec![
            self.quadratic_m[0],
            self.quadratic_m[1],
            self.cubic_m[0],
            self.cubic_m[1],
        ]
    }

    fn with_parameters(&self, p: &[f64]) -> Result<Box<dyn Effect>, SimulationError> {
        parameter_count(Effect::name(self), p, 4)?;
        let effect = PiezoNonlinearity {
            quadratic_m: [p[0], p[1]],
            cubic_m: [p[2], p[3]],
        };
        effect.validate(Effect::name(self))?;
        Ok(Box::new(effect))
    }

    fn config(&self) -> EffectConfig {
        EffectConfig::PiezoNonlinearity(self.clone())
    }
}
