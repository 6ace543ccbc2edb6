//! The library behind the `dhct` command line: every subcommand (`correct`, `batch`,
//! `diagnose`, `info`, `simulate`) as functions, so that other front ends (the Python
//! package `dhct`) resolve options and write outputs exactly as the command line does.

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
pub mod read_limits;
pub mod report;
pub mod setup;
pub mod simulate;
pub mod units;
