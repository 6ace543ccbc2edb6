//! Sim-to-real gap diagnosis for DHCT (issue 8): where the fitted drift/creep/hysteresis
//! model misses, which unmodelled effect explains the miss, and how far the gap shrinks
//! when that effect is added.
//!
//! # What [`diagnose`] does
//!
//! 1. **Sim**: the base DHCT fit ([`dhct_distortion::analyse`]; [`diagnose_with_model`]
//!    takes a correction already made instead, e.g. the pipeline's), the lattice fitted to
//!    the corrected features (every feature gets its ideal site), and each ideal site pushed
//!    back through the fitted distortion to a predicted controller position. The **gap** is
//!    `measured − predicted` ([`DiagnosisReport::dhct`]).
//! 2. **Position-level base fit**: drift, acceleration, creep `C`, `t0`, the hysteresis
//!    law and the lattice origin and angle fitted together to all feature positions,
//!    minimising `|to_sample(measured, t) − ideal site|²` (see `model`'s docs). The
//!    simulator's own effects ([`dhct_simulate::Effect`]) are the model terms. The creep's
//!    `t0` is profiled (a grid from one line period to ten frames, every other parameter
//!    fitted at each point): fitted freely it does not converge, since with drift and
//!    acceleration free `C·ln(1 + t/t0)` has a long valley towards large `t0`.
//! 3. **Noise floor** ([`NoiseFloor`]), independent of the model: trace/retrace pairs of the
//!    same site (for one pass, successive differences of neighbouring features within a
//!    line), cross-checked by the feature fits' own uncertainties. Gap/noise and χ²/dof
//!    follow.
//! 4. **Where** ([`GapLocation`]): residuals binned by frame time, fast phase, position,
//!    pass and feature height; a Lomb–Scargle spectrum; change points.
//! 5. **Which effect** ([`Candidate`]): every candidate is screened on a grid of its shape
//!    parameters (a creep's onset then refined around the best grid point), scored by
//!    cross-validation (time blocks for persistent effects, interleaved lines for
//!    transients) and by BIC/AIC, the best refitted in full (base `t0` profiled again);
//!    greedily combined; "no effect needed" when none passes.
//! 6. **Shrink** ([`Shrink`]): gap/noise before, after the top effect, after the set,
//!    with the added effects' parameters and uncertainties.
//!
//! The `dhct-validation` crate (not published) runs the whole procedure on simulated scans
//! with one effect withheld (and on effect-free and two-effect scans) and tabulates
//! identification and shrink; its sets are data (`crates/validation/sets.toml`).
//!
//! # Frames and units
//!
//! Controller frame = the display-oriented pixel grid of `dhct-scan` (x right, y down);
//! sample frame = the same axes fixed to the sample. Displacements `d` follow the simulator:
//! `p_sample = p_controller + d`. Every public quantity is SI (metres, seconds, Hz);
//! residuals are sample-frame metres, equal to first order to the controller-frame gap.
//!
//! # Example
//!
//! ```no_run
//! use dhct_diagnose::{DiagnoseOptions, diagnose};
//! use dhct_distortion::PassInput;
//! use dhct_features::{FeatureOptions, find_features_in_pair};
//! use dhct_lattice::Hexagonal;
//! use dhct_simulate::{Simulation, presets};
//!
//! // A simulated graphite pair; any scan with its features found will do.
//! let output = Simulation::from_config(&presets::ci_small()).unwrap().run().unwrap();
//! let options = FeatureOptions::for_neighbour_distance(1.42e-10);
//! let sets = find_features_in_pair(&output.pair, &options).unwrap();
//! let inputs = [0, 1].map(|k| PassInput { features: &sets[k].features, mask: None });
//! let report = diagnose(&inputs, output.pair.geometry(), &Hexagonal::graphite(),
//!                       &DiagnoseOptions::default()).unwrap();
//! println!("{report}"); // the verdict, where the gap lies, which effect explains it
//! ```

