//! The Cramér–Rao lower bound of a feature's position, computed from the simulation's
//! known feature shape and white noise (as in `crates/features/tests/precision.rs`): the
//! (x0, x0) element of the inverse Fisher matrix `(1/σ_n²) Σ ∇f ∇fᵀ` of the 7-parameter
//! model the feature fit uses (amplitude, x0, y0, three shape terms, background), summed
//! over the pixels of the fit disc, averaged over sub-pixel positions.
//!
//! It counts white noise only and an isolated Gaussian, so it is a lower bound: pink noise,
//! line offsets, neighbour overlap and the in-feature distortion add to the real error.

use nalgebra::{SMatrix, SVector};

/// Per-axis CRLB of the centre (pixels) of a round Gaussian of standard deviation
/// `sigma_px` and peak `amplitude` under white noise of rms `noise` (same unit as
/// `amplitude`), fitted on the disc of radius `radius_px` around its nearest pixel.
/// `None` if the Fisher matrix is singular (e.g. zero amplitude or noise).
pub fn position_crlb_px(sigma_px: f64, amplitude: f64, noise: f64, radius_px: f64) -> Option<f64> {
    const OFFSETS: usize = 4;
    let mut variance = 0.0;
    for i in 0..OFFSETS {
        for j in 0..OFFSETS {
            let centre = [
                (i as f64 + 0.5) / OFFSETS as f64 - 0.5,
                (j as f64 + 0.5) / OFFSETS as f64 - 0.5,
            ];
            variance += crlb_x_at(centre, sigma_px, amplitude, noise, radius_px)?;
        }
    }
    Some((variance / (OFFSETS * OFFSETS) as f64).sqrt())
}

/// CRLB variance of x0 (px²) for a Gaussian centred at `centre` (px from pixel 0, 0).
fn crlb_x_at(
    centre: [f64; 2],
    sigma_px: f64,
    amplitude: f64,
    noise: f64,
    radius_px: f64,
) -> Option<f64> {
    let q = 1.0 / (sigma_px * sigma_px);
    let mut fisher = SMatrix::<f64, 7, 7>::zeros();
    let reach = radius_px.ceil() as i64;
    for dr in -reach..=reach {
        for dc in -reach..=reach {
            if ((dr * dr + dc * dc) as f64) > radius_px * radius_px {
                continue;
            }
            let (dx, dy) = (dc as f64 - centre[0], dr as f64 - centre[1]);
            let e = (-0.5 * q * (dx * dx + dy * dy)).exp();
            let ae = amplitude * e;
            let g = SVector::<f64, 7>::from([
                e,
                ae * q * dx,
                ae * q * dy,
                -0.5 * ae * dx * dx,
                -ae * dx * dy,
                -0.5 * ae * dy * dy,
                1.0,
            ]);
            fisher += g * g.transpose() / (noise * noise);
        }
    }
    fisher.try_inverse().map(|inverse| inverse[(1, 1)])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bound_scales_with_noise_over_amplitude() {
        let a = position_crlb_px(2.5, 1.0, 0.1, 6.4).unwrap();
        let b = position_crlb_px(2.5, 1.0, 0.2, 6.4).unwrap();
        assert!((b / a - 2.0).abs() < 1e-9, "{a} {b}");
        // Untruncated, all else known: σ_x = (σ_n / A)·sqrt(2/π) px; the disc and the six
        // other parameters can only raise it, a little (radius 2.56 σ, decoupled by symmetry).
        let ideal = 0.1 * (2.0 / std::f64::consts::PI).sqrt();
        assert!(a >= 0.999 * ideal && a < 1.3 * ideal, "{a} vs {ideal}");
    }
}
