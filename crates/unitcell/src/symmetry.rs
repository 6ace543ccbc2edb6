//! Plane-group symmetry averaging of an averaged unit cell.
//!
//! Each operation of a plane group acts on fractional coordinates `(u, v)` (along a1, a2) as
//! `(u, v) → W·(u, v) + w (mod 1)` with an integer matrix `W` and a translation `w` of 0 or ½.
//! On the averaged cell's grid (`u = j/R`, `v = i/R`) this maps grid points onto grid points
//! exactly when `R` is even, so symmetrising needs no interpolation: the symmetrised cell is
//! the mean of the cell over all operations. Operations are about the cell origin, which
//! [`crate::local_cells`] places on motif site 0.
//!
//! The operations are those of the International Tables for Crystallography (Vol. A) in the
//! conventional cell. Hexagonal groups are tabulated there for axes at 120°; dhct's
//! hexagonal lattices have a2 at 60° (a2 = a1 + b), so they are converted by
//! `u = x − y, v = y`. Centred groups (cm, c2mm) need the conventional (rectangular) cell,
//! i.e. a lattice whose cell is that cell. A group whose operations are not isometries of
//! the lattice (e.g. p4 on a hexagonal lattice) is rejected.

use dhct_lattice::{Lattice, PlaneGroup};
use nalgebra::Matrix2;
use ndarray::Array2;
use serde::{Deserialize, Serialize};

use crate::{AveragedCell, UnitCellError};

/// One plane-group operation in fractional coordinates: `x' = matrix·x + translation`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SymmetryOperation {
    /// The integer point-group part, rows of a 2 × 2 matrix in the a1, a2 basis.
    pub matrix: [[i64; 2]; 2],
    /// The translation, fractions of a1 and a2.
    pub translation: [f64; 2],
}

/// How far an averaged cell is from a plane group's symmetry.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SymmetryResidual {
    /// The plane group tested.
    pub group: PlaneGroup,
    /// `‖A − S(A)‖ / ‖A − mean(A)‖`: 0 for a perfectly symmetric cell.
    pub residual: f64,
}

type Op = ([[i64; 2]; 2], [f64; 2]);

const E: Op = ([[1, 0], [0, 1]], [0.0, 0.0]);
const INVERSION: Op = ([[-1, 0], [0, -1]], [0.0, 0.0]);

