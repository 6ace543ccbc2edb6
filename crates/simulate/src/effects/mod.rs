//! The distortion effects: one trait ([`Effect`]) for everything that displaces the tip
//! relative to the sample, one ([`HeightEffect`]) for deterministic changes of the measured
//! height, and the serde-tagged [`EffectConfig`] that lists them in a config file.
//!
//! Every effect is a plain struct whose fields are its parameters (SI units in the field
//! names) and which is its own config entry, so a fitting crate can build one, read its
//! [`Effect::parameters`], and make a modified copy with [`Effect::with_parameters`].
//!
//! # Sign convention
//!
//! [`Effect::displacement`] returns `d` in metres in the display frame (x right, y down) such
//! that the tip, commanded to controller position `p_ctrl`, is at sample position
//! `p_sample = p_ctrl + d`. `d` is the displacement of the tip *relative to the sample*: a
//! sample drifting to the right relative to the instrument is a tip drifting to the left,
//! `d.x < 0`. The total displacement is the sum over all effects.

mod coupling;
mod creep;
mod drift;
mod hysteresis;
mod out_of_library;
mod piezo;
mod scanner_gain;
mod session_drift;
mod tip_change;
mod vibration;

use std::fmt::Debug;

use dhct_scan::{ScanDirection, ScanGeometry, ScanPass};
use nalgebra::Vector2;
use serde::{Deserialize, Serialize};

use crate::SimulationError;

pub use coupling::{HeightCoupling, ScanCoupling};
pub use creep::{ExponentialCreep, LogCreep};
pub use drift::{LineDrift, ThermalDrift};
pub use hysteresis::{AsymmetricHysteresis, FastScanHysteresis, HysteresisLaw, SlowScanHysteresis};
pub use out_of_library::{LineJitter, StrainBubble, TelegraphTip};
pub use piezo::PiezoNonlinearity;
pub use scanner_gain::ScannerGain;
pub use session_drift::SessionDrift;
pub use tip_change::TipChange;
pub use vibration::Vibration;

/// Where and when the tip is: everything an effect may depend on.
#[derive(Debug, Clone, Copy)]
pub struct AcquisitionContext<'a> {
    /// The scan (size, pitch, timing, directions).
    pub geometry: &'a ScanGeometry,
    /// Trace or retrace.
    pub pass: ScanPass,
    /// Seconds since the start of the frame (first trace line), from
    /// [`ScanGeometry::acquisition_time`].
    pub time_since_frame_start: f64,
    /// Seconds since the start of the current line, in this pass's own fast direction.
    pub time_since_line_start: f64,
    /// The commanded (controller) tip position, metres, display frame:
    /// `(column · pitch_x, row · pitch_y)`, pixel (0, 0) centre at the origin.
    pub controller: Vector2<f64>,
    /// Height of the sample's terrace under the tip (step offsets, no atomic corrugation),
    /// metres; used by [`HeightCoupling`]. Zero while the height-independent effects are
    /// summed (see [`Effect::uses_surface_height`]).
    pub surface_height: f64,
}

impl<'a> AcquisitionContext<'a> {
    /// The context of controller position `(x, y)` in pixels (column, row; sub-pixel
    /// allowed) during `pass`, with its acquisition time from the scan geometry.
    pub fn at_pixel(
        geometry: &'a ScanGeometry,
        pass: ScanPass,
        x: f64,
        y: f64,
        surface_height: f64,
    ) -> AcquisitionContext<'a> {
        let time = geometry.acquisition_time(pass, x, y);
        AcquisitionContext {
            geometry,
            pass,
            time_since_frame_start: time.since_frame_start,
            time_since_line_start: time.since_line_start,
            controller: Vector2::new(x * geometry.pitch_x(), y * geometry.pitch_y()),
            surface_height,
        }
    }

    /// The controller position normalised to `[−1, 1]` across the image, `[ξ, η]`: −1 at
    /// the first pixel centre of each axis, +1 at the last.
    pub fn normalised_position(&self) -> [f64; 2] {
        let g = self.geometry;
        let (w, h) = (
            (g.columns() as f64 - 1.0).max(1.0) * g.pitch_x(),
            (g.rows() as f64 - 1.0).max(1.0) * g.pitch_y(),
        );
        [
            2.0 * self.controller.x / w - 1.0,
            2.0 * self.controller.y / h - 1.0,
        ]
    }
}

