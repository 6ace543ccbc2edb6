//! Many frames of one area, one model: drift continuous in session time (a cubic spline
//! whose knots are chosen by cross-validation), a logarithmic creep after every move of the
//! scan frame, and one fast-scan hysteresis law, fitted jointly to every indexed feature of
//! every frame with the lattice of the known constant as the internal standard.
//!
//! # Frames, clocks, signs
//!
//! * **Instrument frame** (the session's common frame): metres, display axes (x right,
//!   y down) of the unrotated scanner; a frame's controller position `p` maps to
//!   [`dhct_scan::ScanGeometry::to_instrument`]`(p)` (its centre to its offset, turned by its
//!   scan angle).
//! * **Session time** `T`: seconds since the first frame's start.
//! * **Session frame**: the instrument frame fixed to the sample, placed where the first
//!   frame's files put it on average (`D` averages to zero over the first frame's features).
//! * The tip at controller position `p` of frame `k` at frame time `t`, line time `τ`, is at
//!   sample position `to_instrument(p + h(τ)) + D(T_k + t)`: the hysteresis lag `h` acts
//!   along the frame's own fast axis, the drift `D` ([`SessionDrift`]) in the instrument
//!   frame, continuous over the whole session.
//!
//! A perfect lattice places a frame only modulo a lattice vector; the drift's continuity
//! picks the vector ([`alignment`]), so a frame must follow the one before it closely enough
//! that the drift carried over it is right to half a cell, unless the two images show where
//! it lies ([`ObservedStep`]: defects, steps and the like, seen by correlation).

pub mod alignment;
mod fit;
mod frame;
mod image_drift;
mod problem;
mod registered_image;
mod session_drift;
mod spline;

pub use fit::{
    GAIN_RANGE, KnotChoice, KnotScore, MAX_SERIES_FITTED, SeriesFit, SeriesOptions,
    TrajectoryPoint, fit_series,
};
pub use frame::{ObservedStep, SeriesFeature, SeriesFrame};
pub use image_drift::{
    DifferenceDriftFit, DriftDifference, ImageRegistration, MoveTiming, fit_drift_differences,
};
pub use registered_image::{SessionPlacement, register_image, register_image_sampled};
pub use session_drift::{MoveCreep, SessionDrift};
pub use spline::SplineBasis;
