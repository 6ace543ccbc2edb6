//! The session drift `D(T)`: thermal drift plus the logarithmic creep of every move, in the
//! instrument frame, continuous over all frames.

use serde::{Deserialize, Serialize};

use crate::effects::SessionDrift;
use crate::sequence::config::{CreepConfig, SequenceConfig};
use crate::sequence::timeline::Timeline;

/// One creep of the session: `C·ln(1 + (T − T_m)/t0)` for `T > T_m`, instrument frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CreepEvent {
    /// `T_m`: when it starts, seconds of session time.
    pub start_s: f64,
    /// `C`, metres, instrument frame `[x, y]`.
    pub coefficient_m: [f64; 2],
    /// `t0`, seconds.
    pub t0_s: f64,
}

impl CreepEvent {
    fn new(start_s: f64, creep: &CreepConfig) -> CreepEvent {
        CreepEvent {
            start_s,
            coefficient_m: creep.coefficient_m,
            t0_s: creep.t0_s,
        }
    }

    /// Its displacement at session time `t_s`, metres, instrument frame (0 before `T_m`).
    pub fn displacement(&self, t_s: f64) -> [f64; 2] {
        let elapsed = t_s - self.start_s;
        if elapsed <= 0.0 {
            return [0.0, 0.0];
        }
        let l = (elapsed / self.t0_s).ln_1p();
        [self.coefficient_m[0] * l, self.coefficient_m[1] * l]
    }
}

/// `D(T)`, the tip's displacement relative to the sample over the session, metres,
/// instrument frame: `v·T + a·T²/2 + A∘sin(2πT/P) + Σ_m C_m·ln(1 + (T − T_m)/t0_m)`.
#[derive(Debug, Clone, PartialEq)]
pub struct SessionMotion {
    /// The thermal part, as seen from a frame starting at `T = 0` with scan angle 0.
    thermal: SessionDrift,
    /// The initial creep (at `T = 0`) and each move's, in time order.
    creeps: Vec<CreepEvent>,
}

impl SessionMotion {
    /// The motion `sequence` describes over `timeline` (moves start at their frame's
    /// start).
    pub fn new(sequence: &SequenceConfig, timeline: &Timeline) -> SessionMotion {
        let drift = &sequence.drift;
        let thermal = SessionDrift {
            velocity_m_per_s: drift.velocity_m_per_s,
            acceleration_m_per_s2: drift.acceleration_m_per_s2,
            oscillation_m: drift.oscillation_m,
            oscillation_period_s: drift.period_s(),
            frame_start_s: 0.0,
            scan_angle_rad: 0.0,
        };
        let initial = sequence
            .initial_creep
            .iter()
            .map(|c| CreepEvent::new(0.0, c));
        let moves = sequence.moves.iter().filter_map(|m| {
            let start = timeline.start_s(m.before_frame)?;
            m.creep.as_ref().map(|c| CreepEvent::new(start, c))
        });
        SessionMotion {
            thermal,
            creeps: initial.chain(moves).collect(),
        }
    }

    /// `D(T)` at session time `t_s` (seconds), metres, instrument frame.
    pub fn displacement(&self, t_s: f64) -> [f64; 2] {
        let mut d = self.thermal.session_displacement(t_s);
        for creep in &self.creeps {
            let c = creep.displacement(t_s);
            d = [d[0] + c[0], d[1] + c[1]];
        }
        d
    }

    /// The thermal drift as frame `k` sees it: starting at `frame_start_s`, turned by
    /// `scan_angle_rad` (the `session-drift` effect of that frame).
    pub fn thermal_for_frame(&self, frame_start_s: f64, scan_angle_rad: f64) -> SessionDrift {
        SessionDrift {
            frame_start_s,
            scan_angle_rad,
            ..self.thermal.clone()
        }
    }

    /// The creeps started at or before session time `t_s`.
    pub fn creeps_started_by(&self, t_s: f64) -> impl Iterator<Item = &CreepEvent> {
        self.creeps.iter().filter(move |c| c.start_s <= t_s)
    }

    /// Every creep, in time order.
    pub fn creeps(&self) -> &[CreepEvent] {
        &self.creeps
    }
}
