//! The `[sequence]` table of a simulation config and its validation.
//!
//! ```toml
//! [sequence]
//! frames = 12
//! pause_s = 3.0
//! start_unix_s = 1800000000
//! scan_angles_deg = [0.0, 90.0]
//! offset_m = [0.0, 0.0]
//! drift = { velocity_m_per_s = [3e-12, -2e-12], oscillation_m = [2e-10, 1e-10], oscillation_period_s = 900.0 }
//! initial_creep = { coefficient_m = [1e-10, 5e-11], t0_s = 20.0 }
//!
//! [[sequence.moves]]
//! before_frame = 6
//! offset_m = [2e-9, -1e-9]
//! creep = { coefficient_m = [2e-10, -1e-10], t0_s = 5.0 }
//! ```

use serde::{Deserialize, Serialize};

use crate::SimulationError;
use crate::config::{MAX_EFFECTS, SimulationConfig};
use crate::error::{finite, finite2, invalid, non_negative, positive};
use crate::sequence::base::check_base;
use crate::sequence::timeline::Timeline;

/// Most frames in one sequence.
pub const MAX_FRAMES: usize = 1000;

/// Default session start, seconds since 1970 (2027-01-15 08:00:00 UTC).
pub const DEFAULT_START_UNIX_S: i64 = 1_800_000_000;

/// Latest session end the SM4 page date can hold, seconds since 1970: 2070-01-01 (its
/// two-digit year is read as 19xx from 70 on).
pub const LATEST_END_UNIX_S: i64 = 3_155_760_000;

/// An image sequence: `frames` frames of one sample area taken one after another, with
/// drift and creep continuous over the whole session (see [`crate::sequence`]).
///
/// Vectors are `[x, y]`, metres, in the **instrument frame** (display axes x right, y down,
/// of the unrotated scanner).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SequenceConfig {
    /// Number of frames, 2 ..= [`MAX_FRAMES`].
    pub frames: usize,
    /// Pause between the end of a frame and the start of the next, seconds (≥ 0) — before
    /// the start is rounded up to a whole second.
    #[serde(default)]
    pub pause_s: f64,
    /// When frame 0 starts, whole seconds since 1970-01-01 (UTC on the file's clock).
    #[serde(default = "default_start")]
    pub start_unix_s: i64,
    /// Scan angle of each frame, degrees counter-clockwise on screen, cycled over the
    /// frames (`[0, 90]`: 0°, 90°, 0°, …).
    #[serde(default = "default_angles")]
    pub scan_angles_deg: Vec<f64>,
    /// Frame centre of frame 0 (and of every frame until the first move), metres,
    /// instrument frame.
    #[serde(default)]
    pub offset_m: [f64; 2],
    /// The session's thermal drift.
    #[serde(default)]
    pub drift: DriftConfig,
    /// Creep already under way at the start of frame 0 (it starts at session time 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub initial_creep: Option<CreepConfig>,
    /// Moves of the scan frame, in order.
    #[serde(default)]
    pub moves: Vec<MoveConfig>,
    /// The scanner's true over stated displacement along the instrument's x and y
    /// (`[1, 1]`: the files' pixel size is right); applied to every frame as a
    /// `scanner-gain` effect turned by the frame's scan angle.
    #[serde(default = "unit_gain")]
    pub scanner_gain: [f64; 2],
}

fn unit_gain() -> [f64; 2] {
    [1.0, 1.0]
}

fn default_start() -> i64 {
    DEFAULT_START_UNIX_S
}

fn default_angles() -> Vec<f64> {
    vec![0.0]
}

/// The session's thermal drift of the tip relative to the sample, instrument frame:
/// `D(T) = v·T + a·T²/2 + A∘sin(2πT/P)`, `T` seconds since frame 0's start.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DriftConfig {
    /// `v`, m/s.
    #[serde(default)]
    pub velocity_m_per_s: [f64; 2],
    /// `a`, m/s².
    #[serde(default)]
    pub acceleration_m_per_s2: [f64; 2],
    /// `A`, metres (default 0: no oscillation).
    #[serde(default)]
    pub oscillation_m: [f64; 2],
    /// `P`, seconds (> 0); needed when `A` is not zero.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub oscillation_period_s: Option<f64>,
}

/// Logarithmic piezo creep after a move at session time `T_m`:
/// `C·ln(1 + (T − T_m)/t0)` for `T > T_m`, instrument frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CreepConfig {
    /// `C`, metres.
    pub coefficient_m: [f64; 2],
    /// `t0`, seconds (> 0).
    pub t0_s: f64,
}

/// A move of the scan frame, at the start of frame `before_frame`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MoveConfig {
    /// The first frame taken at the new place (1 ..= frames − 1); the move, and its creep,
    /// happen at that frame's start.
    pub before_frame: usize,
    /// The new frame centre, metres, instrument frame.
    pub offset_m: [f64; 2],
    /// The creep the move starts.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub creep: Option<CreepConfig>,
}

impl SequenceConfig {
    /// Checks every value, refuses base-config content a sequence cannot carry (drift
    /// effects, features that would differ per frame) and checks that the session fits the
    /// SM4 date; errors name the field (`sequence.moves[1].before_frame`, `effects[0]` …).
    pub fn validate(&self, base: &SimulationConfig) -> Result<(), SimulationError> {
        if !(2..=MAX_FRAMES).contains(&self.frames) {
            return Err(invalid(
                "sequence.frames",
                format!("must lie in 2 ..= {MAX_FRAMES}, got {}", self.frames),
            ));
        }
        non_negative("sequence.pause_s", self.pause_s)?;
        self.validate_angles()?;
        finite2("sequence.offset_m", self.offset_m)?;
        self.drift.validate("sequence.drift")?;
        if let Some(creep) = &self.initial_creep {
            creep.validate("sequence.initial_creep")?;
        }
        self.validate_moves()?;
        for (axis, gain) in self.scanner_gain.iter().enumerate() {
            if !(gain.is_finite() && (0.5..=2.0).contains(gain)) {
                return Err(invalid(
                    format!("sequence.scanner_gain[{axis}]"),
                    format!("must lie in 0.5 ..= 2, got {gain}"),
                ));
            }
        }
        check_base(base)?;
        self.check_effect_count(base)?;
        self.check_dates(base)
    }

