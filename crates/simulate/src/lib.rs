//! Forward simulator of STM acquisition for dhct: a lattice surface scanned in trace and
//! retrace while drift, creep, hysteresis, scanner coupling, vibration, tip changes and
//! noise act, with the exact ground truth of every feature.
//!
//! ```
//! use dhct_simulate::{Simulation, presets};
//!
//! let mut config = presets::ci_small();
//! config.scan.columns = 64; // keep the doctest quick
//! config.scan.rows = 64;
//! config.scan.width_m = 1e-9;
//! config.scan.height_m = 1e-9;
//! let output = Simulation::from_config(&config).unwrap().run().unwrap();
//! assert_eq!(output.pair.trace().unwrap().z.dim(), (64, 64));
//! assert!(!output.truth.features.is_empty());
//! ```
//!
//! # Frames and signs
//!
//! * **Controller frame**: the display-oriented pixel grid of `dhct-scan` — x to the right
//!   (columns), y down (rows), pixel `(column, row)` centred at `(column·pitch_x,
//!   row·pitch_y)` metres. This is where the controller *commands* the tip.
//! * **Sample frame**: the same axes and origin, fixed to the sample. With no effects the
//!   two coincide.
//! * **Displacement**: the tip, commanded to `p_ctrl` at time `t` during pass `pass`, is at
//!   sample position `p_sample = p_ctrl + d(t, pass, …)`, where `d` is the sum of every
//!   [`Effect::displacement`]: the displacement of the tip *relative to the sample*
//!   (a sample drifting right is a tip drifting left).
//! * Each pixel's time comes from [`dhct_scan::ScanGeometry::acquisition_time`] (middle of
//!   the pixel's dwell; trace then retrace per line; optional turnaround). The pixel's value
//!   is the sample height at `p_sample`, then [`HeightEffect`]s, then noise.
//! * All public quantities are SI: metres, seconds, m/s, m/s², radians, Hz.
//! * A feature at true sample position `p_s` appears in a pass's image at the controller
//!   position solving `p_c + d(t(p_c), pass) = p_s` ([`truth`]).
//!
//! Consequences worth knowing (each checked by a test): a drift velocity `v` along the slow
//! direction stretches the slow scale (sample metres per line) by exactly `1 + v/v_slow`, so
//! the lattice looks compressed along the slow axis; hysteresis with `S > 1` at the line
//! start makes the lattice there look stretched along the fast axis, by `1/(2 − S) ≈ S`
//! (the DHCT convention, see [`effects::FastScanHysteresis`]).
//!
//! # Modules
//!
//! [`config`] (serde config), [`presets`], [`surface`] (sample model), [`effects`] (the
//! effect library), [`raster`] (the scan), [`noise`], [`truth`] (ground truth),
//! [`output`] (files), [`sequence`] (many frames of one area with drift continuous over
//! the session).

pub mod config;
pub mod effects;
mod error;
pub mod noise;
pub mod output;
pub mod presets;
pub mod raster;
mod region;
pub mod sequence;
mod simulation;
pub mod surface;
pub mod truth;

pub use config::{
    DefectConfig, FeatureShape, LatticeConfig, Lobe, Modulation, NoiseConfig, OutputConfig,
    OutputFormat, ScanConfig, SecondDomain, SimulationConfig, StepEdge, StrainRegion,
    SurfaceConfig, TipConfig,
};
pub use effects::{AcquisitionContext, Effect, EffectConfig, HeightEffect, HysteresisLaw};
pub use error::SimulationError;
pub use output::SimulationOutput;
pub use region::Region;
pub use sequence::{SequenceConfig, SequenceOutput, SequenceSimulation, SequenceTruth};
pub use simulation::{CHANNEL_NAME, Simulation};
pub use truth::{DisplacementField, FeatureAcquisition, FeatureTruth, GroundTruth};
