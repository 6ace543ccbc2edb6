//! How regular an image's lattice is, judged from the image alone: the non-affine
//! displacement field from the phases of two Bragg reflections (geometric phase analysis,
//! Hÿtch et al., Ultramicroscopy 74, 131 (1998)).
//!
//! Each reflection `g` (cycles per pixel) is demodulated: `z(r)·exp(−2πi g·r)`, smoothed by
//! a Gaussian of a few lattice periods, leaves a slowly varying complex field whose phase
//! `φ(r) = −2π g·u(r)` holds the lattice's displacement `u`. A linear phase (a uniform
//! strain, rotation or offset: what an affine map changes) is fitted and removed; what is
//! left is the displacement no affine correction can remove. Its rms (pixels, over the
//! frame minus a border of two smoothing widths) is the regularity measure: the same for
//! the raw image and an affine-corrected one, smaller after a correction that removes
//! non-uniform drift.

use nalgebra::{Matrix2, Matrix3, Vector2, Vector3};
use ndarray::{Array2, ArrayView2};

/// The non-affine displacement of `z` for reflections `g` (cycles per pixel, `[gx, gy]`),
/// rms over the interior, pixels; `None` when the reflections are parallel or the frame
/// holds no interior.
pub fn non_affine_rms_px(z: ArrayView2<f64>, g: [[f64; 2]; 2]) -> Option<f64> {
    let (rows, columns) = z.dim();
    let period = 1.0
        / Vector2::new(g[0][0], g[0][1])
            .norm()
            .min(Vector2::new(g[1][0], g[1][1]).norm());
    let sigma = 1.5 * period;
    let border = (2.0 * sigma).ceil() as usize;
    if rows <= 2 * border + 4 || columns <= 2 * border + 4 {
        return None;
    }
    let level = mean_finite(z);
    let phases: Vec<Array2<f64>> = g
        .iter()
        .map(|&gk| residual_phase(z, gk, level, sigma, border))
        .collect::<Option<_>>()?;
    let reciprocal = Matrix2::new(g[0][0], g[0][1], g[1][0], g[1][1]);
    let inverse = reciprocal.try_inverse()?;
    let (mut sum, mut count) = (0.0, 0usize);
    for r in border..rows - border {
        for c in border..columns - border {
            let phi = Vector2::new(phases[0][[r, c]], phases[1][[r, c]]);
            if !phi.x.is_finite() || !phi.y.is_finite() {
                continue;
            }
            let u = inverse * phi / (-2.0 * std::f64::consts::PI);
            sum += u.norm_squared();
            count += 1;
        }
    }
    (count > 0).then(|| (sum / count as f64).sqrt())
}

fn mean_finite(z: ArrayView2<f64>) -> f64 {
    let (sum, n) = z
        .iter()
        .filter(|v| v.is_finite())
        .fold((0.0, 0usize), |(s, n), v| (s + v, n + 1));
    if n == 0 { 0.0 } else { sum / n as f64 }
}

/// The demodulated phase of reflection `g` with its best linear phase removed (radians),
/// NaN where the image has no data.
fn residual_phase(
    z: ArrayView2<f64>,
    g: [f64; 2],
    level: f64,
    sigma: f64,
    border: usize,
) -> Option<Array2<f64>> {
    let (rows, columns) = z.dim();
    let two_pi = 2.0 * std::f64::consts::PI;
    let demodulated = |g: [f64; 2]| {
        let (re, im): (Array2<f64>, Array2<f64>) = {
            let mut re = Array2::zeros((rows, columns));
            let mut im = Array2::zeros((rows, columns));
            for ((r, c), v) in z.indexed_iter() {
                let v = if v.is_finite() { v - level } else { 0.0 };
                let phase = -two_pi * (g[0] * c as f64 + g[1] * r as f64);
                re[[r, c]] = v * phase.cos();
                im[[r, c]] = v * phase.sin();
            }
            (re, im)
        };
        (
            dhct_features::gaussian_blur(&re, sigma),
            dhct_features::gaussian_blur(&im, sigma),
        )
    };
    // The mean phase gradient first (a slightly wrong g leaves a ramp of many turns), then
    // the remaining linear phase, fitted by least squares on the interior.
    let (re, im) = demodulated(g);
    let gradient = mean_gradient(&re, &im, border)?;
    let g = [g[0] + gradient[0] / two_pi, g[1] + gradient[1] / two_pi];
    let (re, im) = demodulated(g);
    let mut phase = Array2::from_shape_fn((rows, columns), |(r, c)| im[[r, c]].atan2(re[[r, c]]));
    let plane = fit_plane(&phase, &re, &im, border)?;
    for ((r, c), p) in phase.indexed_iter_mut() {
        let value = *p - (plane[0] + plane[1] * c as f64 + plane[2] * r as f64);
        *p = if z[[r, c]].is_finite() {
            (value + std::f64::consts::PI).rem_euclid(two_pi) - std::f64::consts::PI
        } else {
            f64::NAN
        };
    }
    Some(phase)
}

