//! The reciprocal lattice behind a set of spectral peaks: the coarsest lattice of
//! frequencies (largest real-space cell) that indexes nearly all of the peaks' power, its
//! weighted least-squares refinement over every indexed peak, and its uncertainty.
//!
//! Everything here is in bins (see [`crate::spectrum`]); a basis is a 2 × 2 matrix whose
//! columns are the basis vectors.

use nalgebra::{Matrix2, Matrix4, Vector2, Vector4};

use crate::spectrum::{MIN_RADIUS_BINS, Peak};

/// A candidate must index at least this fraction of the peaks' power…
const MIN_INDEXED_POWER: f64 = 0.85;
/// …and at least this fraction of the lattice points it predicts (within the radius of
/// the peaks it indexes) must be observed peaks: a lattice far finer than the image's
/// indexes everything by chance and is excluded by this.
const MIN_OCCUPANCY: f64 = 0.12;
/// Candidate bases are built from pairs of the strongest peaks.
const PAIR_PEAKS: usize = 24;

/// The reciprocal basis found and the peaks it indexes.
#[derive(Debug, Clone)]
pub struct FittedBasis {
    /// Columns `b1`, `b2`, bins (Gauss-reduced).
    pub basis: Matrix2<f64>,
    /// Covariance of `(b1x, b2x, b1y, b2y)` (row-major entries of `basis`), bins².
    pub covariance: Matrix4<f64>,
    /// Each peak's index `(h, k)` in `basis`, if it is indexed.
    pub indices: Vec<Option<[i64; 2]>>,
    /// Fraction of the peaks' power that is indexed.
    pub indexed_power: f64,
}

/// Gauss (Lagrange) reduction of a 2-D basis: the shortest basis of the same lattice.
pub fn reduce(basis: Matrix2<f64>) -> Matrix2<f64> {
    let (mut u, mut v) = (basis.column(0).into_owned(), basis.column(1).into_owned());
    for _ in 0..64 {
        if u.norm_squared() > v.norm_squared() {
            std::mem::swap(&mut u, &mut v);
        }
        let mu = (u.dot(&v) / u.norm_squared()).round();
        if mu == 0.0 || !mu.is_finite() {
            break;
        }
        v -= u * mu;
    }
    Matrix2::from_columns(&[u, v])
}

struct Score {
    indices: Vec<Option<[i64; 2]>>,
    indexed_power: f64,
    occupancy: f64,
    /// Whether two independent first-order reflections (among ±b1, ±b2, ±(b1 ± b2)) are
    /// observed peaks: a lattice's fundamental reflections are there; a supercell's (whose
    /// reciprocal lattice holds every true peak too) are fractional and absent.
    fundamentals: bool,
}

/// Indexes `peaks` in `basis`; a peak is indexed when it lies within a tolerance of a
/// lattice point (1 bin or 4 % of its radius, but never more than a quarter of the
/// shortest basis vector).
fn score(basis: &Matrix2<f64>, peaks: &[Peak]) -> Option<Score> {
    let inverse = basis.try_inverse()?;
    let shortest = basis.column(0).norm().min(basis.column(1).norm());
    let total: f64 = peaks.iter().map(|p| p.power).sum();
    let mut indexed_power = 0.0;
    let indices: Vec<Option<[i64; 2]>> = peaks
        .iter()
        .map(|p| {
            let k = Vector2::new(p.k[0], p.k[1]);
            let h = (inverse * k).map(f64::round);
            let tolerance = (1.0f64).max(0.04 * k.norm()).min(0.25 * shortest);
            ((basis * h - k).norm() <= tolerance && h != Vector2::zeros()).then(|| {
                indexed_power += p.power;
                [h[0] as i64, h[1] as i64]
            })
        })
        .collect();
    // Occupancy within the radius holding 90 % of the indexed power: weak harmonics and
    // noise peaks indexed far out (a distorted image smears its higher orders) must not
    // dilute it.
    let mut indexed: Vec<(f64, f64)> = peaks
        .iter()
        .zip(&indices)
        .filter(|(_, i)| i.is_some())
        .map(|(p, _)| (p.k[0].hypot(p.k[1]), p.power))
        .collect();
    indexed.sort_by(|a, b| a.0.total_cmp(&b.0));
    let (mut radius, mut count, mut accumulated) = (0.0f64, 0usize, 0.0);
    for (r, power) in indexed {
        if accumulated >= 0.9 * indexed_power {
            break;
        }
        accumulated += power;
        radius = r;
        count += 1;
    }
    let cell = basis.determinant().abs();
    // Lattice points in the half disc of the indexed peaks, outside the excluded centre.
    let predicted =
        (0.5 * std::f64::consts::PI * (radius * radius - MIN_RADIUS_BINS.powi(2)) / cell).max(1.0);
    let observed = |h: [i64; 2]| {
        indices
            .iter()
            .any(|i| *i == Some(h) || *i == Some([-h[0], -h[1]]))
    };
    let first_order = [[1, 0], [0, 1], [1, 1], [1, -1]];
    let present: Vec<[i64; 2]> = first_order.into_iter().filter(|&h| observed(h)).collect();
    let fundamentals = present
        .iter()
        .enumerate()
        .any(|(i, a)| present[i + 1..].iter().any(|b| a[0] * b[1] != a[1] * b[0]));
    Some(Score {
        indices,
        indexed_power: indexed_power / total.max(f64::MIN_POSITIVE),
        occupancy: count as f64 / predicted,
        fundamentals,
    })
}

