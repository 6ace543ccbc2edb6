//! Confidence ellipses, translationally and symmetry-averaged unit cells (DHCT step 6).
//!
//! This crate is part of the dhct workspace; its pipeline stage is being built (see the
//! project's issues). It has no public API yet.