    /// The scan angle of frame `k`, radians (the list cycled).
    pub fn scan_angle_rad(&self, k: usize) -> f64 {
        match self.scan_angles_deg.as_slice() {
            [] => 0.0,
            angles => angles[k % angles.len()].to_radians(),
        }
    }

    /// The frame centre of frame `k`, metres, instrument frame: the last move's at or
    /// before `k`, else [`SequenceConfig::offset_m`].
    pub fn offset_of_frame(&self, k: usize) -> [f64; 2] {
        self.moves
            .iter()
            .rev()
            .find(|m| m.before_frame <= k)
            .map_or(self.offset_m, |m| m.offset_m)
    }

    fn validate_angles(&self) -> Result<(), SimulationError> {
        let field = "sequence.scan_angles_deg";
        if self.scan_angles_deg.is_empty() || self.scan_angles_deg.len() > MAX_FRAMES {
            return Err(invalid(
                field,
                format!(
                    "must hold 1 ..= {MAX_FRAMES} angles, got {}",
                    self.scan_angles_deg.len()
                ),
            ));
        }
        for (index, angle) in self.scan_angles_deg.iter().enumerate() {
            finite(&format!("{field}[{index}]"), *angle)?;
        }
        Ok(())
    }

    fn validate_moves(&self) -> Result<(), SimulationError> {
        let mut previous = 0;
        for (index, m) in self.moves.iter().enumerate() {
            let field = format!("sequence.moves[{index}]");
            if !(1..self.frames).contains(&m.before_frame) {
                return Err(invalid(
                    format!("{field}.before_frame"),
                    format!(
                        "must lie in 1 ..= {} (frames − 1), got {}",
                        self.frames - 1,
                        m.before_frame
                    ),
                ));
            }
            if m.before_frame <= previous {
                return Err(invalid(
                    format!("{field}.before_frame"),
                    format!(
                        "moves must be in order, one per frame at most: {} follows {previous}",
                        m.before_frame
                    ),
                ));
            }
            previous = m.before_frame;
            finite2(&format!("{field}.offset_m"), m.offset_m)?;
            if let Some(creep) = &m.creep {
                creep.validate(&format!("{field}.creep"))?;
            }
        }
        Ok(())
    }

    /// The last frame carries the base effects, the session drift and one creep per move.
    fn check_effect_count(&self, base: &SimulationConfig) -> Result<(), SimulationError> {
        let creeps = usize::from(self.initial_creep.is_some())
            + self.moves.iter().filter(|m| m.creep.is_some()).count();
        let total = base.effects.len() + 1 + creeps;
        if total > MAX_EFFECTS {
            return Err(invalid(
                "sequence.moves",
                format!(
                    "{} base effects, the session drift and {creeps} creeps make {total} \
                     effects per frame, more than the limit of {MAX_EFFECTS}",
                    base.effects.len()
                ),
            ));
        }
        Ok(())
    }

    /// The session must start at or after 1970 and end before 2070 (the SM4 page date).
    fn check_dates(&self, base: &SimulationConfig) -> Result<(), SimulationError> {
        let geometry = base.scan.geometry()?;
        let timeline = Timeline::new(self.frames, geometry.frame_duration(), self.pause_s);
        let end = self.start_unix_s as f64 + timeline.end_s();
        let fits = end.is_finite() && end < LATEST_END_UNIX_S as f64;
        if self.start_unix_s < 0 || !fits {
            return Err(invalid(
                "sequence.start_unix_s",
                format!(
                    "the session ({} s from {}) must lie within 1970-01-01 ..= 2069-12-31 \
                     (0 ..< {LATEST_END_UNIX_S} s), the years an SM4 page date can hold",
                    timeline.end_s(),
                    self.start_unix_s
                ),
            ));
        }
        Ok(())
    }
}

impl DriftConfig {
    /// Checks every value finite and the period positive where the amplitude is not zero.
    pub fn validate(&self, field: &str) -> Result<(), SimulationError> {
        finite2(&format!("{field}.velocity_m_per_s"), self.velocity_m_per_s)?;
        finite2(
            &format!("{field}.acceleration_m_per_s2"),
            self.acceleration_m_per_s2,
        )?;
        finite2(&format!("{field}.oscillation_m"), self.oscillation_m)?;
        let period = format!("{field}.oscillation_period_s");
        match self.oscillation_period_s {
            Some(p) => positive(&period, p),
            None if self.oscillation_m == [0.0, 0.0] => Ok(()),
            None => Err(invalid(period, "is needed when oscillation_m is not zero")),
        }
    }

    /// The period `P` used, seconds: the configured one, or 1 s when there is no
    /// oscillation (then `P` has no effect).
    pub fn period_s(&self) -> f64 {
        self.oscillation_period_s.unwrap_or(1.0)
    }
}

impl CreepConfig {
    /// Checks `C` finite and `t0 > 0`.
    pub fn validate(&self, field: &str) -> Result<(), SimulationError> {
        finite2(&format!("{field}.coefficient_m"), self.coefficient_m)?;
        positive(&format!("{field}.t0_s"), self.t0_s)
    }
}