/// The coarsest-cell reciprocal lattice that indexes the peaks, refined; `None` when no
/// two independent peaks exist.
pub fn find_basis(peaks: &[Peak]) -> Option<FittedBasis> {
    let strongest = &peaks[..peaks.len().min(PAIR_PEAKS)];
    let mut candidates: Vec<(Matrix2<f64>, Score)> = Vec::new();
    for (i, a) in strongest.iter().enumerate() {
        for b in &strongest[i + 1..] {
            let (u, v) = (Vector2::new(a.k[0], a.k[1]), Vector2::new(b.k[0], b.k[1]));
            if (u.x * v.y - u.y * v.x).abs() < 0.2 * u.norm() * v.norm() {
                continue;
            }
            let basis = reduce(Matrix2::from_columns(&[u, v]));
            if basis.column(0).norm() < MIN_RADIUS_BINS {
                continue;
            }
            if let Some(s) = score(&basis, peaks) {
                candidates.push((basis, s));
            }
        }
    }
    let best_power = candidates
        .iter()
        .map(|(_, s)| s.indexed_power)
        .fold(0.0, f64::max);
    let floor = MIN_INDEXED_POWER.min(best_power - 0.03);
    let (basis, chosen) = candidates
        .into_iter()
        .filter(|(_, s)| s.indexed_power >= floor && s.occupancy >= MIN_OCCUPANCY && s.fundamentals)
        .min_by(|(a, sa), (b, sb)| {
            let (ca, cb) = (a.determinant().abs(), b.determinant().abs());
            // Same cell within 2 %: the one indexing more power.
            if (ca - cb).abs() <= 0.02 * ca.max(cb) {
                sb.indexed_power.total_cmp(&sa.indexed_power)
            } else {
                ca.total_cmp(&cb)
            }
        })?;
    let (basis, covariance) = refine(&basis, peaks, &refinable(&basis, peaks, &chosen.indices))?;
    let basis = reduce(basis);
    let rescored = score(&basis, peaks)?;
    Some(FittedBasis {
        basis,
        covariance,
        indices: rescored.indices,
        indexed_power: rescored.indexed_power,
    })
}

/// A peak farther than this many of its position uncertainties from its reflection under
/// the current map is left out of the next least-squares step (a noise peak that lands
/// near some high-order reflection by chance)…
const CONSISTENT_SIGMAS: f64 = 3.0;

/// …its uncertainty for this test including this fraction of its radius: a non-uniform
/// distortion (creep, a drift that changes) smears and shifts a peak in proportion to its
/// frequency.
const DISTORTION_SMEAR: f64 = 0.005;

/// The indices the least-squares refinement uses under basis `n`: without the peaks whose
/// position could not be refined (beside the scan-line band, off by up to a bin on a small
/// frame) or that lie more than [`CONSISTENT_SIGMAS`] from their reflection, as long as the
/// others still span two directions.
pub(crate) fn refinable(
    n: &Matrix2<f64>,
    peaks: &[Peak],
    indices: &[Option<[i64; 2]>],
) -> Vec<Option<[i64; 2]>> {
    let consistent = |p: &Peak, h: [i64; 2]| {
        let predicted = n * Vector2::new(h[0] as f64, h[1] as f64);
        let sigma = position_sigma(p).hypot(DISTORTION_SMEAR * predicted.norm());
        (Vector2::new(p.k[0], p.k[1]) - predicted).norm() <= CONSISTENT_SIGMAS * sigma
    };
    let refined: Vec<Option<[i64; 2]>> = peaks
        .iter()
        .zip(indices)
        .map(|(p, i)| i.filter(|&h| !p.unrefined && consistent(p, h)))
        .collect();
    let kept: Vec<[i64; 2]> = refined.iter().flatten().copied().collect();
    let spans = kept
        .iter()
        .enumerate()
        .any(|(i, a)| kept[i + 1..].iter().any(|b| a[0] * b[1] != a[1] * b[0]));
    if spans { refined } else { indices.to_vec() }
}

/// Position uncertainty of a peak (bins): about half a bin at the detection threshold,
/// shrinking with the square root of its signal-to-noise ratio; half a bin for a peak
/// whose position could not be refined (next to the scan-line band), however strong.
pub(crate) fn position_sigma(peak: &Peak) -> f64 {
    if peak.unrefined {
        return 0.5;
    }
    (0.5 * (crate::spectrum::MIN_PEAK_SNR / peak.snr.max(1e-9)).sqrt()).clamp(0.02, 0.5)
}

