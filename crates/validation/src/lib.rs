//! The validation of `dhct-diagnose` on simulated scans (not published; a bench-like
//! crate): a scan with base distortion plus one effect (or none, two, or one outside the
//! library) is diagnosed with the effect withheld from the base model; identification,
//! false alarms and how far the gap shrinks are tabulated per set.
//!
//! # Sets are data
//!
//! `crates/validation/sets.toml` holds every set ([`ValidationSet`]): the physics its
//! scans are drawn with ([`ScanForm`]: base law, images or positions, slow-scan
//! relaxation, noise, magnitude and vibration bands), its seeds, whether its numbers are
//! evidence and its history (`about`). A case is a seed; a held-out set is a table
//! committed before its first run. [`ValidationOptions::default`] is the shipped sweep.
//!
//! # Scoring
//!
//! Single effect: the top-ranked effect is the withheld one; effect-free: nothing added
//! and verdict `no_gap`; mixture: the first two distinct effects named are the two;
//! out of library: `unexplained`, or `partly_explained` with the remaining gap located;
//! scan coupling is *degenerate* (linear coupling equals lattice rotation + drift at the
//! position level): none or the truth. **Absorbed effects**: a single effect's
//! *visibility* is the base model's gap on the same scan without noise
//! ([`CaseResult::visibility`]); at ≤ [`ABSORBED_VISIBILITY`] the base model alone would
//! be `no_gap` even with the noise known exactly, so no diagnosis can demand the effect:
//! such a case is [`CaseKind::Absorbed`], right if nothing or the truth is named, and not
//! in top-1. This is a property of the scan, computed from the truth, never from the
//! diagnosis. Acceptance ([`SetSummary::accepted`]): top-1 ≥ 90 %, false alarms ≤ 1 in
//! 40, gap ≤ 1.2 × floor in ≥ 90 % of the correct single cases, ≥ 80 % of out-of-library
//! cases unexplained.
//!
//! # Example
//!
//! ```no_run
//! use dhct_validation::{ValidationCase, ValidationSet, simulate_positions};
//! use dhct_diagnose::{Candidate, DiagnoseOptions};
//!
//! let tuned = ValidationSet::named("tuned").unwrap();
//! let case = ValidationCase::single(Candidate::TipChange, 1, &tuned);
//! let scan = simulate_positions(&case.config, 2e-12, 7).unwrap();
//! let report = scan.diagnosed(&case.config, &DiagnoseOptions::default()).unwrap();
//! assert_eq!(report.top(), Some(Candidate::TipChange));
//! ```
//!
//! The sweep: `cargo run --release -p dhct-validation -- [SET...] [--seeds N] [--json]`.

mod base;
mod case;
mod run;
mod set;
mod simulated;
mod summary;

pub use base::{BaseLaw, base_config, base_config_with_law, rendered_look};
pub use case::{ForeignEffect, ValidationCase};
pub use run::{ValidationOptions, validate};
pub use set::{
    BaseForm, Catalogue, NoiseForm, ScanForm, SetError, SlowRelaxation, SweepPlan, ValidationSet,
};
pub use simulated::{
    PositionNoise, RenderedScan, SimulatedScan, simulate_images, simulate_positions,
    simulate_positions_with, simulate_rendered,
};
pub use summary::{
    ABSORBED_VISIBILITY, CaseKind, CaseResult, SetReport, SetSummary, ValidationReport,
};
