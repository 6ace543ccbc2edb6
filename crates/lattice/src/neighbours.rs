//! Neighbour geometry derived from primitive vectors and motif, and enumeration of the
//! lattice sites inside a region.

use nalgebra::{Matrix2, Vector2};
use serde::{Deserialize, Serialize};

use crate::{Lattice, MotifSite};

/// Relative tolerance for two distances to count as one shell.
const SHELL_TOLERANCE: f64 = 1e-6;

/// Most cells visited along either lattice direction in a neighbour search: bounds the work
/// for any lattice, even one that `UserLattice` validation would refuse (e.g. a preset
/// rectangle of extreme aspect ratio), at the cost of missing neighbours beyond it.
pub const MAX_CELL_REACH: i64 = 2048;

/// Most neighbour shells computed by [`crate::Lattice::neighbour_shells`].
pub const MAX_SHELLS: usize = 64;

/// Most cells [`lattice_sites`] visits (10^8, about 5 GB of sites); a larger region gives
/// no sites.
pub const MAX_REGION_CELLS: f64 = 1e8;

/// The offset of a motif site from its cell origin, with the fractional position wrapped
/// into `[0, 1)`: the set of features (and so every neighbour vector) is the same, and the
/// search reach no longer grows with a site given many cells away.
fn site_offset(vectors: [Vector2<f64>; 2], site: &MotifSite) -> Vector2<f64> {
    let wrap = |f: f64| f.rem_euclid(1.0);
    vectors[0] * wrap(site.fractional[0]) + vectors[1] * wrap(site.fractional[1])
}

/// Cells to visit along a1 and a2 (each way) to find every feature within `radius` of
/// any motif site, capped at [`MAX_CELL_REACH`] (0 for non-finite input).
fn search_reach(vectors: [Vector2<f64>; 2], motif: &[MotifSite], radius: f64) -> (i64, i64) {
    let [a1, a2] = vectors;
    let area = (a1.x * a2.y - a1.y * a2.x).abs();
    // Distance between neighbouring lines of constant n (and of constant m).
    let (h1, h2) = (area / a2.norm(), area / a1.norm());
    let max_offset = motif
        .iter()
        .map(|s| site_offset(vectors, s).norm())
        .fold(0.0, f64::max);
    let reach = radius + 2.0 * max_offset;
    // `as` saturates and maps NaN to 0; the cap bounds the loops.
    let cells = |h: f64| ((reach / h).ceil().min(MAX_CELL_REACH as f64) as i64 + 1).max(1);
    (cells(h1), cells(h2))
}

/// Site comparisons needed to find the nearest neighbours of every motif site: what
/// [`crate::UserLattice`] validation bounds.
pub(crate) fn neighbour_search_work(vectors: [Vector2<f64>; 2], motif: &[MotifSite]) -> f64 {
    let reach = vectors[0].norm().max(vectors[1].norm());
    let (n_max, m_max) = search_reach(vectors, motif, reach);
    let sites = motif.len() as f64;
    (2 * n_max + 1) as f64 * (2 * m_max + 1) as f64 * sites * sites
}

/// All vectors from site `from` to features within `radius` (excluding itself).
fn vectors_within(
    vectors: [Vector2<f64>; 2],
    motif: &[MotifSite],
    from: usize,
    radius: f64,
) -> Vec<Vector2<f64>> {
    let [a1, a2] = vectors;
    let (n_max, m_max) = search_reach(vectors, motif, radius);
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
    let count = count.clamp(1, MAX_SHELLS);
    let shortest = vectors[0].norm().min(vectors[1].norm());
    let radius = count as f64 * shortest;
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
    if shells.is_empty() {
        // Only for degenerate input (non-finite vectors): never an empty list.
        shells.push(shortest);
    }
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
/// Regions of more than [`MAX_REGION_CELLS`] cells, and non-finite input, give no sites.
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
    let (n_lo, n_hi) = (lo.x.floor() - 1.0, hi.x.ceil() + 1.0);
    let (m_lo, m_hi) = (lo.y.floor() - 1.0, hi.y.ceil() + 1.0);
    let cells = (n_hi - n_lo + 1.0) * (m_hi - m_lo + 1.0);
    if !(cells.is_finite() && cells <= MAX_REGION_CELLS) {
        return Vec::new();
    }
    let offsets: Vec<_> = (0..lattice.motif().len())
        .map(|s| rotation * lattice.site_position(s))
        .collect();
    let mut sites = Vec::new();
    for n in (n_lo as i64)..=(n_hi as i64) {
        for m in (m_lo as i64)..=(m_hi as i64) {
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