/// A mechanism that displaces the tip relative to the sample during acquisition.
///
/// Implementations are pure functions of the [`AcquisitionContext`]: the simulator sums
/// them per pixel, and a diagnosis crate can fit their [`parameters`](Effect::parameters)
/// to measured feature displacements.
pub trait Effect: Send + Sync + Debug {
    /// The effect's config kind, e.g. `"thermal-drift"`.
    fn name(&self) -> &'static str;

    /// Tip displacement relative to the sample (metres, display frame, x right, y down):
    /// `p_sample = p_ctrl + d`.
    fn displacement(&self, at: &AcquisitionContext) -> Vector2<f64>;

    /// Names (with units) of the numbers returned by [`Effect::parameters`].
    fn parameter_names(&self) -> Vec<&'static str>;

    /// The effect's parameters, in SI units, in the order of [`Effect::parameter_names`].
    fn parameters(&self) -> Vec<f64>;

    /// A copy with new parameters (same order as [`Effect::parameters`]); validated like a
    /// config entry.
    fn with_parameters(&self, parameters: &[f64]) -> Result<Box<dyn Effect>, SimulationError>;

    /// True if [`Effect::displacement`] reads [`AcquisitionContext::surface_height`].
    fn uses_surface_height(&self) -> bool {
        false
    }

    /// The config entry that builds this effect.
    fn config(&self) -> EffectConfig;
}

/// A deterministic change of the measured height (random noise is in [`crate::noise`]).
pub trait HeightEffect: Send + Sync + Debug {
    /// The effect's config kind.
    fn name(&self) -> &'static str;
    /// The measured height (metres) given the surface height `z` under the tip.
    fn apply(&self, z: f64, at: &AcquisitionContext) -> f64;
}

/// One `[[effects]]` entry of a config file, tagged by `kind`.
///
/// ```toml
/// [[effects]]
/// kind = "thermal-drift"
/// velocity_m_per_s = [1e-11, 0.0]
///
/// [[effects]]
/// kind = "fast-hysteresis"
/// law = { kind = "power", k = 0.93, n = -0.035 }
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case")]
pub enum EffectConfig {
    /// 1: constant velocity and acceleration.
    ThermalDrift(ThermalDrift),
    /// 2 and 8: piezo creep, velocity `C/(t − start + t0)`.
    Creep(LogCreep),
    /// 8: creep relaxing exponentially.
    ExponentialCreep(ExponentialCreep),
    /// 3: fast-scan hysteresis, trace and retrace mirrored.
    FastHysteresis(FastScanHysteresis),
    /// 10: fast-scan hysteresis with different laws in trace and retrace.
    AsymmetricHysteresis(AsymmetricHysteresis),
    /// 9: slow-scan hysteresis at frame start.
    SlowHysteresis(SlowScanHysteresis),
    /// 4: drift that only acts within each line (a fast-axis stretch differing in trace
    /// and retrace).
    LineDrift(LineDrift),
    /// 5: slow-to-fast and fast-to-slow coupling.
    ScanCoupling(ScanCoupling),
    /// 11: lateral shift proportional to the terrace height (T_fz).
    HeightCoupling(HeightCoupling),
    /// 6: sinusoidal vibration.
    Vibration(Vibration),
    /// 7: sudden lateral jump, with optional height and contrast change.
    TipChange(TipChange),
    /// The scanner's displacement not proportional to its drive (per axis, in position).
    PiezoNonlinearity(PiezoNonlinearity),
    /// A tip switching irregularly between two apexes (outside the diagnosis library).
    TelegraphTip(TelegraphTip),
    /// A local radial strain bubble (outside the diagnosis library).
    StrainBubble(StrainBubble),
    /// Every scan line displaced by its own random offset (outside the diagnosis library).
    LineJitter(LineJitter),
    /// The thermal drift of a session of frames as one frame sees it (written by
    /// [`crate::sequence`] into each frame's config).
    SessionDrift(SessionDrift),
    /// A scanner whose piezo axes move the tip by a factor times what they were told.
    ScannerGain(ScannerGain),
}