/// Weighted least squares `k_i ≈ B·h_i` over the indexed peaks; the covariance is scaled by
/// the reduced χ² when that exceeds 1 (peaks smeared by a non-uniform distortion).
pub(crate) fn refine(
    basis: &Matrix2<f64>,
    peaks: &[Peak],
    indices: &[Option<[i64; 2]>],
) -> Option<(Matrix2<f64>, Matrix4<f64>)> {
    let mut normal = Matrix2::zeros();
    let mut right = Matrix2::zeros();
    let mut used = 0usize;
    for (peak, index) in peaks.iter().zip(indices) {
        let Some([h, k]) = *index else { continue };
        let w = position_sigma(peak).powi(-2);
        let h = Vector2::new(h as f64, k as f64);
        let k = Vector2::new(peak.k[0], peak.k[1]);
        normal += h * h.transpose() * w;
        right += k * h.transpose() * w;
        used += 1;
    }
    let inverse = normal.try_inverse()?;
    let fitted = if used >= 2 { right * inverse } else { *basis };
    let mut chi2 = 0.0;
    for (peak, index) in peaks.iter().zip(indices) {
        let Some([h, k]) = *index else { continue };
        let r = Vector2::new(peak.k[0], peak.k[1]) - fitted * Vector2::new(h as f64, k as f64);
        chi2 += r.norm_squared() / position_sigma(peak).powi(2);
    }
    let dof = (2 * used).saturating_sub(4);
    let inflation = if dof > 0 {
        (chi2 / dof as f64).max(1.0)
    } else {
        1.0
    };
    // Rows of B are independent fits with the same normal matrix.
    let block = inverse * inflation;
    let mut covariance = Matrix4::zeros();
    for row in 0..2 {
        for i in 0..2 {
            for j in 0..2 {
                covariance[(2 * row + i, 2 * row + j)] = block[(i, j)];
            }
        }
    }
    Some((fitted, covariance))
}

/// 1σ of `f(B)` by linear propagation of the covariance of `B`'s entries (row-major).
pub fn propagate(
    basis: &Matrix2<f64>,
    covariance: &Matrix4<f64>,
    f: impl Fn(&Matrix2<f64>) -> f64,
) -> f64 {
    let f0 = f(basis);
    let scale = basis.abs().max().max(1e-300);
    let mut gradient = Vector4::zeros();
    for e in 0..4 {
        let h = 1e-6 * scale;
        let mut shifted = *basis;
        shifted[(e / 2, e % 2)] += h;
        gradient[e] = (f(&shifted) - f0) / h;
    }
    (gradient.transpose() * covariance * gradient)[(0, 0)]
        .max(0.0)
        .sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn peak(kx: f64, ky: f64, power: f64) -> Peak {
        Peak::at(kx, ky, power)
    }

    #[test]
    fn reduction_finds_the_shortest_basis() {
        let b = reduce(Matrix2::new(10.0, 31.0, 0.0, 17.0));
        let lengths = [b.column(0).norm(), b.column(1).norm()];
        assert!((lengths[0] - 10.0).abs() < 1e-9, "{b}");
        assert!(lengths[1] <= (11.0f64.powi(2) + 17.0f64.powi(2)).sqrt() + 1e-9);
        assert!((b.determinant().abs() - 170.0).abs() < 1e-9);
    }

    #[test]
    fn hexagonal_peaks_give_the_hexagonal_basis_not_a_finer_one() {
        // First order at radius 20 (three in the half plane), second order weaker, and a
        // weak stray peak.
        let r = 20.0;
        let mut peaks = Vec::new();
        for k in 0..3 {
            let a = std::f64::consts::PI / 3.0 * k as f64 + 0.1;
            peaks.push(peak(r * a.cos(), r * a.sin(), 100.0));
        }
        let s = 3f64.sqrt() * r;
        for k in 0..3 {
            let a = std::f64::consts::PI / 3.0 * k as f64 + 0.1 + std::f64::consts::PI / 6.0;
            peaks.push(peak(s * a.cos(), s * a.sin(), 5.0));
        }
        peaks.push(peak(7.3, 11.1, 1.0));
        for p in &mut peaks {
            if p.k[0] < 0.0 || (p.k[0] == 0.0 && p.k[1] < 0.0) {
                p.k = [-p.k[0], -p.k[1]];
            }
        }
        peaks.sort_by(|a, b| b.power.total_cmp(&a.power));
        let fitted = find_basis(&peaks).expect("a basis");
        let b = fitted.basis;
        assert!((b.column(0).norm() - r).abs() < 1e-6, "{b}");
        assert!((b.column(1).norm() - r).abs() < 1e-6, "{b}");
        assert!(fitted.indexed_power > 0.99);
        assert_eq!(fitted.indices.iter().flatten().count(), 6);
    }
}
