//! Piezo creep: logarithmic (effect 2, and a second impulse later, effect 8) and
//! exponential (effect 8).

use nalgebra::Vector2;
use serde::{Deserialize, Serialize};

use super::{AcquisitionContext, Effect, EffectConfig, vector};
use crate::SimulationError;
use crate::error::{finite2, non_negative, parameter_count, positive};

/// Logarithmic piezo creep after a sudden move (the DHCT paper's creep term): velocity
/// `C/(t' + t0)`, displacement
///
/// `d = C·ln(1 + t'/t0)` for `t' = t − start ≥ 0`, zero before `start`.
///
/// `C` is independent along x and y, `t0` is shared. With `start_s = 0` this is the creep
/// left over from the move to the frame's start; a second entry with `start_s > 0` is a
/// later creep impulse (e.g. after an offset change).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LogCreep {
    /// `C`, metres, display frame `[x, y]`: the creep velocity is `C/(t' + t0)` m/s.
    pub coefficient_m: [f64; 2],
    /// `t0`, seconds (> 0): the time since the move at `t' = 0`.
    pub t0_s: f64,
    /// When the creep starts, seconds since frame start (≥ 0).
    #[serde(default)]
    pub start_s: f64,
}

impl LogCreep {
    /// Checks `C` finite, `t0 > 0`, `start ≥ 0`.
    pub fn validate(&self, field: &str) -> Result<(), SimulationError> {
        finite2(&format!("{field}.coefficient_m"), self.coefficient_m)?;
        positive(&format!("{field}.t0_s"), self.t0_s)?;
        non_negative(&format!("{field}.start_s"), self.start_s)
    }
}

impl Effect for LogCreep {
    fn name(&self) -> &'static str {
        "creep"
    }

    fn displacement(&self, at: &AcquisitionContext) -> Vector2<f64> {
        let elapsed = at.time_since_frame_start - self.start_s;
        if elapsed <= 0.0 {
            return Vector2::zeros();
        }
        vector(self.coefficient_m) * (elapsed / self.t0_s).ln_1p()
    }

    fn parameter_names(&self) -> Vec<&'static str> {
        vec!["coefficient_x_m", "coefficient_y_m", "t0_s", "start_s"]
    }

    fn parameters(&self) -> Vec<f64> {
        let [cx, cy] = self.coefficient_m;
        vec![cx, cy, self.t0_s, self.start_s]
    }

    fn with_parameters(&self, p: &[f64]) -> Result<Box<dyn Effect>, SimulationError> {
        parameter_count(self.name(), p, 4)?;
        let effect = LogCreep {
            coefficient_m: [p[0], p[1]],
            t0_s: p[2],
            start_s: p[3],
        };
        effect.validate(self.name())?;
        Ok(Box::new(effect))
    }

    fn config(&self) -> EffectConfig {
        EffectConfig::Creep(self.clone())
    }
}

/// Creep that relaxes exponentially towards a final offset:
///
/// `d = A·(1 − exp(−t'/τ))` for `t' = t − start ≥ 0`, zero before `start`
/// (velocity `A/τ·exp(−t'/τ)`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExponentialCreep {
    /// Final displacement `A`, metres, display frame `[x, y]`.
    pub amplitude_m: [f64; 2],
    /// Relaxation time `τ`, seconds (> 0).
    pub time_constant_s: f64,
    /// When the creep starts, seconds since frame start (≥ 0).
    #[serde(default)]
    pub start_s: f64,
}

impl ExponentialCreep {
    /// Checks `A` finite, `τ > 0`, `start ≥ 0`.
    pub fn validate(&self, field: &str) -> Result<(), SimulationError> {
        finite2(&format!("{field}.amplitude_m"), self.amplitude_m)?;
        positive(&format!("{field}.time_constant_s"), self.time_constant_s)?;
        non_negative(&format!("{field}.start_s"), self.start_s)
    }
}

impl Effect for ExponentialCreep {
    fn name(&self) -> &'static str {
        "exponential-creep"
    }

    fn displacement(&self, at: &AcquisitionContext) -> Vector2<f64> {
        let elapsed = at.time_since_frame_start - self.start_s;
        if elapsed <= 0.0 {
            return Vector2::zeros();
        }
        vector(self.amplitude_m) * -(-elapsed / self.time_constant_s).exp_m1()
    }

    fn parameter_names(&self) -> Vec<&'static str> {
        vec![
            "amplitude_x_m",
            "amplitude_y_m",
            "time_constant_s",
            "start_s",
        ]
    }

    fn parameters(&self) -> Vec<f64> {
        let [ax, ay] = self.amplitude_m;
        vec![ax, ay, self.time_constant_s, self.start_s]
    }

    fn with_parameters(&self, p: &[f64]) -> Result<Box<dyn Effect>, SimulationError> {
        parameter_count(self.name(), p, 4)?;
        let effect = ExponentialCreep {
            amplitude_m: [p[0], p[1]],
            time_constant_s: p[2],
            start_s: p[3],
        };
        effect.validate(self.name())?;
        Ok(Box::new(effect))
    }

    fn config(&self) -> EffectConfig {
        EffectConfig::ExponentialCreep(self.clone())
    }
}
