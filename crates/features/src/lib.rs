//! Feature indexing: find and sub-pixel fit every atom or molecule in an STM image (DHCT step 1-2).
//!
//! This crate is part of the dhct workspace; its pipeline stage is being built (see the
//! project's issues). It has no public API yet.
