//! Tip change (effect 7): a sudden lateral jump, optionally with a height and contrast change.

use nalgebra::Vector2;
use serde::{Deserialize, Serialize};

use super::{AcquisitionContext, Effect, EffectConfig, HeightEffect, vector};
use crate::SimulationError;
use crate::error::{finite, finite2, non_negative, parameter_count};

/// At `time_s` the tip's imaging apex jumps laterally by `jump_m` and from then on the
/// measured height is `contrast·z + height_offset_m`:
///
/// `d = jump` for `t ≥ time_s`, else 0.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TipChange {
    /// When the tip changes, seconds since frame start (≥ 0).
    pub time_s: f64,
    /// Lateral jump of the tip relative to the sample, metres, display frame `[x, y]`.
    #[serde(default)]
    pub jump_m: [f64; 2],
    /// Height added to every later measurement, metres.
    #[serde(default)]
    pub height_offset_m: f64,
    /// Factor on every later measured height (1 = unchanged).
    #[serde(default = "unit_contrast")]
    pub contrast: f64,
}

fn unit_contrast() -> f64 {
    1.0
}

impl TipChange {
    /// Checks every value.
    pub fn validate(&self, field: &str) -> Result<(), SimulationError> {
        non_negative(&format!("{field}.time_s"), self.time_s)?;
        finite2(&format!("{field}.jump_m"), self.jump_m)?;
        finite(&format!("{field}.height_offset_m"), self.height_offset_m)?;
        finite(&format!("{field}.contrast"), self.contrast)
    }

    /// True if the measured height changes too (offset ≠ 0 or contrast ≠ 1).
    pub fn changes_height(&self) -> bool {
        self.height_offset_m != 0.0 || self.contrast != 1.0
    }

    fn has_happened(&self, at: &AcquisitionContext) -> bool {
        at.time_since_frame_start >= self.time_s
    }
}

impl Effect for TipChange {
    fn name(&self) -> &'static str {
        "tip-change"
    }

    fn displacement(&self, at: &AcquisitionContext) -> Vector2<f64> {
        if self.has_happened(at) {
            vector(self.jump_m)
        } else {
            Vector2::zeros()
        }
    }

    fn parameter_names(&self) -> Vec<&'static str> {
        vec![
            "time_s",
            "jump_x_m",
            "jump_y_m",
            "height_offset_m",
            "contrast",
        ]
    }

    fn parameters(&self) -> Vec<f64> {
        let [jx, jy] = self.jump_m;
        vec![self.time_s, jx, jy, self.height_offset_m, self.contrast]
    }

    fn with_parameters(&self, p: &[f64]) -> Result<Box<dyn Effect>, SimulationError> {
        parameter_count(Effect::name(self), p, 5)?;
        let effect = TipChange {
            time_s: p[0],
            jump_m: [p[1], p[2]],
            height_offset_m: p[3],
            contrast: p[4],
        };
        effect.validate(Effect::name(self))?;
        Ok(Box::new(effect))
    }

    fn config(&self) -> EffectConfig {
        EffectConfig::TipChange(self.clone())
    }
}

impl HeightEffect for TipChange {
    fn name(&self) -> &'static str {
        "tip-change"
    }

    fn apply(&self, z: f64, at: &AcquisitionContext) -> f64 {
        if self.has_happened(at) {
            self.contrast * z + self.height_offset_m
        } else {
            z
        }
    }
}