impl EffectConfig {
    /// The config kind, e.g. `"thermal-drift"`.
    pub fn kind(&self) -> &'static str {
        self.as_effect().name()
    }

    fn as_effect(&self) -> &dyn Effect {
        match self {
            EffectConfig::ThermalDrift(e) => e,
            EffectConfig::Creep(e) => e,
            EffectConfig::ExponentialCreep(e) => e,
            EffectConfig::FastHysteresis(e) => e,
            EffectConfig::AsymmetricHysteresis(e) => e,
            EffectConfig::SlowHysteresis(e) => e,
            EffectConfig::LineDrift(e) => e,
            EffectConfig::ScanCoupling(e) => e,
            EffectConfig::HeightCoupling(e) => e,
            EffectConfig::Vibration(e) => e,
            EffectConfig::TipChange(e) => e,
            EffectConfig::PiezoNonlinearity(e) => e,
            EffectConfig::TelegraphTip(e) => e,
            EffectConfig::StrainBubble(e) => e,
            EffectConfig::LineJitter(e) => e,
            EffectConfig::SessionDrift(e) => e,
            EffectConfig::ScannerGain(e) => e,
        }
    }

    /// Checks every parameter; `field` names the entry in error messages (`effects[2]`).
    pub fn validate(&self, field: &str) -> Result<(), SimulationError> {
        match self {
            EffectConfig::ThermalDrift(e) => e.validate(field),
            EffectConfig::Creep(e) => e.validate(field),
            EffectConfig::ExponentialCreep(e) => e.validate(field),
            EffectConfig::FastHysteresis(e) => e.validate(field),
            EffectConfig::AsymmetricHysteresis(e) => e.validate(field),
            EffectConfig::SlowHysteresis(e) => e.validate(field),
            EffectConfig::LineDrift(e) => e.validate(field),
            EffectConfig::ScanCoupling(e) => e.validate(field),
            EffectConfig::HeightCoupling(e) => e.validate(field),
            EffectConfig::Vibration(e) => e.validate(field),
            EffectConfig::TipChange(e) => e.validate(field),
            EffectConfig::TelegraphTip(e) => e.validate(field),
            EffectConfig::StrainBubble(e) => e.validate(field),
            EffectConfig::LineJitter(e) => e.validate(field),
            EffectConfig::PiezoNonlinearity(e) => e.validate(field),
            EffectConfig::SessionDrift(e) => e.validate(field),
            EffectConfig::ScannerGain(e) => e.validate(field),
        }
    }

    /// Validates and builds the displacement effect.
    pub fn build(&self, field: &str) -> Result<Box<dyn Effect>, SimulationError> {
        self.validate(field)?;
        Ok(match self {
            EffectConfig::ThermalDrift(e) => Box::new(e.clone()),
            EffectConfig::Creep(e) => Box::new(e.clone()),
            EffectConfig::ExponentialCreep(e) => Box::new(e.clone()),
            EffectConfig::FastHysteresis(e) => Box::new(e.clone()),
            EffectConfig::AsymmetricHysteresis(e) => Box::new(e.clone()),
            EffectConfig::SlowHysteresis(e) => Box::new(e.clone()),
            EffectConfig::LineDrift(e) => Box::new(e.clone()),
            EffectConfig::ScanCoupling(e) => Box::new(e.clone()),
            EffectConfig::HeightCoupling(e) => Box::new(e.clone()),
            EffectConfig::Vibration(e) => Box::new(e.clone()),
            EffectConfig::TipChange(e) => Box::new(e.clone()),
            EffectConfig::TelegraphTip(e) => Box::new(e.clone()),
            EffectConfig::StrainBubble(e) => Box::new(e.clone()),
            EffectConfig::LineJitter(e) => Box::new(e.clone()),
            EffectConfig::PiezoNonlinearity(e) => Box::new(e.clone()),
            EffectConfig::SessionDrift(e) => Box::new(e.clone()),
            EffectConfig::ScannerGain(e) => Box::new(e.clone()),
        })
    }

    /// The height-changing part of this effect, if it has one (tip change contrast).
    pub fn height_effect(&self) -> Option<Box<dyn HeightEffect>> {
        match self {
            EffectConfig::TipChange(e) if e.changes_height() => Some(Box::new(e.clone())),
            _ => None,
        }
    }
}

/// Unit vector of a scan direction in the display frame (x right, y down).
pub fn direction_vector(direction: ScanDirection) -> Vector2<f64> {
    match direction {
        ScanDirection::Right => Vector2::new(1.0, 0.0),
        ScanDirection::Left => Vector2::new(-1.0, 0.0),
        ScanDirection::Down => Vector2::new(0.0, 1.0),
        ScanDirection::Up => Vector2::new(0.0, -1.0),
    }
}

pub(crate) fn vector([x, y]: [f64; 2]) -> Vector2<f64> {
    Vector2::new(x, y)
}
