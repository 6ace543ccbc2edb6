//! Plane-group operations: closed groups of lattice isometries of the right order, exact
//! symmetrisation, and the right groups recognised on known motifs.

use dhct_lattice::{Hexagonal, Lattice, PlaneGroup, Rectangular, Square};
use dhct_unitcell::{AveragedCell, SymmetryOperation, operations, symmetrize, symmetry_residuals};
use ndarray::Array2;

fn lattice_for(group: PlaneGroup) -> Box<dyn Lattice> {
    use PlaneGroup::*;
    match group {
        P3 | P3m1 | P31m | P6 | P6mm => Box::new(Hexagonal::graphite()),
        P4 | P4mm | P4gm => Box::new(Square::new(3e-10).unwrap()),
        _ => Box::new(Rectangular::new(3e-10, 4e-10).unwrap()),
    }
}

fn same(a: &SymmetryOperation, b: &SymmetryOperation) -> bool {
    let wrapped = |x: f64| (x - x.round()).abs() < 1e-12;
    a.matrix == b.matrix
        && wrapped(a.translation[0] - b.translation[0])
        && wrapped(a.translation[1] - b.translation[1])
}

#[test]
fn every_group_is_a_closed_set_of_lattice_isometries_of_its_order() {
    for group in PlaneGroup::ALL {
        let lattice = lattice_for(group);
        let ops = operations(group, lattice.as_ref()).unwrap_or_else(|e| panic!("{group}: {e}"));
        assert_eq!(ops.len(), group.order(), "{group}");
        for a in &ops {
            for b in &ops {
                // a ∘ b: W_a·W_b, W_a·t_b + t_a.
                let m = |i: usize, j: usize| {
                    a.matrix[i][0] * b.matrix[0][j] + a.matrix[i][1] * b.matrix[1][j]
                };
                let t = |i: usize| {
                    a.matrix[i][0] as f64 * b.translation[0]
                        + a.matrix[i][1] as f64 * b.translation[1]
                        + a.translation[i]
                };
                let product = SymmetryOperation {
                    matrix: [[m(0, 0), m(0, 1)], [m(1, 0), m(1, 1)]],
                    translation: [t(0), t(1)],
                };
                assert!(ops.iter().any(|o| same(o, &product)), "{group}: not closed");
            }
        }
    }
}

#[test]
fn groups_that_are_not_isometries_of_the_lattice_are_rejected() {
    let hexagonal = Hexagonal::graphite();
    let square = Square::new(3e-10).unwrap();
    assert!(operations(PlaneGroup::P4, &hexagonal).is_err());
    assert!(operations(PlaneGroup::P2mm, &hexagonal).is_err());
    assert!(operations(PlaneGroup::P6, &square).is_err());
    assert!(operations(PlaneGroup::P4, &Rectangular::new(3e-10, 4e-10).unwrap()).is_err());
}

/// A periodic cell on a 48² fractional grid of the hexagonal lattice with Gaussian atoms at
/// the given fractional positions and heights.
fn hexagonal_cell(atoms: &[([f64; 2], f64)]) -> AveragedCell {
    let lattice = Hexagonal::graphite();
    let [a1, a2] = lattice.primitive_vectors();
    let r = 48;
    let values = Array2::from_shape_fn((r, r), |(i, j)| {
        let (u, v) = (j as f64 / r as f64, i as f64 / r as f64);
        let mut z = 0.0;
        for (position, height) in atoms {
            for k in -2..=2 {
                for l in -2..=2 {
                    let d = a1 * (u - position[0] + k as f64) + a2 * (v - position[1] + l as f64);
                    z += height * (-d.norm_squared() / (2.0 * 0.5e-10f64.powi(2))).exp();
                }
            }
        }
        z
    });
    AveragedCell {
        values,
        cells: 1,
        skipped: 0,
    }
}

#[test]
fn graphite_like_cell_is_p3m1_about_its_atom_not_p31m() {
    // Strong β atom at the origin, weak α atom at (1/3, 1/3): site symmetry 3m with mirrors
    // along the bonds.
    let cell = hexagonal_cell(&[([0.0, 0.0], 1.0), ([1.0 / 3.0, 1.0 / 3.0], 0.3)]);
    let residuals = symmetry_residuals(&cell, &Hexagonal::graphite()).unwrap();
    let of = |g: PlaneGroup| residuals.iter().find(|r| r.group == g).unwrap().residual;
    for r in &residuals {
        println!("{}: {:.4}", r.group, r.residual);
    }
    assert!(of(PlaneGroup::P1) < 1e-12);
    assert!(
        of(PlaneGroup::P3) < 1e-9 && of(PlaneGroup::P3m1) < 1e-9,
        "{residuals:?}"
    );
    assert!(
        of(PlaneGroup::P31m) > 0.05 && of(PlaneGroup::P6) > 0.05 && of(PlaneGroup::P6mm) > 0.05
    );
    // Symmetrising is a projection.
    let ops = operations(PlaneGroup::P6mm, &Hexagonal::graphite()).unwrap();
    let once = symmetrize(&cell, &ops).unwrap();
    let twice = symmetrize(&once, &ops).unwrap();
    assert!(
        (&once.values - &twice.values)
            .iter()
            .all(|d| d.abs() < 1e-12)
    );
    // A single atom per cell is fully p6mm.
    let single = hexagonal_cell(&[([0.0, 0.0], 1.0)]);
    let residuals = symmetry_residuals(&single, &Hexagonal::graphite()).unwrap();
    assert!(residuals.iter().all(|r| r.residual < 1e-9), "{residuals:?}");
}

#[test]
fn odd_grids_are_refused_for_exact_symmetrisation() {
    let cell = AveragedCell {
        values: Array2::zeros((47, 47)),
        cells: 1,
        skipped: 0,
    };
    let ops = operations(PlaneGroup::P2, &Square::new(3e-10).unwrap()).unwrap();
    assert!(symmetrize(&cell, &ops).is_err());
}
