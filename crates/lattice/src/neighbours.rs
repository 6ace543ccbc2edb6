//! Neighbour geometry derived from primitive vectors and motif: nearest-neighbour vectors
//! per motif site, neighbour shells, and the windows that tell the shells apart.

use nalgebra::Vector2;

use crate::MotifSite;

/// The default relative tolerance for two distances to count as one shell (exact
/// vectors); see [`crate::Lattice::shell_tolerance`].
pub const DEFAULT_SHELL_TOLERANCE: f64 = 1e-6;

/// The largest relative window around a nearest-neighbour distance (the DHCT paper's
/// 35 %); a lattice whose other shells are closer gets a narrower one.
pub const MAX_NEIGHBOUR_WINDOW: f64 = 0.35;

/// Most cells visited along either lattice direction in a neighbour search: bounds the work
/// for any lattice, even one that `UserLattice` validation would refuse (e.g. a preset
/// rectangle of extreme aspect ratio), at the cost of missing neighbours beyond it.
pub const MAX_CELL_REACH: i64 = 2048;

/// Most neighbour shells computed by [`crate::Lattice::neighbour_shells`].
pub const MAX_SHELLS: usize = 64;

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

/// All vectors from site `from` to features within `radius` (relative tolerance
/// `tolerance`), excluding itself.
fn vectors_within(
    vectors: [Vector2<f64>; 2],
    motif: &[MotifSite],
    from: usize,
    radius: f64,
    tolerance: f64,
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
                if d > radius * DEFAULT_SHELL_TOLERANCE && d <= radius * (1.0 + tolerance) {
                    out.push(v);
                }
            }
        }
    }
    out
}

/// Nearest-neighbour vectors of motif site `site`, sorted by angle from +x: the nearest
/// shell, extended by the next shells until the vectors span the plane (so a rectangular
/// lattice gets its ±a and ±b neighbours). Distances within the relative `tolerance` of a
/// shell's first are that shell.
pub(crate) fn nearest_neighbour_vectors(
    vectors: [Vector2<f64>; 2],
    motif: &[MotifSite],
    site: usize,
    tolerance: f64,
) -> Vec<Vector2<f64>> {
    // Both primitive vectors lie within this reach, so the candidates span the plane.
    let reach = vectors[0].norm().max(vectors[1].norm());
    let mut candidates = vectors_within(vectors, motif, site, reach, tolerance);
    candidates.sort_by(|a, b| a.norm().total_cmp(&b.norm()));
    let mut chosen: Vec<Vector2<f64>> = Vec::new();
    let mut index = 0;
    while index < candidates.len() {
        let shell = candidates[index].norm();
        while index < candidates.len() && candidates[index].norm() <= shell * (1.0 + tolerance) {
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

/// The first `count` distinct neighbour distances over all motif sites, ascending:
/// distances are clustered, a distance within the relative `tolerance` of its cluster's
/// first joining it, and each shell is its cluster's mean.
pub(crate) fn shell_distances(
    vectors: [Vector2<f64>; 2],
    motif: &[MotifSite],
    count: usize,
    tolerance: f64,
) -> Vec<f64> {
    // Multiples of the shorter primitive vector alone give `count` distinct distances.
    let count = count.clamp(1, MAX_SHELLS);
    let shortest = vectors[0].norm().min(vectors[1].norm());
    let radius = count as f64 * shortest;
    let distances: Vec<f64> = (0..motif.len())
        .flat_map(|site| vectors_within(vectors, motif, site, radius, tolerance))
        .map(|v| v.norm())
        .collect();
    let mut shells = cluster_distances(distances, tolerance);
    shells.truncate(count);
    if shells.is_empty() {
        // Only for degenerate input (non-finite vectors): never an empty list.
        shells.push(shortest);
    }
    shells
}

/// Clusters `distances` into shells (ascending): a distance within the relative
/// `tolerance` of its cluster's smallest joins it; each shell is its cluster's mean.
pub(crate) fn cluster_distances(mut distances: Vec<f64>, tolerance: f64) -> Vec<f64> {
    distances.sort_by(f64::total_cmp);
    let mut clusters: Vec<(f64, f64, usize)> = Vec::new(); // (first, sum, count)
    for d in distances {
        match clusters.last_mut() {
            Some((first, sum, count)) if d <= *first * (1.0 + tolerance) => {
                *sum += d;
                *count += 1;
            }
            _ => clusters.push((d, d, 1)),
        }
    }
    clusters
        .into_iter()
        .map(|(_, sum, count)| sum / count as f64)
        .collect()
}

/// The relative half-width of a window around each of the `inside` distances that keeps
/// every `outside` distance out with a margin (half the smallest relative gap), at most
/// [`MAX_NEIGHBOUR_WINDOW`]. With no outside distance the window is the maximum.
pub(crate) fn separating_window(inside: &[f64], outside: &[f64]) -> f64 {
    let mut window = MAX_NEIGHBOUR_WINDOW;
    for &d in inside {
        for &s in outside {
            window = window.min(0.5 * (s - d).abs() / d);
        }
    }
    window
}