/// The mean phase step per pixel along x and y of the complex field `re + i·im`.
fn mean_gradient(re: &Array2<f64>, im: &Array2<f64>, border: usize) -> Option<[f64; 2]> {
    let (rows, columns) = re.dim();
    let (mut sx, mut sy) = ((0.0, 0.0), (0.0, 0.0));
    for r in border..rows - border - 1 {
        for c in border..columns - border - 1 {
            let a = (re[[r, c]], im[[r, c]]);
            let b = (re[[r, c + 1]], im[[r, c + 1]]);
            let d = (re[[r + 1, c]], im[[r + 1, c]]);
            // b·conj(a), d·conj(a)
            sx.0 += b.0 * a.0 + b.1 * a.1;
            sx.1 += b.1 * a.0 - b.0 * a.1;
            sy.0 += d.0 * a.0 + d.1 * a.1;
            sy.1 += d.1 * a.0 - d.0 * a.1;
        }
    }
    let gx = sx.1.atan2(sx.0);
    let gy = sy.1.atan2(sy.0);
    (gx.is_finite() && gy.is_finite()).then_some([gx, gy])
}

/// `[p0, px, py]` of the phase plane `p0 + px·c + py·r`, weighted by the field's amplitude,
/// fitted to the phase wrapped about the plane's own start (one Gauss–Newton-like pass
/// about the interior's mean phase, which is enough once the gradient is removed).
fn fit_plane(
    phase: &Array2<f64>,
    re: &Array2<f64>,
    im: &Array2<f64>,
    border: usize,
) -> Option<[f64; 3]> {
    let (rows, columns) = phase.dim();
    let (mut mean_re, mut mean_im) = (0.0, 0.0);
    for r in border..rows - border {
        for c in border..columns - border {
            mean_re += re[[r, c]];
            mean_im += im[[r, c]];
        }
    }
    let centre = mean_im.atan2(mean_re);
    let two_pi = 2.0 * std::f64::consts::PI;
    let mut normal = Matrix3::zeros();
    let mut right = Vector3::zeros();
    for r in border..rows - border {
        for c in border..columns - border {
            let w = re[[r, c]].hypot(im[[r, c]]);
            let p = (phase[[r, c]] - centre + std::f64::consts::PI).rem_euclid(two_pi)
                - std::f64::consts::PI;
            let x = Vector3::new(1.0, c as f64, r as f64);
            normal += x * x.transpose() * w;
            right += x * (p * w);
        }
    }
    let solution = normal.try_inverse()? * right;
    Some([solution[0] + centre, solution[1], solution[2]])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lattice(
        n: usize,
        displacement: impl Fn(f64, f64) -> [f64; 2],
    ) -> (Array2<f64>, [[f64; 2]; 2]) {
        let g = [[0.1, 0.02], [-0.03, 0.095]];
        let z = Array2::from_shape_fn((n, n), |(r, c)| {
            let (x, y) = (c as f64, r as f64);
            let u = displacement(x, y);
            g.iter()
                .map(|gk| {
                    (2.0 * std::f64::consts::PI * (gk[0] * (x - u[0]) + gk[1] * (y - u[1]))).cos()
                })
                .sum()
        });
        (z, g)
    }

    #[test]
    fn an_affine_lattice_is_regular_and_a_wavy_one_is_not() {
        // A uniform strain (affine): no non-affine displacement.
        let (affine, g) = lattice(160, |x, y| [0.01 * x + 0.02 * y, -0.015 * x]);
        let rms = non_affine_rms_px(affine.view(), g).unwrap();
        assert!(rms < 0.05, "affine: {rms}");
        // A wave of 1 px amplitude along x with a 120 px period: rms 0.71 px, of which the
        // smoothing (σ = 1.5 periods) keeps about 0.73 and the plane fitted over the
        // 100 px interior takes the part that looks linear there: about 0.4 px is left.
        let (wavy, g) = lattice(160, |_, y| {
            [(2.0 * std::f64::consts::PI * y / 120.0).sin(), 0.0]
        });
        let rms = non_affine_rms_px(wavy.view(), g).unwrap();
        assert!((0.3..0.6).contains(&rms), "wavy: {rms}");
    }
}
