//! Sim-to-real gap diagnosis (work in progress).