/// Operations as tabulated (oblique, rectangular and square groups in their own axes,
/// hexagonal groups in 120° axes), and whether the axes are hexagonal.
fn tabulated(group: PlaneGroup) -> (Vec<Op>, bool) {
    let h = 0.5;
    let rect = |ops: &[Op]| (ops.to_vec(), false);
    let hex = |ops: &[Op]| (ops.to_vec(), true);
    // Hexagonal (120° axes): 3-fold (x,y)→(−y,x−y), (x,y)→(−x+y,−x); 2-fold (−x,−y);
    // 6-fold (y,−x+y), (x−y,x); mirrors of p3m1 (−y,−x), (−x+y,y), (x,x−y); of p31m (y,x),
    // (x−y,−y), (−x,−x+y).
    let three = [
        ([[0, -1], [1, -1]], [0.0, 0.0]),
        ([[-1, 1], [-1, 0]], [0.0, 0.0]),
    ];
    let six = [
        INVERSION,
        ([[0, 1], [-1, 1]], [0.0, 0.0]),
        ([[1, -1], [1, 0]], [0.0, 0.0]),
    ];
    let m_3m1 = [
        ([[0, -1], [-1, 0]], [0.0, 0.0]),
        ([[-1, 1], [0, 1]], [0.0, 0.0]),
        ([[1, 0], [1, -1]], [0.0, 0.0]),
    ];
    let m_31m = [
        ([[0, 1], [1, 0]], [0.0, 0.0]),
        ([[1, -1], [0, -1]], [0.0, 0.0]),
        ([[-1, 0], [-1, 1]], [0.0, 0.0]),
    ];
    let mx = ([[-1, 0], [0, 1]], [0.0, 0.0]);
    let my = ([[1, 0], [0, -1]], [0.0, 0.0]);
    let four = [
        ([[0, -1], [1, 0]], [0.0, 0.0]),
        ([[0, 1], [-1, 0]], [0.0, 0.0]),
    ];
    let diagonals = [
        ([[0, 1], [1, 0]], [0.0, 0.0]),
        ([[0, -1], [-1, 0]], [0.0, 0.0]),
    ];
    match group {
        PlaneGroup::P1 => rect(&[E]),
        PlaneGroup::P2 => rect(&[E, INVERSION]),
        PlaneGroup::Pm => rect(&[E, mx]),
        PlaneGroup::Pg => rect(&[E, ([[-1, 0], [0, 1]], [0.0, h])]),
        PlaneGroup::Cm => rect(&[
            E,
            mx,
            ([[1, 0], [0, 1]], [h, h]),
            ([[-1, 0], [0, 1]], [h, h]),
        ]),
        PlaneGroup::P2mm => rect(&[E, INVERSION, mx, my]),
        PlaneGroup::P2mg => rect(&[
            E,
            INVERSION,
            ([[-1, 0], [0, 1]], [h, 0.0]),
            ([[1, 0], [0, -1]], [h, 0.0]),
        ]),
        PlaneGroup::P2gg => rect(&[
            E,
            INVERSION,
            ([[-1, 0], [0, 1]], [h, h]),
            ([[1, 0], [0, -1]], [h, h]),
        ]),
        PlaneGroup::C2mm => {
            let base = [E, INVERSION, mx, my];
            let centred: Vec<Op> = base.iter().map(|(w, _)| (*w, [h, h])).collect();
            (base.iter().copied().chain(centred).collect(), false)
        }
        PlaneGroup::P4 => rect(&[E, INVERSION, four[0], four[1]]),
        PlaneGroup::P4mm => rect(&[
            E,
            INVERSION,
            four[0],
            four[1],
            mx,
            my,
            diagonals[0],
            diagonals[1],
        ]),
        PlaneGroup::P4gm => {
            let glides: Vec<Op> = [mx, my, diagonals[0], diagonals[1]]
                .iter()
                .map(|(w, _)| (*w, [h, h]))
                .collect();
            (
                vec![E, INVERSION, four[0], four[1]]
                    .into_iter()
                    .chain(glides)
                    .collect(),
                false,
            )
        }
        PlaneGroup::P3 => hex(&[E, three[0], three[1]]),
        PlaneGroup::P3m1 => hex(&[E, three[0], three[1], m_3m1[0], m_3m1[1], m_3m1[2]]),
        PlaneGroup::P31m => hex(&[E, three[0], three[1], m_31m[0], m_31m[1], m_31m[2]]),
        PlaneGroup::P6 => hex(&[E, three[0], three[1], six[0], six[1], six[2]]),
        PlaneGroup::P6mm => {
            let ops: Vec<Op> = [E, three[0], three[1]]
                .into_iter()
                .chain(six)
                .chain(m_3m1)
                .chain(m_31m)
                .collect();
            (ops, true)
        }
    }
}

fn multiply(a: [[i64; 2]; 2], b: [[i64; 2]; 2]) -> [[i64; 2]; 2] {
    let mut out = [[0; 2]; 2];
    for i in 0..2 {
        for j in 0..2 {
            out[i][j] = a[i][0] * b[0][j] + a[i][1] * b[1][j];
        }
    }
    out
}

