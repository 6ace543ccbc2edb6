//! What a local distortion measures of a function of time: its secant over the feature's
//! neighbours' time offsets (or its derivative, without offsets).

use crate::LocalDistortion;

/// Each local distortion's neighbour time offsets (`of` picks frame or line times) when
/// the secant form is used, else none (the derivative at the feature's own time).
pub(crate) fn secant_offsets<'a>(
    local: &'a [LocalDistortion],
    secant_mode: bool,
    of: impl Fn(&'a LocalDistortion) -> &'a [f64],
) -> Vec<&'a [f64]> {
    local
        .iter()
        .map(|l| if secant_mode { of(l) } else { &[] })
        .collect()
}

/// `Σ Δ·(g(x+Δ) − g(x)) / Σ Δ²`: the least-squares slope of `g` through the point `x` over
/// the offsets `Δ`; the derivative (central difference) when there are no offsets.
pub(crate) fn secant<G: Fn(f64) -> f64>(g: G, x: f64, offsets: &[f64]) -> f64 {
    let denominator: f64 = offsets.iter().map(|d| d * d).sum();
    if offsets.is_empty() || denominator <= 0.0 {
        let h = 1e-6 * x.abs().max(1e-6);
        return (g(x + h) - g(x - h)) / (2.0 * h);
    }
    let g0 = g(x);
    offsets.iter().map(|d| d * (g(x + d) - g0)).sum::<f64>() / denominator
}
