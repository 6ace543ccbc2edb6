//! Thermal drift of a whole session of frames, seen from one frame (the drift part of an
//! image sequence, [`crate::sequence`]).

use std::f64::consts::TAU;

use nalgebra::Vector2;
use serde::{Deserialize, Serialize};

use super::{AcquisitionContext, Effect, EffectConfig, vector};
use crate::SimulationError;
use crate::error::{finite, finite2, non_negative, parameter_count, positive};

/// The session's thermal drift, continuous over many frames, as frame `k` sees it.
///
/// The session drift of the tip relative to the sample, in the **instrument frame**
/// (metres, display axes x right, y down, of the unrotated scanner), as a function of the
/// session time `T` (seconds since the first frame's start) is
///
/// `D(T) = v·T + a·T²/2 + A∘sin(2πT/P)` (per axis; `A∘` the component-wise product).
///
/// A frame starting at session time `T_k = frame_start_s` with scan angle
/// `φ = scan_angle_rad` sees, at frame time `t` (seconds since its own start), the change
/// since its start turned into its own display frame:
///
/// `d(t) = R(−φ)·(D(T_k + t) − D(T_k))`,
///
/// `R(−φ)` being [`dhct_scan::ScanGeometry::vector_from_instrument`] of a geometry with scan
/// angle `φ`. `d(0) = 0`: the drift accumulated before the frame starts is a constant shift
/// of the whole frame, which a sequence puts into the frame's sample origin.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SessionDrift {
    /// `v`, m/s, instrument frame `[x, y]`.
    pub velocity_m_per_s: [f64; 2],
    /// `a`, m/s², instrument frame `[x, y]`.
    #[serde(default)]
    pub acceleration_m_per_s2: [f64; 2],
    /// `A`, metres, instrument frame `[x, y]` (zero: no oscillation).
    #[serde(default)]
    pub oscillation_m: [f64; 2],
    /// `P`, seconds (> 0; irrelevant when `A` is zero).
    #[serde(default = "one_second")]
    pub oscillation_period_s: f64,
    /// `T_k`: when this frame starts, seconds of session time (≥ 0).
    #[serde(default)]
    pub frame_start_s: f64,
    /// `φ`: this frame's scan angle, radians counter-clockwise on screen (as
    /// [`dhct_scan::ScanGeometry::scan_angle`]).
    #[serde(default)]
    pub scan_angle_rad: f64,
}

fn one_second() -> f64 {
    1.0
}

impl SessionDrift {
    /// Checks every value finite, `P > 0` and `T_k ≥ 0`.
    pub fn validate(&self, field: &str) -> Result<(), SimulationError> {
        finite2(&format!("{field}.velocity_m_per_s"), self.velocity_m_per_s)?;
        finite2(
            &format!("{field}.acceleration_m_per_s2"),
            self.acceleration_m_per_s2,
        )?;
        finite2(&format!("{field}.oscillation_m"), self.oscillation_m)?;
        positive(
            &format!("{field}.oscillation_period_s"),
            self.oscillation_period_s,
        )?;
        non_negative(&format!("{field}.frame_start_s"), self.frame_start_s)?;
        finite(&format!("{field}.scan_angle_rad"), self.scan_angle_rad)
    }

    /// `D(T)`: the session drift at session time `t_s` (seconds), metres, instrument frame.
    pub fn session_displacement(&self, t_s: f64) -> [f64; 2] {
        let phase = TAU * t_s / self.oscillation_period_s;
        let [v, a, amplitude] = [
            self.velocity_m_per_s,
            self.acceleration_m_per_s2,
            self.oscillation_m,
        ];
        let axis = |i: usize| v[i] * t_s + 0.5 * a[i] * t_s * t_s + amplitude[i] * phase.sin();
        [axis(0), axis(1)]
    }

    /// `D(T_k + t) − D(T_k)`, metres, instrument frame, for frame time `t` (seconds),
    /// written so that no large terms cancel.
    pub fn change_since_frame_start(&self, t: f64) -> [f64; 2] {
        let start = self.frame_start_s;
        let w = TAU / self.oscillation_period_s;
        // sin(w(T+t)) − sin(wT) = 2·cos(w(T + t/2))·sin(wt/2)
        let oscillation = 2.0 * (w * (start + 0.5 * t)).cos() * (0.5 * w * t).sin();
        let [v, a, amplitude] = [
            self.velocity_m_per_s,
            self.acceleration_m_per_s2,
            self.oscillation_m,
        ];
        let axis = |i: usize| v[i] * t + a[i] * t * (start + 0.5 * t) + amplitude[i] * oscillation;
        [axis(0), axis(1)]
    }
}

