//! The rotation of a lattice from measured bond directions, for any set of ideal bond
//! directions: equally spaced (hexagonal, square) or not (oblique, centred rectangular).

use std::f64::consts::PI;

/// Bins of the bond-direction histogram over `[0, π)` (0.25° each).
const HISTOGRAM_BINS: usize = 720;

/// Width σ of the Gaussian that smooths the histogram, radians (2°): wide enough for the
/// scatter of bond directions in a drifting image, narrow enough to keep 30° apart.
const SMOOTHING_RAD: f64 = 2.0 * PI / 180.0;

/// Largest residual (radians) of a bond from its nearest ideal direction that the
/// refinement uses (and at most a third of the smallest gap between ideal directions).
const REFINE_REACH_RAD: f64 = 10.0 * PI / 180.0;

/// Distinct undirected directions of `vectors` (radians in `[0, π)`, ascending); two
/// directions within `tolerance_rad` are one.
pub fn undirected_directions(
    vectors: impl IntoIterator<Item = [f64; 2]>,
    tolerance_rad: f64,
) -> Vec<f64> {
    let mut angles: Vec<f64> = vectors
        .into_iter()
        .map(|[x, y]| y.atan2(x).rem_euclid(PI))
        .collect();
    angles.sort_by(f64::total_cmp);
    let mut out: Vec<f64> = Vec::new();
    for angle in angles {
        let seen = out
            .iter()
            .any(|d| circular_gap(*d, angle, PI) <= tolerance_rad);
        if !seen {
            out.push(angle);
        }
    }
    out
}

/// The smallest rotation `π/k` (k = 1..=12) that maps the undirected `directions` (radians)
/// onto themselves within `tolerance_rad`: π/3 for hexagonal bonds, π/2 for square, π for
/// oblique ones.
pub fn direction_period(directions: &[f64], tolerance_rad: f64) -> f64 {
    (1..=12usize)
        .rev()
        .map(|k| PI / k as f64)
        .find(|&period| {
            directions.iter().all(|d| {
                directions
                    .iter()
                    .any(|e| circular_gap(d + period, *e, PI) <= tolerance_rad)
            })
        })
        .unwrap_or(PI)
}

/// Distance between angles `a` and `b` on a circle of circumference `period`.
fn circular_gap(a: f64, b: f64, period: f64) -> f64 {
    let d = (a - b).rem_euclid(period);
    d.min(period - d)
}

/// The lattice rotation φ (radians, in `[0, period)`) that best maps the ideal undirected
/// bond `directions` (radians, the unrotated lattice's) onto the measured `bonds` (vectors,
/// any frame and unit): the maximum of the smoothed bond-direction histogram correlated with
/// the ideal directions, refined by the mean residual of the bonds near an ideal direction.
/// `period` is the directions' symmetry (see [`crate::Lattice::bond_direction_period`]);
/// φ is defined modulo it. `None` without bonds or directions.
pub fn estimate_rotation(
    bonds: impl IntoIterator<Item = [f64; 2]>,
    directions: &[f64],
    period: f64,
) -> Option<f64> {
    let angles: Vec<f64> = bonds
        .into_iter()
        .filter(|[x, y]| x.is_finite() && y.is_finite() && (*x != 0.0 || *y != 0.0))
        .map(|[x, y]| y.atan2(x).rem_euclid(PI))
        .collect();
    if angles.is_empty() || directions.is_empty() || !(period > 0.0 && period <= PI) {
        return None;
    }
    let smoothed = smoothed_histogram(&angles);
    let bin_width = PI / HISTOGRAM_BINS as f64;
    let candidates = ((period / bin_width).round() as usize).clamp(1, HISTOGRAM_BINS);
    let score = |phi: f64| -> f64 {
        directions
            .iter()
            .map(|d| smoothed[bin_of(phi + d)])
            .sum::<f64>()
    };
    let mut phi = (0..candidates)
        .map(|c| c as f64 * bin_width)
        .max_by(|a, b| score(*a).total_cmp(&score(*b)))?;
    let reach = REFINE_REACH_RAD.min(smallest_gap(directions) / 3.0);
    for _ in 0..3 {
        phi += mean_residual(&angles, directions, phi, reach).unwrap_or(0.0);
    }
    Some(phi.rem_euclid(period))
}

/// Histogram bin of an undirected angle (radians).
fn bin_of(angle: f64) -> usize {
    ((angle.rem_euclid(PI) / PI * HISTOGRAM_BINS as f64) as usize).min(HISTOGRAM_BINS - 1)
}

