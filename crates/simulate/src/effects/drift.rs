//! Thermal drift (effect 1) and per-line drift along the fast axis (effect 4).

use nalgebra::Vector2;
use serde::{Deserialize, Serialize};

use super::{AcquisitionContext, Effect, EffectConfig, vector};
use crate::SimulationError;
use crate::error::{finite2, parameter_count};

/// Thermal drift: the tip moves relative to the sample with constant velocity `v` and
/// acceleration `a` from the start of the frame (the DHCT paper's drift model):
///
/// `d(t) = v·t + a·t²/2`, `t` = seconds since frame start.
///
/// A velocity component along the slow direction stretches the slow scale (sample metres
/// per line) by exactly `1 + v_s/v_slow`; one along the fast axis stretches the trace's fast
/// scale by `1 + v_f/v_fast` and the retrace's by `1 − v_f/v_fast` and shears the frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ThermalDrift {
    /// Velocity of the tip relative to the sample, m/s, display frame `[x, y]`
    /// (minus the sample's drift velocity in the instrument frame).
    pub velocity_m_per_s: [f64; 2],
    /// Constant acceleration, m/s², display frame `[x, y]`.
    #[serde(default)]
    pub acceleration_m_per_s2: [f64; 2],
}

impl ThermalDrift {
    /// Checks that every value is finite.
    pub fn validate(&self, field: &str) -> Result<(), SimulationError> {
        finite2(&format!("{field}.velocity_m_per_s"), self.velocity_m_per_s)?;
        finite2(
            &format!("{field}.acceleration_m_per_s2"),
            self.acceleration_m_per_s2,
        )
    }
}

impl Effect for ThermalDrift {
    fn name(&self) -> &'static str {
        "thermal-drift"
    }

    fn displacement(&self, at: &AcquisitionContext) -> Vector2<f64> {
        let t = at.time_since_frame_start;
        vector(self.velocity_m_per_s) * t + vector(self.acceleration_m_per_s2) * (0.5 * t * t)
    }

    fn parameter_names(&self) -> Vec<&'static str> {
        vec![
            "velocity_x_m_per_s",
            "velocity_y_m_per_s",
            "acceleration_x_m_per_s2",
            "acceleration_y_m_per_s2",
        ]
    }

    fn parameters(&self) -> Vec<f64> {
        let [vx, vy] = self.velocity_m_per_s;
        let [ax, ay] = self.acceleration_m_per_s2;
        vec![vx, vy, ax, ay]
    }

    fn with_parameters(&self, p: &[f64]) -> Result<Box<dyn Effect>, SimulationError> {
        parameter_count(self.name(), p, 4)?;
        let effect = ThermalDrift {
            velocity_m_per_s: [p[0], p[1]],
            acceleration_m_per_s2: [p[2], p[3]],
        };
        effect.validate(self.name())?;
        Ok(Box::new(effect))
    }

    fn config(&self) -> EffectConfig {
        EffectConfig::ThermalDrift(self.clone())
    }
}

/// Drift that acts only within each line and restarts at every line start:
/// `d = v·τ`, `τ` = seconds since the line start (turnaround excluded).
///
/// It reproduces the fast-axis stretch that drift along the fast axis causes — the trace's
/// fast scale is multiplied by `1 + v_f/v_fast` and the retrace's by `1 − v_f/v_fast`, where
/// `v_f` is the component along the trace's fast direction — without the frame-long shear
/// and offset of [`ThermalDrift`]. A slow-axis component tilts every line.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LineDrift {
    /// Velocity of the tip relative to the sample within a line, m/s, display frame `[x, y]`.
    pub velocity_m_per_s: [f64; 2],
}

impl LineDrift {
    /// Checks that every value is finite.
    pub fn validate(&self, field: &str) -> Result<(), SimulationError> {
        finite2(&format!("{field}.velocity_m_per_s"), self.velocity_m_per_s)
    }
}

impl Effect for LineDrift {
    fn name(&self) -> &'static str {
        "line-drift"
    }

    fn displacement(&self, at: &AcquisitionContext) -> Vector2<f64> {
        vector(self.velocity_m_per_s) * at.time_since_line_start
    }

    fn parameter_names(&self) -> Vec<&'static str> {
        vec!["velocity_x_m_per_s", "velocity_y_m_per_s"]
    }

    fn parameters(&self) -> Vec<f64> {
        self.velocity_m_per_s.to_vec()
    }

    fn with_parameters(&self, p: &[f64]) -> Result<Box<dyn Effect>, SimulationError> {
        parameter_count(self.name(), p, 2)?;
        let effect = LineDrift {
            velocity_m_per_s: [p[0], p[1]],
        };
        effect.validate(self.name())?;
        Ok(Box::new(effect))
    }

    fn config(&self) -> EffectConfig {
        EffectConfig::LineDrift(self.clone())
    }
}
