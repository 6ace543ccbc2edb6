//! The asymmetric unit of a plane group: the smallest part of the cell from which the group's
//! operations rebuild the whole cell, outlined on the symmetry-averaged cell.
//!
//! The polygons are those of the International Tables for Crystallography (Vol. A), in the
//! same axes as [`crate::operations`]: tabulated in the group's own axes (120° axes for the
//! hexagonal groups) and converted to the lattice's fractional coordinates. A test checks,
//! for every group, that the polygon's images under the operations tile the cell exactly once.

use dhct_lattice::{Lattice, PlaneGroup};

use crate::{UnitCellError, operations};

/// Vertices (counter-clockwise in the tabulated axes) of the ITA asymmetric unit.
fn tabulated(group: PlaneGroup) -> (Vec<[f64; 2]>, bool) {
    let (h, q, t1, t2) = (0.5, 0.25, 1.0 / 3.0, 2.0 / 3.0);
    let rect = |v: &[[f64; 2]]| (v.to_vec(), false);
    let hex = |v: &[[f64; 2]]| (v.to_vec(), true);
    match group {
        PlaneGroup::P1 => rect(&[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]),
        PlaneGroup::P2 | PlaneGroup::Pm | PlaneGroup::Pg => {
            rect(&[[0.0, 0.0], [h, 0.0], [h, 1.0], [0.0, 1.0]])
        }
        PlaneGroup::Cm | PlaneGroup::P2mm | PlaneGroup::P2gg | PlaneGroup::P4 => {
            rect(&[[0.0, 0.0], [h, 0.0], [h, h], [0.0, h]])
        }
        PlaneGroup::P2mg => rect(&[[0.0, 0.0], [q, 0.0], [q, 1.0], [0.0, 1.0]]),
        PlaneGroup::C2mm => rect(&[[0.0, 0.0], [q, 0.0], [q, h], [0.0, h]]),
        PlaneGroup::P4mm => rect(&[[0.0, 0.0], [h, 0.0], [h, h]]),
        PlaneGroup::P4gm => rect(&[[0.0, 0.0], [h, 0.0], [0.0, h]]),
        PlaneGroup::P3 => hex(&[[0.0, 0.0], [h, 0.0], [t2, t1], [t1, t2], [0.0, h]]),
        PlaneGroup::P3m1 => hex(&[[0.0, 0.0], [t2, t1], [t1, t2]]),
        PlaneGroup::P31m | PlaneGroup::P6 => hex(&[[0.0, 0.0], [h, 0.0], [t2, t1], [h, h]]),
        PlaneGroup::P6mm => hex(&[[0.0, 0.0], [h, 0.0], [t2, t1]]),
    }
}

/// The asymmetric unit of `group` as a polygon in the fractional coordinates `(u, v)` of
/// `lattice` (position = u·a1 + v·a2), placed at the lattice's symmetry origin. Errors as [`operations`] when the group is not a
/// symmetry of the lattice.
pub fn asymmetric_unit(
    group: PlaneGroup,
    lattice: &dyn Lattice,
) -> Result<Vec<[f64; 2]>, UnitCellError> {
    // Reject incompatible groups exactly as the averaging does.
    operations(group, lattice)?;
    let (vertices, hexagonal_axes) = tabulated(group);
    let [ou, ov] = lattice.symmetry_origin();
    Ok(vertices
        .iter()
        .map(|&[x, y]| {
            // 120° axes (x, y) → dhct's 60° axes (u, v): u = x − y, v = y.
            let [u, v] = if hexagonal_axes { [x - y, y] } else { [x, y] };
            [u + ou, v + ov]
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use dhct_lattice::{Hexagonal, Rectangular, Square};

    /// Whether `p` lies strictly inside the convex polygon (either orientation).
    fn inside(polygon: &[[f64; 2]], p: [f64; 2]) -> Option<bool> {
        let n = polygon.len();
        let mut sign = 0.0f64;
        for i in 0..n {
            let (a, b) = (polygon[i], polygon[(i + 1) % n]);
            let cross = (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0]);
            if cross.abs() < 1e-9 {
                return None; // on an edge: not a generic point
            }
            if sign == 0.0 {
                sign = cross.signum();
            } else if cross.signum() != sign {
                return Some(false);
            }
        }
        Some(true)
    }

    fn check(group: PlaneGroup, lattice: &dyn Lattice) {
        let polygon = asymmetric_unit(group, lattice).unwrap();
        let ops = operations(group, lattice).unwrap();
        // Every generic point of the cell has exactly one image (mod lattice) inside.
        let mut state = 12345u64;
        let mut random = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut tested = 0;
        while tested < 2000 {
            let p = [random(), random()];
            let mut hits = 0;
            let mut generic = true;
            for op in &ops {
                let w = op.matrix;
                let q = [
                    w[0][0] as f64 * p[0] + w[0][1] as f64 * p[1] + op.translation[0],
                    w[1][0] as f64 * p[0] + w[1][1] as f64 * p[1] + op.translation[1],
                ];
                for i in -2..=2 {
                    for j in -2..=2 {
                        match inside(&polygon, [q[0] + i as f64, q[1] + j as f64]) {
                            Some(true) => hits += 1,
                            Some(false) => {}
                            None => generic = false,
                        }
                    }
                }
            }
            if generic {
                assert_eq!(hits, 1, "{group}: point {p:?} has {hits} images inside");
                tested += 1;
            }
        }
    }

    #[test]
    fn every_asymmetric_unit_tiles_the_cell_once() {
        let graphite = Hexagonal::graphite();
        for group in [
            PlaneGroup::P1,
            PlaneGroup::P2,
            PlaneGroup::P3,
            PlaneGroup::P3m1,
            PlaneGroup::P31m,
            PlaneGroup::P6,
            PlaneGroup::P6mm,
        ] {
            check(group, &graphite);
        }
        let square = Square::new(3e-10).unwrap();
        for group in [PlaneGroup::P4, PlaneGroup::P4mm, PlaneGroup::P4gm] {
            check(group, &square);
        }
        let rectangular = Rectangular::new(3e-10, 4e-10).unwrap();
        for group in [
            PlaneGroup::Pm,
            PlaneGroup::Pg,
            PlaneGroup::Cm,
            PlaneGroup::P2mm,
            PlaneGroup::P2mg,
            PlaneGroup::P2gg,
            PlaneGroup::C2mm,
        ] {
            check(group, &rectangular);
        }
    }

    #[test]
    fn incompatible_group_is_rejected() {
        assert!(asymmetric_unit(PlaneGroup::P4, &Hexagonal::graphite()).is_err());
    }
}