/// The bond-direction histogram over `[0, π)`, circularly smoothed by a Gaussian of
/// [`SMOOTHING_RAD`].
fn smoothed_histogram(angles: &[f64]) -> Vec<f64> {
    let mut counts = vec![0.0; HISTOGRAM_BINS];
    for angle in angles {
        counts[bin_of(*angle)] += 1.0;
    }
    let bin_width = PI / HISTOGRAM_BINS as f64;
    let sigma_bins = SMOOTHING_RAD / bin_width;
    let reach = (3.0 * sigma_bins).ceil() as i64;
    let kernel: Vec<f64> = (-reach..=reach)
        .map(|k| (-0.5 * (k as f64 / sigma_bins).powi(2)).exp())
        .collect();
    let n = HISTOGRAM_BINS as i64;
    (0..n)
        .map(|i| {
            (-reach..=reach)
                .zip(&kernel)
                .map(|(k, w)| w * counts[(i + k).rem_euclid(n) as usize])
                .sum()
        })
        .collect()
}

/// The smallest circular gap (mod π) between distinct ideal directions; π for one.
fn smallest_gap(directions: &[f64]) -> f64 {
    let mut gap = PI;
    for (i, a) in directions.iter().enumerate() {
        for b in &directions[i + 1..] {
            gap = gap.min(circular_gap(*a, *b, PI));
        }
    }
    gap
}

/// The mean residual (radians) of the bond `angles` within `reach` of an ideal direction
/// rotated by `phi`; `None` when none is.
fn mean_residual(angles: &[f64], directions: &[f64], phi: f64, reach: f64) -> Option<f64> {
    let (mut sum, mut count) = (0.0, 0usize);
    for angle in angles {
        let residual = directions
            .iter()
            .map(|d| {
                let r = (angle - phi - d).rem_euclid(PI);
                if r > 0.5 * PI { r - PI } else { r }
            })
            .min_by(|a, b| a.abs().total_cmp(&b.abs()))?;
        if residual.abs() <= reach {
            sum += residual;
            count += 1;
        }
    }
    (count > 0).then(|| sum / count as f64)
}

/// The rotation of a lattice from measured bond vectors: the circular mean of
/// `(bond angle − reference_rad)` with period `period_rad` (the period of the ideal bond
/// directions, e.g. π/3 for hexagonal), in `(−period/2, period/2]`; `None` without bonds.
/// `reference_rad` is the direction of any one ideal bond.
pub fn mean_bond_rotation(
    bonds: impl IntoIterator<Item = [f64; 2]>,
    reference_rad: f64,
    period_rad: f64,
) -> Option<f64> {
    let (mut sum_cos, mut sum_sin, mut count) = (0.0, 0.0, 0usize);
    for [dx, dy] in bonds {
        let phase = 2.0 * std::f64::consts::PI * (dy.atan2(dx) - reference_rad) / period_rad;
        sum_cos += phase.cos();
        sum_sin += phase.sin();
        count += 1;
    }
    (count > 0).then(|| sum_sin.atan2(sum_cos) * period_rad / (2.0 * std::f64::consts::PI))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bonds_at(directions: &[f64], phi: f64, scatter: f64) -> Vec<[f64; 2]> {
        let mut out = Vec::new();
        for (k, d) in directions.iter().enumerate() {
            for j in 0..50 {
                // Deterministic scatter, mean zero per direction.
                let e = scatter * ((j * 7 + k * 3) % 11) as f64 / 5.0 - scatter;
                let a = d + phi + e;
                let sign = if j % 2 == 0 { 1.0 } else { -1.0 };
                out.push([sign * a.cos(), sign * a.sin()]);
            }
        }
        out
    }

    #[test]
    fn finds_the_rotation_of_unequally_spaced_directions() {
        // A centred-rectangular c(2×2) on a × √2a: bonds at ±54.74°, 90° symmetry.
        let d = (2f64.sqrt()).atan();
        let directions = undirected_directions([[1.0, d.tan()], [1.0, -d.tan()]], 1e-6);
        let period = direction_period(&directions, 1e-6);
        assert!((period - PI).abs() < 1e-12, "{period}");
        for phi in [0.0, 0.2, 1.0, 2.9] {
            let found =
                estimate_rotation(bonds_at(&directions, phi, 0.02), &directions, period).unwrap();
            assert!(circular_gap(found, phi, period) < 2e-3, "{phi}: {found}");
        }
    }

    #[test]
    fn hexagonal_directions_have_a_sixty_degree_period() {
        let directions: Vec<f64> = (0..3).map(|k| k as f64 * PI / 3.0 + 0.1).collect();
        let period = direction_period(&directions, 1e-6);
        assert!((period - PI / 3.0).abs() < 1e-12);
        let found =
            estimate_rotation(bonds_at(&directions, 0.3, 0.03), &directions, period).unwrap();
        assert!(circular_gap(found, 0.3, period) < 2e-3, "{found}");
        assert!(estimate_rotation(Vec::<[f64; 2]>::new(), &directions, period).is_none());
    }
}
