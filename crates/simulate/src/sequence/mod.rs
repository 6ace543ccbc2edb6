//! Image sequences: many frames of one sample area taken one after another, with drift and
//! creep continuous over the whole session, optional moves of the scan frame (each
//! restarting creep) and a scan angle per frame — with the ground truth of every frame.
//!
//! # Frames and times
//!
//! * **Instrument (session) frame**: metres in the display axes (x right, y down) of the
//!   unrotated scanner, fixed to the sample. Frame `k`'s controller position `p` (its own
//!   display frame) is at `to_instrument(p) = O_k + R(φ_k)(p − c)`
//!   ([`dhct_scan::ScanGeometry::to_instrument`]).
//! * **Session time** `T`: seconds since frame 0's first line. `T_0 = 0`,
//!   `T_k = ⌈T_{k−1} + frame_duration + pause⌉` (whole seconds).
//! * **Session drift** `D(T)` (instrument frame): `v·T + a·T²/2 + A∘sin(2πT/P)` plus
//!   `C_m·ln(1 + (T − T_m)/t0_m)` for every creep (the initial one at `T = 0`, each move's at
//!   the start of its frame). `D(0) = 0`.
//! * The tip of frame `k` at controller position `p` and frame time `t` is at instrument
//!   position `to_instrument(p + d_raster(t)) + D(T_k + t)`, `d_raster` the base config's
//!   effects (hysteresis, coupling …, in the image's own frame).
//!
//! Each frame is an ordinary [`crate::Simulation`] ([`frame`] explains how);
//! [`SequenceSimulation::write`] runs and writes them one at a time.
//!
//! ```
//! use dhct_simulate::{SequenceSimulation, presets};
//!
//! let mut config = presets::by_name("graphite-sequence").unwrap();
//! config.scan.columns = 32; // keep the doctest quick
//! config.scan.rows = 32;
//! config.scan.width_m = 0.5e-9;
//! config.scan.height_m = 0.5e-9;
//! let sequence = SequenceSimulation::from_config(&config).unwrap();
//! let frame = sequence.run_frame(1).unwrap();
//! assert_eq!(frame.truth.placement.start_unix_s, 1_800_000_000 + frame.truth.placement.start_s as i64);
//! ```

mod base;
pub mod config;
pub mod frame;
pub mod motion;
mod output;
mod simulation;
pub mod timeline;
pub mod truth;

pub use config::{CreepConfig, DriftConfig, MoveConfig, SequenceConfig};
pub use frame::{FramePlacement, frame_seed};
pub use motion::{CreepEvent, SessionMotion};
pub use output::{SEQUENCE_TRUTH_FILE, frame_prefix};
pub use simulation::{FrameOutput, SequenceOutput, SequenceSimulation};
pub use timeline::Timeline;
pub use truth::{FrameTruth, SequenceFeature, SequenceTruth, TrajectorySample};
