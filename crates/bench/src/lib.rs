//! Benchmarks of the whole DHCT chain at scale (issue 9): per-stage wall time and peak
//! memory on the paper's headline case (graphite, 2048² trace + retrace over 25 nm, from
//! `dhct-simulate`), the scaling curve over image size, accuracy against the simulator's
//! ground truth, a robustness sweep, and a determinism check across thread counts.
//!
//! Everything here is measured on simulated data whose truth is known, or (the `real`
//! binary, [`real_corpus`]) on real files judged from their corrected image alone; nothing
//! is hard-coded. The `headline` binary prints the tables and writes them as JSON; the tests
//! in `tests/` run a small robustness sweep and the determinism check.

pub mod accuracy;
pub mod crlb;
pub mod determinism;
pub mod known_lattice;
pub mod machine;
pub mod measure;
pub mod real_corpus;
pub mod real_diagnosis;
pub mod regularity;
pub mod robustness;
pub mod scenario;
pub mod table;
