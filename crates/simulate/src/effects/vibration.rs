//! Periodic vibration (effect 6).

use std::f64::consts::TAU;

use nalgebra::Vector2;
use serde::{Deserialize, Serialize};

use super::{AcquisitionContext, Effect, EffectConfig};
use crate::SimulationError;
use crate::error::{finite2, non_negative, parameter_count};

/// Sinusoidal tip–sample vibration at one frequency:
///
/// `d_x = A_x·sin(2π·f·t + φ_x)`, `d_y = A_y·sin(2π·f·t + φ_y)`, `t` = seconds since frame
/// start. Several entries model several frequencies.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Vibration {
    /// `f`, Hz (≥ 0).
    pub frequency_hz: f64,
    /// `[A_x, A_y]`, metres (peak amplitude).
    pub amplitude_m: [f64; 2],
    /// `[φ_x, φ_y]`, radians.
    #[serde(default)]
    pub phase_rad: [f64; 2],
}

impl Vibration {
    /// Checks `f ≥ 0` and finite amplitudes and phases.
    pub fn validate(&self, field: &str) -> Result<(), SimulationError> {
        non_negative(&format!("{field}.frequency_hz"), self.frequency_hz)?;
        finite2(&format!("{field}.amplitude_m"), self.amplitude_m)?;
        finite2(&format!("{field}.phase_rad"), self.phase_rad)
    }
}

impl Effect for Vibration {
    fn name(&self) -> &'static str {
        "vibration"
    }

    fn displacement(&self, at: &AcquisitionContext) -> Vector2<f64> {
        let angle = TAU * self.frequency_hz * at.time_since_frame_start;
        Vector2::new(
            self.amplitude_m[0] * (angle + self.phase_rad[0]).sin(),
            self.amplitude_m[1] * (angle + self.phase_rad[1]).sin(),
        )
    }

    fn parameter_names(&self) -> Vec<&'static str> {
        vec![
            "frequency_hz",
            "amplitude_x_m",
            "amplitude_y_m",
            "phase_x_rad",
            "phase_y_rad",
        ]
    }

    fn parameters(&self) -> Vec<f64> {
        let [ax, ay] = self.amplitude_m;
        let [px, py] = self.phase_rad;
        vec![self.frequency_hz, ax, ay, px, py]
    }

    fn with_parameters(&self, p: &[f64]) -> Result<Box<dyn Effect>, SimulationError> {
        parameter_count(self.name(), p, 5)?;
        let effect = Vibration {
            frequency_hz: p[0],
            amplitude_m: [p[1], p[2]],
            phase_rad: [p[3], p[4]],
        };
        effect.validate(self.name())?;
        Ok(Box::new(effect))
    }

    fn config(&self) -> EffectConfig {
        EffectConfig::Vibration(self.clone())
    }
}