/// `R(−φ)·v`: an instrument-frame vector in the display frame of a scan turned by `φ`, the
/// formula of [`dhct_scan::ScanGeometry::vector_from_instrument`].
fn vector_from_instrument(scan_angle_rad: f64, v: [f64; 2]) -> [f64; 2] {
    let (s, c) = scan_angle_rad.sin_cos();
    [c * v[0] - s * v[1], s * v[0] + c * v[1]]
}

impl Effect for SessionDrift {
    fn name(&self) -> &'static str {
        "session-drift"
    }

    fn displacement(&self, at: &AcquisitionContext) -> Vector2<f64> {
        let change = self.change_since_frame_start(at.time_since_frame_start);
        vector(vector_from_instrument(self.scan_angle_rad, change))
    }

    fn parameter_names(&self) -> Vec<&'static str> {
        vec![
            "velocity_x_m_per_s",
            "velocity_y_m_per_s",
            "acceleration_x_m_per_s2",
            "acceleration_y_m_per_s2",
            "oscillation_x_m",
            "oscillation_y_m",
            "oscillation_period_s",
            "frame_start_s",
            "scan_angle_rad",
        ]
    }

    fn parameters(&self) -> Vec<f64> {
        let [vx, vy] = self.velocity_m_per_s;
        let [ax, ay] = self.acceleration_m_per_s2;
        let [ox, oy] = self.oscillation_m;
        vec![
            vx,
            vy,
            ax,
            ay,
            ox,
            oy,
            self.oscillation_period_s,
            self.frame_start_s,
            self.scan_angle_rad,
        ]
    }

    fn with_parameters(&self, p: &[f64]) -> Result<Box<dyn Effect>, SimulationError> {
        parameter_count(self.name(), p, 9)?;
        let effect = SessionDrift {
            velocity_m_per_s: [p[0], p[1]],
            acceleration_m_per_s2: [p[2], p[3]],
            oscillation_m: [p[4], p[5]],
            oscillation_period_s: p[6],
            frame_start_s: p[7],
            scan_angle_rad: p[8],
        };
        effect.validate(self.name())?;
        Ok(Box::new(effect))
    }

    fn config(&self) -> EffectConfig {
        EffectConfig::SessionDrift(self.clone())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use dhct_scan::{ScanDirection, ScanGeometry, ScanPass};

    fn drift(start: f64, angle: f64) -> SessionDrift {
        SessionDrift {
            velocity_m_per_s: [3e-12, -2e-12],
            acceleration_m_per_s2: [1e-15, -4e-16],
            oscillation_m: [2e-10, 1e-10],
            oscillation_period_s: 900.0,
            frame_start_s: start,
            scan_angle_rad: angle,
        }
    }

    #[test]
    fn the_change_is_the_difference_of_the_session_drift() {
        let d = drift(417.0, 0.0);
        for t in [0.0, 0.3, 12.5, 40.96] {
            let change = d.change_since_frame_start(t);
            let (a, b) = (
                d.session_displacement(417.0 + t),
                d.session_displacement(417.0),
            );
            for i in 0..2 {
                assert!((change[i] - (a[i] - b[i])).abs() < 1e-20, "{t}: {change:?}");
            }
        }
        assert_eq!(d.change_since_frame_start(0.0), [0.0, 0.0]);
    }

    #[test]
    fn the_rotation_is_the_geometry_s() {
        for angle in [0.0, 0.4, std::f64::consts::FRAC_PI_2, -2.0] {
            let g = ScanGeometry::new(
                8,
                8,
                1e-10,
                1e-10,
                1e-3,
                ScanDirection::Right,
                ScanDirection::Down,
            )
            .unwrap()
            .with_scan_angle(angle)
            .unwrap();
            let d = drift(100.0, angle);
            let at = AcquisitionContext::at_pixel(&g, ScanPass::Retrace, 3.0, 5.0, 0.0);
            let got = d.displacement(&at);
            let want =
                g.vector_from_instrument(d.change_since_frame_start(at.time_since_frame_start));
            assert!((got.x - want[0]).abs() < 1e-24 && (got.y - want[1]).abs() < 1e-24);
        }
    }
}
