//! How each scan line departs from the rendered model as a whole: tilted along itself, or
//! shifted along itself (line jitter). Both are read from the residual image's lines
//! ([`crate::PassResidual`]), in acquisition order.

use dhct_numerics::robust::{finite_median, mad_sigma};

/// The robust variance of the lines' slopes over that of their next two shapes (the
/// orthonormal quadratic and cubic parts of each line over its finite pixels): white noise
/// gives every part the same variance, noise that rises to low frequencies (1/f) a little
/// more to the slope, a tilt of each line only the slope. `None` with fewer than 16 lines of
/// at least 16 finite pixels.
pub(crate) fn line_tilt_evidence(lines: &[&[f64]]) -> Option<f64> {
    let parts: Vec<[f64; 3]> = lines
        .iter()
        .filter_map(|line| {
            let points: Vec<(f64, f64)> = line
                .iter()
                .enumerate()
                .filter(|(_, v)| v.is_finite())
                .map(|(i, v)| (i as f64, *v))
                .collect();
            (points.len() >= 16).then(|| orthonormal_parts(&points))
        })
        .collect();
    if parts.len() < 16 {
        return None;
    }
    let variance = |k: usize| {
        let values: Vec<f64> = parts.iter().map(|p| p[k]).collect();
        dhct_numerics::robust::mad_sigma(&values).map(|s| s * s)
    };
    let reference = 0.5 * (variance(1)? + variance(2)?);
    Some(variance(0)? / reference).filter(|r| r.is_finite())
}

/// The coefficients of `points` `(i, v)` on the orthonormal linear, quadratic and cubic
/// polynomials over their `i` (Gram–Schmidt against the constant and each other): each has
/// the pixel noise's variance under white noise.
fn orthonormal_parts(points: &[(f64, f64)]) -> [f64; 3] {
    let count = points.len() as f64;
    let centre = points.iter().map(|p| p.0).sum::<f64>() / count;
    let half = points
        .iter()
        .map(|p| (p.0 - centre).abs())
        .fold(1.0, f64::max);
    let u: Vec<f64> = points.iter().map(|p| (p.0 - centre) / half).collect();
    let mut basis: Vec<Vec<f64>> = vec![vec![1.0 / count.sqrt(); points.len()]];
    let mut parts = [0.0; 3];
    for (k, part) in parts.iter_mut().enumerate() {
        let mut b: Vec<f64> = u.iter().map(|x| x.powi(k as i32 + 1)).collect();
        for e in &basis {
            let dot: f64 = b.iter().zip(e).map(|(a, c)| a * c).sum();
            b.iter_mut().zip(e).for_each(|(a, c)| *a -= dot * c);
        }
        let norm = b.iter().map(|a| a * a).sum::<f64>().sqrt();
        b.iter_mut().for_each(|a| *a /= norm);
        *part = b.iter().zip(points).map(|(a, p)| a * p.1).sum();
        basis.push(b);
    }
    parts
}

/// Each line's shift along itself against the model: the least-squares `δ` of the
/// residual `r` on the model's gradient along the line `g` (`r ≈ −g·δ`, pixels; `g` by the
/// five-point derivative), over the finite pixels of both.
struct LineShift {
    /// The shift, pixels.
    shift_px: f64,
    /// Its variance under pixel noise `σ`: `σ²/Σg²`, px².
    noise_variance: f64,
}

/// How much the lines' shifts along themselves differ from one line to the next, over
/// what the pixel noise `noise` gives: the robust variance of the successive differences
/// over twice the median noise variance of one shift; and the rms shift beyond the noise in
/// pixels (0 when there is none). Successive differences keep what is new on every line
/// (jitter) and drop what lines acquired together share: the features' own position
/// errors and the model's gap (a feature spans ten or more lines), slow motion. `residual`
/// and `model` lines are in the same order and length. `None` with fewer than 16 pairs of
/// consecutive lines that cross the model's atoms.
pub(crate) fn line_shifts(residual: &[&[f64]], model: &[&[f64]], noise: f64) -> Option<(f64, f64)> {
    let shifts: Vec<Option<LineShift>> = residual
        .iter()
        .zip(model)
        .map(|(r, m)| line_shift(r, m, noise))
        .collect();
    let (differences, variances): (Vec<f64>, Vec<f64>) = shifts
        .windows(2)
        .filter_map(|pair| match pair {
            [Some(a), Some(b)] => {
                Some((b.shift_px - a.shift_px, a.noise_variance + b.noise_variance))
            }
            _ => None,
        })
        .unzip();
    if differences.len() < 16 {
        return None;
    }
    let spread = mad_sigma(&differences)?;
    let noise_variance = finite_median(variances)?;
    let over_noise = spread * spread / noise_variance;
    let beyond_px = (0.5 * (spread * spread - noise_variance)).max(0.0).sqrt();
    over_noise.is_finite().then_some((over_noise, beyond_px))
}

/// One line's shift ([`LineShift`]); `None` when the model has no gradient along it.
fn line_shift(residual: &[f64], model: &[f64], noise: f64) -> Option<LineShift> {
    let (mut rg, mut gg) = (0.0, 0.0);
    for i in 2..model.len().saturating_sub(2) {
        // Five-point derivative: 1 % low for an 8-pixel period (the central difference: 10 %).
        let g = (8.0 * (model[i + 1] - model[i - 1]) - (model[i + 2] - model[i - 2])) / 12.0;
        let r = residual[i];
        if g.is_finite() && r.is_finite() {
            rg += r * g;
            gg += g * g;
        }
    }
    (gg > 0.0).then(|| LineShift {
        shift_px: -rg / gg,
        noise_variance: noise * noise / gg,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A lattice-like line `cos(2π i/8)` and its lines shifted by `shifts` px.
    fn shifted_lines(shifts: &[f64]) -> (Vec<Vec<f64>>, Vec<Vec<f64>>) {
        let wave = |x: f64| (std::f64::consts::TAU * x / 8.0).cos();
        let model: Vec<f64> = (0..256).map(|i| wave(i as f64)).collect();
        let residual = shifts
            .iter()
            .map(|d| {
                (0..256)
                    .map(|i| wave(i as f64 - d) - wave(i as f64))
                    .collect()
            })
            .collect();
        (residual, vec![model; shifts.len()])
    }

    #[test]
    fn line_shifts_are_read_against_the_model_gradient() {
        // Pseudo-random shifts within ±0.05 px.
        let shifts: Vec<f64> = (0..64u64)
            .map(|l| 0.05 * (((l * l * 37 + l * 11 + 5) % 101) as f64 - 50.0) / 50.0)
            .collect();
        let (r, m) = shifted_lines(&shifts);
        let r: Vec<&[f64]> = r.iter().map(Vec::as_slice).collect();
        let m: Vec<&[f64]> = m.iter().map(Vec::as_slice).collect();
        for (line, truth) in r.iter().zip(&shifts) {
            let s = line_shift(line, m[0], 0.01).unwrap();
            assert!(
                (s.shift_px - truth).abs() < 0.002,
                "{} vs {truth}",
                s.shift_px
            );
        }
        let (over_noise, beyond) = line_shifts(&r, &m, 1e-4).unwrap();
        assert!(over_noise > 100.0 && beyond > 0.02, "{over_noise} {beyond}");
    }
}
