//! The features of a lattice placed in a region of an image.

use nalgebra::{Matrix2, Vector2};
use serde::{Deserialize, Serialize};

use crate::Lattice;

/// Most cells [`lattice_sites`] visits (10^8, about 5 GB of sites); a larger region gives
/// no sites.
pub const MAX_REGION_CELLS: f64 = 1e8;

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