/// The operations of `group` in the fractional coordinates of `lattice`, or an error if the
/// group's operations are not isometries of the lattice.
pub fn operations(
    group: PlaneGroup,
    lattice: &dyn Lattice,
) -> Result<Vec<SymmetryOperation>, UnitCellError> {
    let (ops, hexagonal_axes) = tabulated(group);
    // From 120° axes (x, y) to 60° axes (u, v): u = x − y, v = y; P = [[1, −1], [0, 1]].
    let (p, p_inverse) = ([[1, -1], [0, 1]], [[1, 1], [0, 1]]);
    let [a1, a2] = lattice.primitive_vectors();
    let basis = Matrix2::from_columns(&[a1, a2]);
    let basis_inverse = basis
        .try_inverse()
        .ok_or(UnitCellError::IncompatibleGroup {
            group,
            lattice: lattice.name().to_string(),
        })?;
    ops.into_iter()
        .map(|(w, t)| {
            let (matrix, translation) = if hexagonal_axes {
                let m = multiply(multiply(p, w), p_inverse);
                (m, [t[0] - t[1], t[1]])
            } else {
                (w, t)
            };
            // An isometry of the lattice: basis·W·basis⁻¹ must be orthogonal.
            let w = Matrix2::new(
                matrix[0][0] as f64,
                matrix[0][1] as f64,
                matrix[1][0] as f64,
                matrix[1][1] as f64,
            );
            let q = basis * w * basis_inverse;
            if (q.transpose() * q - Matrix2::identity()).abs().max() > 1e-9 {
                return Err(UnitCellError::IncompatibleGroup {
                    group,
                    lattice: lattice.name().to_string(),
                });
            }
            // About the lattice's symmetry origin o: x' = W(x − o) + o + t.
            let [ou, ov] = lattice.symmetry_origin();
            let shifted = [
                translation[0] + ou - (matrix[0][0] as f64 * ou + matrix[0][1] as f64 * ov),
                translation[1] + ov - (matrix[1][0] as f64 * ou + matrix[1][1] as f64 * ov),
            ];
            Ok(SymmetryOperation {
                matrix,
                translation: shifted.map(|t| t.rem_euclid(1.0)),
            })
        })
        .collect()
}

/// The mean of `cell` over the operations: a cell with the group's symmetry.
pub fn symmetrize(
    cell: &AveragedCell,
    operations: &[SymmetryOperation],
) -> Result<AveragedCell, UnitCellError> {
    let (rows, cols) = cell.values.dim();
    if rows != cols || rows % 2 != 0 {
        return Err(UnitCellError::BadResolution(rows));
    }
    let r = rows as i64;
    let mut sum = Array2::<f64>::zeros((rows, cols));
    for op in operations {
        let [[w00, w01], [w10, w11]] = op.matrix;
        let (tu, tv) = (
            (op.translation[0] * r as f64).round() as i64,
            (op.translation[1] * r as f64).round() as i64,
        );
        for ((i, j), value) in sum.indexed_iter_mut() {
            let (u, v) = (j as i64, i as i64);
            let (u2, v2) = (
                (w00 * u + w01 * v + tu).rem_euclid(r),
                (w10 * u + w11 * v + tv).rem_euclid(r),
            );
            *value += cell.values[[v2 as usize, u2 as usize]];
        }
    }
    Ok(AveragedCell {
        values: sum / operations.len() as f64,
        ..cell.clone()
    })
}

/// The symmetry residual of `cell` for every plane group compatible with `lattice`.
pub fn symmetry_residuals(
    cell: &AveragedCell,
    lattice: &dyn Lattice,
) -> Result<Vec<SymmetryResidual>, UnitCellError> {
    let mean = cell.values.mean().unwrap_or(0.0);
    let spread: f64 = cell
        .values
        .iter()
        .map(|v| (v - mean).powi(2))
        .sum::<f64>()
        .sqrt();
    let mut out = Vec::new();
    for group in PlaneGroup::ALL {
        let Ok(ops) = operations(group, lattice) else {
            continue;
        };
        let symmetric = symmetrize(cell, &ops)?;
        let difference: f64 = cell
            .values
            .iter()
            .zip(symmetric.values.iter())
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f64>()
            .sqrt();
        out.push(SymmetryResidual {
            group,
            residual: if spread > 0.0 {
                difference / spread
            } else {
                0.0
            },
        });
    }
    Ok(out)
}
