//! dhct's application layer: every task of the command line (`correct`, `batch`,
//! `diagnose`, `apply` (images and points), `info`, `simulate`, `lattice check`) as functions, so that both
//! front ends — the `dhct` binary (crates/cli) and the Python package `dhct` — resolve
//! options, read inputs and write outputs the same way. Errors stay typed to the edge
//! ([`correct::CorrectError`]); [`hints`] renders a hint in the front end's own terms.

pub mod analysis;
pub mod apply;
pub mod batch;
pub mod correct;
pub mod diagnose;
pub mod flags;
pub mod hints;
pub mod info;
pub mod lattice_check;
pub mod output_dir;
pub mod points;
pub mod read_limits;
pub mod report;
pub mod series;
pub mod setup;
pub mod simulate;
pub mod units;
