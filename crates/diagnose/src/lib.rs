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
//! [`validate`] runs the whole procedure on simulated scans with one effect withheld (and
//! on effect-free and two-effect scans) and tabulates identification and shrink.
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
//! use dhct_diagnose::{DiagnoseOptions, diagnose, synth};
//! use dhct_lattice::Hexagonal;
//!
//! // A simulated scan with a tip change the base model does not know about.
//! let case = synth::ValidationCase::single(
//!     dhct_diagnose::Candidate::TipChange,
//!     1,
//!     synth::ValidationSet::Tuned,
//! );
//! let scan = synth::simulate_positions(&case.config, 2e-12, 7).unwrap();
//! let report = diagnose(&scan.inputs(), &scan.geometry,
//!                       &Hexagonal::graphite(), &DiagnoseOptions::default()).unwrap();
//! println!("{report}");
//! assert_eq!(report.top(), Some(dhct_diagnose::Candidate::TipChange));
//! ```

mod along_line;
mod base;
mod candidates;
mod data;
mod diagnose;
mod error;
mod fit;
mod heights;
mod image_residual;
mod line_departures;
mod location;
mod model;
mod noise;
mod pair_images;
mod pass_phases;
mod report;
mod select;
mod spectrum;
mod sub_feature;
pub mod synth;
mod terms;
mod timing_gain;
mod validate;
mod verdict;

pub use along_line::{
    ALONG_LINE_FALSE_ALARM, AlongLinePeak, LATTICE_LINE_RATIO, LatticeSideband, MIN_SHARED_EXCESS,
};
pub use base::{BaseChoice, LawScore, PassLevelling};
pub use candidates::Candidate;
pub use data::{MIN_FEATURES, Observation};
pub use diagnose::{DiagnoseOptions, diagnose, diagnose_with_model};
pub use error::DiagnoseError;
pub use fit::FittedParameter;
pub use heights::{HEIGHT_CHANGE_MIN, HEIGHT_CHANGE_Z, HeightChange, HeightView};
pub use image_residual::{
    EXCESS_LINE_FACTOR, EXCESS_LINE_SPREADS, FAST_PHASE_BINS, LINE_JITTER_EVIDENCE,
    LINE_TILT_EVIDENCE, LineWindow, PassResidual, ResidualImage,
};
pub use location::{Bin, ChangePoint, GapLocation};
pub use noise::{FloorEstimate, FloorSource, FloorUnavailable, NoiseFloor};
pub use pair_images::{pair_views, sub_feature_view_of_pair, with_pair_views};
pub use pass_phases::{MIN_PHASE_AGREEMENT, MIN_STEADINESS, PHASE_MARGIN, PassPhases};
pub use report::{
    AddedEffect, DiagnosisReport, FeatureResidual, GapSummary, GreedyRound, ModelSummary,
    NEAR_TIE_FRACTION, Shrink,
};
pub use select::{CandidateScore, CvScheme, SelectionOptions};
pub use spectrum::{SpectralPeak, Spectrum};
pub use sub_feature::{
    ACROSS_SCATTER_LIMIT, MAX_SCATTER_LEFT, MIN_PASS_AGREEMENT, MIN_PERIODS_PER_LINE_ACROSS,
    OUTLIER_READING, PassImage, SIGNIFICANT_FALSE_ALARM, SliceVibration, SubFeatureView,
    sub_feature_view,
};
pub use validate::{
    ABSORBED_VISIBILITY, CaseKind, CaseResult, SetReport, SetSeeds, SetSummary, ValidationOptions,
    ValidationReport, rendered_held_out, second_rendered_held_out, third_rendered_held_out,
    validate,
};
pub use verdict::{GAP_THRESHOLD, GapPlace, PlaceKind, Verdict, VerdictKind};
