//! Effects outside dhct's and its diagnosis's model library, for validation whose right
//! answer is "unexplained": a tip that switches irregularly between two apexes
//! (telegraph noise), a local strain bubble, and line jitter.

use std::f64::consts::{PI, SQRT_2};

use nalgebra::Vector2;
use serde::{Deserialize, Serialize};

use super::{AcquisitionContext, Effect, EffectConfig, vector};
use crate::SimulationError;
use crate::error::{finite2, non_negative, parameter_count, positive};

/// A tip switching irregularly between two apexes `jump_m` apart (telegraph noise):
///
/// `d = jump` while `sin(2π f t) + sin(2π √2 f t + 1) + sin(2π φ f t + 2) > 0`, else 0,
///
/// with `f = rate_hz` and `φ` the golden ratio: an aperiodic square wave switching about
/// `2·rate_hz` times per second.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TelegraphTip {
    /// Lateral offset of the second apex, metres, display frame `[x, y]`.
    pub jump_m: [f64; 2],
    /// Base rate `f`, Hz (> 0).
    pub rate_hz: f64,
}

impl TelegraphTip {
    /// Checks every value.
    pub fn validate(&self, field: &str) -> Result<(), SimulationError> {
        finite2(&format!("{field}.jump_m"), self.jump_m)?;
        positive(&format!("{field}.rate_hz"), self.rate_hz)
    }

    /// Whether the second apex images at frame time `t` (seconds).
    pub fn switched(&self, t: f64) -> bool {
        let golden = 0.5 * (1.0 + 5f64.sqrt());
        let w = 2.0 * PI * self.rate_hz * t;
        w.sin() + (SQRT_2 * w + 1.0).sin() + (golden * w + 2.0).sin() > 0.0
    }
}

impl Effect for TelegraphTip {
    fn name(&self) -> &'static str {
        "telegraph-tip"
    }

    fn displacement(&self, at: &AcquisitionContext) -> Vector2<f64> {
        if self.switched(at.time_since_frame_start) {
            vector(self.jump_m)
        } else {
            Vector2::zeros()
        }
    }

    fn parameter_names(&self) -> Vec<&'static str> {
        vec!["jump_x_m", "jump_y_m", "rate_hz"]
    }

    fn parameters(&self) -> Vec<f64> {
        vec![self.jump_m[0], self.jump_m[1], self.rate_hz]
    }

    fn with_parameters(&self, p: &[f64]) -> Result<Box<dyn Effect>, SimulationError> {
        parameter_count(Effect::name(self), p, 3)?;
        let effect = TelegraphTip {
            jump_m: [p[0], p[1]],
            rate_hz: p[2],
        };
        effect.validate(Effect::name(self))?;
        Ok(Box::new(effect))
    }

    fn config(&self) -> EffectConfig {
        EffectConfig::TelegraphTip(self.clone())
    }
}

/// A local strain bubble: the sample bulges radially around `centre_m` (controller frame,
/// metres) within a radius `radius_m`:
///
/// `d = −amplitude · (Δ/R) · exp(−|Δ|²/2R²)`, `Δ = p_ctrl − centre`,
///
/// so that sample features near the centre are pushed outward by up to `amplitude·e^(−1/2)`
/// at `|Δ| = R` (positive amplitude: a bulge; negative: a dimple).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StrainBubble {
    /// Centre, metres, display frame `[x, y]`.
    pub centre_m: [f64; 2],
    /// Radius `R`, metres (> 0).
    pub radius_m: f64,
    /// Amplitude, metres.
    pub amplitude_m: f64,
}

impl StrainBubble {
    /// Checks every value.
    pub fn validate(&self, field: &str) -> Result<(), SimulationError> {
        finite2(&format!("{field}.centre_m"), self.centre_m)?;
        positive(&format!("{field}.radius_m"), self.radius_m)?;
        finite2(&format!("{field}.amplitude_m"), [self.amplitude_m, 0.0])
    }
}

