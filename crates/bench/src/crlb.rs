//! The Cramér–Rao lower bound of a feature's position, computed from the simulation's
//! known feature shape and white noise (as in `crates/features/tests/precision.rs`): the
//! (x0, x0) element of the inverse Fisher matrix `(1/σ_n²) Σ ∇f ∇fᵀ` of the 7-parameter
//! model the feature fit uses (amplitude, x0, y0, three shape terms, background), summed
//! over the pixels of the fit disc, averaged over sub-pixel positions.
//!
//! It counts white noise only and an isolated Gaussian, so it is a lower bound: pink noise,
//! line offsets, neighbour overlap and the in-feature distortion add to the real error.

use dhct_numerics::crlb::{GaussianSpot, centre_crlb_px};

/// Per-axis CRLB of the centre (pixels) of a round Gaussian of standard deviation
/// `sigma_px` and peak `amplitude` under white noise of rms `noise` (same unit as
/// `amplitude`), fitted on the disc of radius `radius_px` around its nearest pixel, averaged
/// over sub-pixel positions ([`dhct_numerics::crlb`]). `None` if the Fisher matrix is
/// singular (e.g. zero amplitude or noise).
pub fn position_crlb_px(sigma_px: f64, amplitude: f64, noise: f64, radius_px: f64) -> Option<f64> {
    centre_crlb_px(&GaussianSpot {
        sigma_px,
        amplitude,
        noise,
        radius_px,
    })
}
