//! The Lattice trait and lattice fitting with integer indices (DHCT step 6).
//!
//! This crate is part of the dhct workspace; its pipeline stage is being built (see the
//! project's issues). It has no public API yet.