impl Effect for StrainBubble {
    fn name(&self) -> &'static str {
        "strain-bubble"
    }

    fn displacement(&self, at: &AcquisitionContext) -> Vector2<f64> {
        let delta = at.controller - vector(self.centre_m);
        let u = delta / self.radius_m;
        -u * self.amplitude_m * (-0.5 * u.norm_squared()).exp()
    }

    fn parameter_names(&self) -> Vec<&'static str> {
        vec!["centre_x_m", "centre_y_m", "radius_m", "amplitude_m"]
    }

    fn parameters(&self) -> Vec<f64> {
        vec![
            self.centre_m[0],
            self.centre_m[1],
            self.radius_m,
            self.amplitude_m,
        ]
    }

    fn with_parameters(&self, p: &[f64]) -> Result<Box<dyn Effect>, SimulationError> {
        parameter_count(Effect::name(self), p, 4)?;
        let effect = StrainBubble {
            centre_m: [p[0], p[1]],
            radius_m: p[2],
            amplitude_m: p[3],
        };
        effect.validate(Effect::name(self))?;
        Ok(Box::new(effect))
    }

    fn config(&self) -> EffectConfig {
        EffectConfig::StrainBubble(self.clone())
    }
}

/// Line jitter: every scan line (each trace and each retrace line on its own) displaced as
/// a whole by its own random offset, normal with standard deviation `rms_m` per axis:
///
/// `d = rms ⊙ n(line)`, `n` two standard normal values drawn from `seed` and the line's
/// acquisition index (`2·line` for the trace, `2·line + 1` for the retrace).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LineJitter {
    /// Standard deviation of the offsets, metres, display frame `[x, y]` (≥ 0).
    pub rms_m: [f64; 2],
    /// Seed of the offsets.
    #[serde(default)]
    pub seed: u64,
}

impl LineJitter {
    /// Checks every value.
    pub fn validate(&self, field: &str) -> Result<(), SimulationError> {
        non_negative(&format!("{field}.rms_m[0]"), self.rms_m[0])?;
        non_negative(&format!("{field}.rms_m[1]"), self.rms_m[1])
    }

    /// The two standard normal values of acquisition line `line` (Box–Muller of two
    /// SplitMix64 draws).
    fn normals(&self, line: u64) -> [f64; 2] {
        let draw = |k: u64| {
            let mut z = self.seed.wrapping_add(
                line.wrapping_mul(2)
                    .wrapping_add(k)
                    .wrapping_mul(0x9E37_79B9_7F4A_7C15),
            );
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^= z >> 31;
            ((z >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        };
        let (u, v) = (draw(0), draw(1));
        let r = (-2.0 * u.ln()).sqrt();
        let angle = 2.0 * PI * v;
        [r * angle.cos(), r * angle.sin()]
    }
}

impl Effect for LineJitter {
    fn name(&self) -> &'static str {
        "line-jitter"
    }

    fn displacement(&self, at: &AcquisitionContext) -> Vector2<f64> {
        let line_start = at.time_since_frame_start - at.time_since_line_start;
        let line = (line_start / at.geometry.line_period()).round().max(0.0) as u64;
        let n = self.normals(line);
        Vector2::new(self.rms_m[0] * n[0], self.rms_m[1] * n[1])
    }

    fn parameter_names(&self) -> Vec<&'static str> {
        vec!["rms_x_m", "rms_y_m"]
    }

    fn parameters(&self) -> Vec<f64> {
        self.rms_m.to_vec()
    }

    fn with_parameters(&self, p: &[f64]) -> Result<Box<dyn Effect>, SimulationError> {
        parameter_count(Effect::name(self), p, 2)?;
        let effect = LineJitter {
            rms_m: [p[0], p[1]],
            seed: self.seed,
        };
        effect.validate(Effect::name(self))?;
        Ok(Box::new(effect))
    }

    fn config(&self) -> EffectConfig {
        EffectConfig::LineJitter(self.clone())
    }
}
