//! Neighbour geometry derived from primitive vectors and motif, and enumeration of the
//! lattice sites inside a region.

use nalgebra::{Matrix2, Vector2};
use serde::{Deserialize, Serialize};

use crate::{Lattice, MotifSite};

/// Relative tolerance for two distances to count as one shell.
const SHELL_TOLERANCE: f64 = 1e-6;

fn site_offset(vectors: [Vector2<f64>; 2], site: &MotifSite) -> Vector2<f64> {
    vectors[0] * site.fractional[0] + vectors[1] * site.fractional[1]
}

/// All vectors from site `from` to features within `radius` (excluding itself).
fn vectors_within(
    vectors: [Vector2<f64>; 2],
    motif: &[MotifSite],
    from: usize,
    radius: f64,
) -> Vec<Vector2<f64>> {
    let [a1, a2] = vectors;
    let area = (a1.x * a2.y - a1.y * a2.x).abs();
    // Distance between neighbouring lines of constant n (and of constant m).
    let (h1, h2) = (area / a2.norm(), area / a1.norm());
    let max_offset = motif
        .iter()
        .map(|s| site_offset(vectors, s).norm())
        .fold(0.0, f64::max);
    let reach = radius + 2.0 * max_offset;
    let n_max = (reach / h1).ceil() as i64 + 1;
    let m_max = (reach / h2).ceil() as i64 + 1;
    let origin = site_offset(vectors, &motif[from]);
    let mut out = Vec::new();
    for n in -n_max..=n_max {
        for m in -m_max..=m_max {
            let cell = a1 * n as f64 + a2 * m as f64;
            for site in motif {
                let v = cell + site_offset(vectors, site) - origin;
                let d = v.norm();
                if d > radius * SHELL_TOLERANCE && d <= radius * (1.0 + SHELL_TOLERANCE) {
                    out.push(v);
                }
            }
        }
    }
    out
}

/// Nearest-neighbour vectors of motif site `site`, sorted by angle from +x: the nearest
/// shell, extended by the next shells until the vectors span the plane (so a rectangular
/// lattice gets its ±a and ±b neighbours).
pub(crate) fn nearest_neighbour_vectors(
    vectors: [Vector2<f64>; 2],
    motif: &[MotifSite],
    site: usize,
) -> Vec<Vector2<f64>> {
    // Both primitive vectors lie within this reach, so the candidates span the plane.
    let reach = vectors[0].norm().max(vectors[1].norm());
    let mut candidates = vectors_within(vectors, motif, site, reach);
    candidates.sort_by(|a, b| a.norm().total_cmp(&b.norm()));
    let mut chosen: Vec<Vector2<f64>> = Vec::new();
    let mut index = 0;
    while index < candidates.len() {
        let shell = candidates[index].norm();
        while index < candidates.len()
            && candidates[index].norm() <= shell * (1.0 + SHELL_TOLERANCE)
        {
            chosen.push(candidates[index]);
            index += 1;
        }
        if spans_plane(&chosen) {
            break;
        }
    }
    chosen.sort_by(|a, b| a.y.atan2(a.x).total_cmp(&b.y.atan2(b.x)));
    chosen
}

fn spans_plane(vectors: &[Vector2<f64>]) -> bool {
    let Some(first) = vectors.first() else {
        return false;
    };
    vectors
        .iter()
        .any(|v| (first.x * v.y - first.y * v.x).abs() > 1e-6 * first.norm() * v.norm())
}

/// The first `count` distinct neighbour distances over all motif sites, ascending.
pub(crate) fn shell_distances(
    vectors: [Vector2<f64>; 2],
    motif: &[MotifSite],
    count: usize,
) -> Vec<f64> {
    // Multiples of the shorter primitive vector alone give `count` distinct distances.
    let radius = count.max(1) as f64 * vectors[0].norm().min(vectors[1].norm());
    let mut distances: Vec<f64> = (0..motif.len())
        .flat_map(|site| vectors_within(vectors, motif, site, radius))
        .map(|v| v.norm())
        .collect();
    distances.sort_by(f64::total_cmp);
    let mut shells: Vec<f64> = Vec::new();
    for d in distances {
        match shells.last() {
            Some(&last) if d <= last * (1.0 + SHELL_TOLERANCE) => {}
            _ => shells.push(d),
        }
    }
    shells.truncate(count);
    shells
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

/// One feature of a lattice placed in a region: cell indices, motif site and position.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LatticeSite {
    /// Integer index along a1.
    pub n: i64,
    /// Integer index along a2.
    pub m: i64,
    /// Index into the motif.
    pub site: usize,
    /// Position in metres, in the frame of the region.
    pub position: Vector2<f64>,
}

/// Every feature of `lattice`, rotated by `angle` (radians, from +x towards +y) about the
/// cell origin placed at `origin` (metres), that lies inside `[0, width] x [0, height]`.
pub fn lattice_sites(
    lattice: &dyn Lattice,
    origin: Vector2<f64>,
    angle: f64,
    width: f64,
    height: f64,
) -> Vec<LatticeSite> {
    let [a1, a2] = lattice.primitive_vectors();
    let (sin, cos) = angle.sin_cos();
    let rotation = Matrix2::new(cos, -sin, sin, cos);
    let basis = rotation * Matrix2::from_columns(&[a1, a2]);
    let Some(inverse) = basis.try_inverse() else {
        return Vec::new();
    };
    // Fractional coordinates of the region's corners bound the cells to visit.
    let corners = [(0.0, 0.0), (width, 0.0), (0.0, height), (width, height)];
    let (mut lo, mut hi) = (
        Vector2::repeat(f64::INFINITY),
        Vector2::repeat(f64::NEG_INFINITY),
    );
    for (x, y) in corners {
        let f = inverse * (Vector2::new(x, y) - origin);
        lo = lo.inf(&f);
        hi = hi.sup(&f);
    }
    let offsets: Vec<_> = (0..lattice.motif().len())
        .map(|s| rotation * lattice.site_position(s))
        .collect();
    let mut sites = Vec::new();
    for n in (lo.x.floor() as i64 - 1)..=(hi.x.ceil() as i64 + 1) {
        for m in (lo.y.floor() as i64 - 1)..=(hi.y.ceil() as i64 + 1) {
            let cell = origin + basis * Vector2::new(n as f64, m as f64);
            for (site, offset) in offsets.iter().enumerate() {
                let position = cell + offset;
                if (0.0..=width).contains(&position.x) && (0.0..=height).contains(&position.y) {
                    sites.push(LatticeSite {
                        n,
                        m,
                        site,
                        position,
                    });
                }
            }
        }
    }
    sites
}
