use std::collections::HashMap;

use dhct_lattice::{Lattice, LatticeFit};
use nalgebra::{Matrix2, Vector2};
use serde::{Deserialize, Serialize};

/// One unit cell fitted to its own four corner features (motif site 0 of cells
/// `(n, m)`, `(n+1, m)`, `(n, m+1)`, `(n+1, m+1)`), with the orientation of the whole-image
/// fit: `p = o + D(s_x, s_y)·R(θ)·(k·a1 + l·a2)` for corners `k, l ∈ {0, 1}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LocalCell {
    /// Cell index of the first corner along a1.
    pub n: i64,
    /// Cell index of the first corner along a2.
    pub m: i64,
    /// Local origin (the first corner's fitted position), metres.
    pub origin_m: [f64; 2],
    /// Local scales along x and y.
    pub scale: [f64; 2],
    /// Orientation θ (from the whole-image fit), radians.
    pub angle_rad: f64,
    /// Indices of the corner features in the point list, order (0,0), (1,0), (0,1), (1,1).
    pub corners: [usize; 4],
    /// Corner deviations from the local cell, metres, same order.
    pub deviations_m: [[f64; 2]; 4],
}

impl LocalCell {
    /// The linear map `D·R` from lattice-frame vectors to positions, for this cell.
    pub fn transform(&self) -> Matrix2<f64> {
        let (sin, cos) = self.angle_rad.sin_cos();
        Matrix2::new(
            self.scale[0] * cos,
            -self.scale[0] * sin,
            self.scale[1] * sin,
            self.scale[1] * cos,
        )
    }
}

const CORNERS: [(i64, i64); 4] = [(0, 0), (1, 0), (0, 1), (1, 1)];

/// Every cell of point set `set` whose four corners were indexed by `fit`; `positions` are
/// the same points (metres) that were given to the fit for that set.
pub fn local_cells(
    lattice: &dyn Lattice,
    fit: &LatticeFit,
    positions: &[[f64; 2]],
    set: usize,
) -> Vec<LocalCell> {
    let Some(indexed) = fit.points.get(set) else {
        return Vec::new();
    };
    // Site-0 features by cell; of two features indexed to one site keep the closer one.
    let mut by_cell: HashMap<(i64, i64), usize> = HashMap::new();
    for (i, p) in indexed.iter().enumerate().filter(|(_, p)| p.site == 0) {
        let deviation = |k: usize| {
            let d = indexed[k].deviation_m;
            d[0].hypot(d[1])
        };
        by_cell
            .entry((p.n, p.m))
            .and_modify(|k| {
                if deviation(i) < deviation(*k) {
                    *k = i;
                }
            })
            .or_insert(i);
    }
    let [a1, a2] = lattice.primitive_vectors();
    let (sin, cos) = fit.angle_rad.sin_cos();
    let rotation = Matrix2::new(cos, -sin, sin, cos);
    let corner_vectors: Vec<Vector2<f64>> = CORNERS
        .iter()
        .map(|&(k, l)| rotation * (a1 * k as f64 + a2 * l as f64))
        .collect();
    let mut cells: Vec<LocalCell> = by_cell
        .keys()
        .filter_map(|&(n, m)| {
            let corners =
                [(n, m), (n + 1, m), (n, m + 1), (n + 1, m + 1)].map(|c| by_cell.get(&c).copied());
            let corners = [corners[0]?, corners[1]?, corners[2]?, corners[3]?];
            // Each axis: p = o + s·w, two unknowns, four equations.
            let mut origin = [0.0; 2];
            let mut scale = [0.0; 2];
            for axis in 0..2 {
                let (mut sw, mut sww, mut sp, mut swp) = (0.0, 0.0, 0.0, 0.0);
                for (corner, w) in corners.iter().zip(&corner_vectors) {
                    let (w, p) = (w[axis], positions[*corner][axis]);
                    sw += w;
                    sww += w * w;
                    sp += p;
                    swp += w * p;
                }
                let determinant = 4.0 * sww - sw * sw;
                if determinant.abs() <= 1e-30 * sww.max(f64::MIN_POSITIVE) {
                    // The cell has no extent along this axis (cannot happen for a 2-D lattice).
                    return None;
                }
                scale[axis] = (4.0 * swp - sw * sp) / determinant;
                origin[axis] = (sp - scale[axis] * sw) / 4.0;
            }
            let deviations_m = [0, 1, 2, 3].map(|k| {
                let p = positions[corners[k]];
                let w = corner_vectors[k];
                [
                    p[0] - origin[0] - scale[0] * w.x,
                    p[1] - origin[1] - scale[1] * w.y,
                ]
            });
            Some(LocalCell {
                n,
                m,
                origin_m: origin,
                scale,
                angle_rad: fit.angle_rad,
                corners,
                deviations_m,
            })
        })
        .collect();
    cells.sort_by_key(|c| (c.m, c.n));
    cells
}
