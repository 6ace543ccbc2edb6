//! One frame of a sequence as an ordinary simulation: its placement (time, scan angle,
//! offset), its geometry and its config.
//!
//! Frame `k` (start `T_k`, scan angle `φ_k`, centre `O_k`) commands the tip to controller
//! position `p` at frame time `t`; the tip is then at instrument position
//!
//! `q = to_instrument(p + d_raster(t)) + D(T_k + t)`,
//!
//! `d_raster` the base config's effects (hysteresis …, in the image's own frame) and `D`
//! the session drift. Since `to_instrument` is affine, `q = to_instrument(p_sim) + D(T_k)`
//! with `p_sim = p + d_raster(t) + d_k(t)`, `d_k(t) = R(−φ_k)·(D(T_k + t) − D(T_k))`: frame
//! `k` is the base simulation plus the effects `d_k` (a `session-drift` effect and one
//! `creep` per creep under way), imaging the common surface seen through
//! `q = to_instrument(p_sim) + D(T_k)`. A common lattice site `r` (instrument frame) is
//! thus at `p_sim = from_instrument(r − D(T_k))`; the lattice of angle `θ` and origin `o`
//! becomes the lattice of angle `θ + φ_k` (the surface's angle runs from +x towards +y,
//! clockwise on screen, the scan angle counter-clockwise) and origin
//! `from_instrument(o − D(T_k))`.

use dhct_scan::ScanGeometry;
use serde::{Deserialize, Serialize};

use crate::SimulationError;
use crate::config::SimulationConfig;
use crate::effects::{EffectConfig, LogCreep};
use crate::sequence::config::SequenceConfig;
use crate::sequence::motion::SessionMotion;
use crate::sequence::timeline::Timeline;

/// Where and when one frame of a sequence is taken.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FramePlacement {
    /// Frame number, 0-based.
    pub index: usize,
    /// `T_k`: start, seconds of session time (whole seconds).
    pub start_s: f64,
    /// Start, whole seconds since 1970-01-01 (what the frame's file records).
    pub start_unix_s: i64,
    /// `φ_k`: scan angle, radians counter-clockwise on screen.
    pub scan_angle_rad: f64,
    /// `O_k`: frame centre, metres, instrument frame.
    pub offset_m: [f64; 2],
    /// `D(T_k)`: the session drift at the frame's start, metres, instrument frame.
    pub displacement_at_start_m: [f64; 2],
}

impl FramePlacement {
    /// The placement of frame `k` (`None` past the last frame).
    pub(crate) fn of(
        k: usize,
        sequence: &SequenceConfig,
        timeline: &Timeline,
        motion: &SessionMotion,
    ) -> Option<FramePlacement> {
        let start_s = timeline.start_s(k)?;
        Some(FramePlacement {
            index: k,
            start_s,
            start_unix_s: sequence.start_unix_s + start_s as i64,
            scan_angle_rad: sequence.scan_angle_rad(k),
            offset_m: sequence.offset_of_frame(k),
            displacement_at_start_m: motion.displacement(start_s),
        })
    }

    /// The frame's geometry: the base geometry with this scan angle, offset and start time.
    pub fn geometry(&self, base: &ScanGeometry) -> Result<ScanGeometry, SimulationError> {
        Ok(base
            .clone()
            .with_scan_angle(self.scan_angle_rad)?
            .with_offset(self.offset_m[0], self.offset_m[1])?
            .with_start_time(Some(self.start_unix_s as f64)))
    }

    /// Instrument-frame position (metres) of a point at `p_sim` (metres) of this frame's
    /// simulated sample frame: `to_instrument(p_sim) + D(T_k)`.
    pub fn to_session(&self, geometry: &ScanGeometry, p_sim: [f64; 2]) -> [f64; 2] {
        let q = geometry.to_instrument(p_sim);
        let d = self.displacement_at_start_m;
        [q[0] + d[0], q[1] + d[1]]
    }
}

/// The config of frame `k`: the base config (without `[sequence]`) with its own noise seed,
/// the lattice turned by `φ_k` and shifted to `from_instrument(o − D(T_k))`, and the
/// effects `d_k` appended (`session-drift`, then one `creep` per creep under way, then the
/// `scanner-gain` when the scanner's gain is not 1).
pub(crate) fn frame_config(
    base: &SimulationConfig,
    motion: &SessionMotion,
    placement: &FramePlacement,
    geometry: &ScanGeometry,
    scanner_gain: [f64; 2],
) -> SimulationConfig {
    let mut config = base.clone();
    config.sequence = None;
    config.seed = frame_seed(base.seed, placement.index);
    // The same sites empty in every frame: the vacancies belong to the sample.
    config.surface.defects.vacancy_seed =
        Some(base.surface.defects.vacancy_seed.unwrap_or(base.seed));
    let [ox, oy] = base.surface.origin_m;
    let [dx, dy] = placement.displacement_at_start_m;
    config.surface.angle_rad = base.surface.angle_rad + placement.scan_angle_rad;
    config.surface.origin_m = geometry.from_instrument([ox - dx, oy - dy]);
    for effect in &mut config.effects {
        if let EffectConfig::LineJitter(jitter) = effect {
            jitter.seed = frame_seed(jitter.seed, placement.index);
        }
    }
    config.effects.push(EffectConfig::SessionDrift(
        motion.thermal_for_frame(placement.start_s, placement.scan_angle_rad),
    ));
    if scanner_gain != [1.0, 1.0] {
        config
            .effects
            .push(EffectConfig::ScannerGain(crate::effects::ScannerGain {
                gain: scanner_gain,
                scan_angle_rad: placement.scan_angle_rad,
            }));
    }
    for creep in motion.creeps_started_by(placement.start_s) {
        config.effects.push(EffectConfig::Creep(LogCreep {
            coefficient_m: geometry.vector_from_instrument(creep.coefficient_m),
            t0_s: creep.t0_s + (placement.start_s - creep.start_s),
            start_s: 0.0,
        }));
    }
    config
}

/// The random seed of frame `k` (noise, line jitter): the sequence's seed mixed with the
/// frame number (splitmix64), so frames draw independent noise.
pub fn frame_seed(seed: u64, k: usize) -> u64 {
    let mut z = seed ^ (k as u64 + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}
