//! Nearest neighbours, local distortion, the drift/creep/hysteresis model and the correction (DHCT steps 3-5).
//!
//! This crate is part of the dhct workspace; its pipeline stage is being built (see the
//! project's issues). It has no public API yet.