// The steps, one folder each: the model and its fit; the search for effects; the evidence
// read from the positions; the view of the images; the report and its verdict.
mod diagnose;
mod error;

/// The position-level model: observations, displacement terms, the base law, the fit.
mod model {
    pub(crate) mod base;
    pub(crate) mod data;
    pub(crate) mod fit;
    pub(crate) mod global;
    pub(crate) mod terms;
    pub(crate) mod timing_gain;
}

/// The search for effects: candidates, their scores and the greedy selection.
mod search {
    pub(crate) mod candidates;
    pub(crate) mod select;
}

/// What the positions show: the noise floor, where the gap lies, its spectrum, heights.
mod evidence {
    pub(crate) mod heights;
    pub(crate) mod location;
    pub(crate) mod noise;
    pub(crate) mod spectrum;
}

/// What only the images show: residual images, line departures, the lines' spectrum and
/// its phases, the slices below one feature.
mod image_view {
    pub(crate) mod along_line;
    pub(crate) mod image_residual;
    pub(crate) mod line_departures;
    pub(crate) mod line_spectrum;
    pub(crate) mod pair_images;
    pub(crate) mod pass_phases;
    pub(crate) mod sub_feature;
}

/// The serialisable report and its verdict.
mod report {
    pub(crate) mod diagnosis;
    pub(crate) mod gap;
    pub(crate) mod pass_offset;
    pub(crate) mod verdict;
    pub(crate) mod with_views;
}

pub use diagnose::{DiagnoseOptions, diagnose, diagnose_with_model};
pub use error::DiagnoseError;
pub use evidence::heights::{HEIGHT_CHANGE_MIN, HEIGHT_CHANGE_Z, HeightChange, HeightView};
pub use evidence::location::{Bin, ChangePoint, GapLocation};
pub use evidence::noise::{FloorEstimate, FloorSource, FloorUnavailable, NoiseFloor};
pub use evidence::spectrum::{SIGNIFICANT_FALSE_ALARM, SpectralPeak, Spectrum};
pub use image_view::along_line::{
    ALONG_LINE_FALSE_ALARM, AlongLinePeak, LATTICE_LINE_RATIO, LatticeSideband, MIN_SHARED_EXCESS,
};
pub use image_view::image_residual::{
    EXCESS_LINE_FACTOR, EXCESS_LINE_SPREADS, FAST_PHASE_BINS, LINE_JITTER_EVIDENCE,
    LINE_TILT_EVIDENCE, LineWindow, PassResidual, ResidualImage,
};
pub use image_view::pair_images::{pair_views, sub_feature_view_of_pair, with_pair_views};
pub use image_view::pass_phases::{MIN_PHASE_AGREEMENT, MIN_STEADINESS, PHASE_MARGIN, PassPhases};
pub use image_view::sub_feature::{
    ACROSS_SCATTER_LIMIT, MAX_SCATTER_LEFT, MIN_PASS_AGREEMENT, MIN_PERIODS_PER_LINE_ACROSS,
    OUTLIER_READING, PassImage, SliceVibration, SubFeatureView, sub_feature_view,
};
pub use model::base::{BaseChoice, LawScore, PassLevelling, WholeModelScore};
pub use model::data::{MIN_FEATURES, Observation};
pub use model::fit::FittedParameter;
pub use report::diagnosis::{DiagnosisReport, GreedyRound, ModelSummary};
pub use report::gap::{AddedEffect, FeatureResidual, GapSummary, NEAR_TIE_FRACTION, Shrink};
pub use report::pass_offset::{PASS_OFFSET_FLOORS, PassOffsetReading};
pub use report::verdict::{GAP_THRESHOLD, GapPlace, PlaceKind, Verdict, VerdictKind};
pub use search::candidates::Candidate;
pub use search::select::{CandidateScore, CvScheme, SelectionOptions};
