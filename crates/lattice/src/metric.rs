//! Whether a lattice's cell and motif agree with its plane group (within the precision of
//! the numbers given), and the cell made exact for the group: a file with rounded vectors
//! gets the exact metric its group implies, an inconsistent one an error naming what
//! disagrees.

use nalgebra::{Matrix2, Vector2};

use crate::{LatticeError, MotifSite, PlaneGroup};

/// Relative heights closer than this are one kind of site (a file's heights are rounded
/// like its positions).
const HEIGHT_TOLERANCE: f64 = 1e-3;

/// The metric a plane group needs of its cell.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Metric {
    /// Any cell.
    Oblique,
    /// a1 ⟂ a2.
    Rectangular,
    /// |a1| = |a2|, a1 ⟂ a2.
    Square,
    /// |a1| = |a2| at 60° or 120°.
    Hexagonal,
}

fn metric_of(group: PlaneGroup) -> Metric {
    use PlaneGroup::*;
    match group {
        P1 | P2 => Metric::Oblique,
        Pm | Pg | Cm | P2mm | P2mg | P2gg | C2mm => Metric::Rectangular,
        P4 | P4mm | P4gm => Metric::Square,
        P3 | P3m1 | P31m | P6 | P6mm => Metric::Hexagonal,
    }
}

/// The order of the group's rotations (1 when it has none beyond the identity).
fn rotation_order(group: PlaneGroup) -> u32 {
    use PlaneGroup::*;
    match group {
        P1 | Pm | Pg | Cm => 1,
        P2 | P2mm | P2mg | P2gg | C2mm => 2,
        P3 | P3m1 | P31m => 3,
        P4 | P4mm | P4gm => 4,
        P6 | P6mm => 6,
    }
}

/// `a1` and `a2` made exact for `group` (a2 rotated and scaled onto the group's metric),
/// or an error when they miss it by more than the relative `tolerance` (lengths) or
/// `tolerance` radians (angle).
pub(crate) fn exact_cell(
    a1: Vector2<f64>,
    a2: Vector2<f64>,
    group: PlaneGroup,
    tolerance: f64,
) -> Result<[Vector2<f64>; 2], LatticeError> {
    let metric = metric_of(group);
    let cross = a1.x * a2.y - a1.y * a2.x;
    let gamma = cross.abs().atan2(a1.dot(&a2));
    let sign = cross.signum();
    let ratio = a2.norm() / a1.norm();
    let (wanted_ratio, wanted_gamma) = match metric {
        Metric::Oblique => return Ok([a1, a2]),
        Metric::Rectangular => (ratio, std::f64::consts::FRAC_PI_2),
        Metric::Square => (1.0, std::f64::consts::FRAC_PI_2),
        Metric::Hexagonal => {
            let (sixty, one_twenty) = (60f64.to_radians(), 120f64.to_radians());
            let nearer = if (gamma - sixty).abs() < (gamma - one_twenty).abs() {
                sixty
            } else {
                one_twenty
            };
            (1.0, nearer)
        }
    };
    if (ratio - wanted_ratio).abs() > tolerance || (gamma - wanted_gamma).abs() > tolerance {
        return Err(LatticeError::MetricMismatch {
            group,
            needs: match metric {
                Metric::Rectangular => "a1 ⟂ a2",
                Metric::Square => "|a1| = |a2| and a1 ⟂ a2",
                _ => "|a1| = |a2| at 60° or 120°",
            },
            lengths: [a1.norm(), a2.norm()],
            angle_deg: gamma.to_degrees(),
            tolerance,
        });
    }
    let (sin, cos) = (sign * wanted_gamma).sin_cos();
    let direction = Vector2::new(cos * a1.x - sin * a1.y, sin * a1.x + cos * a1.y);
    Ok([a1, direction * wanted_ratio])
}

/// Checks that the group's rotation about `origin` (fractional) and, for a centred group,
/// the centring translation map every site of `motif` onto a site of equal relative height
/// within `tolerance` × the shorter vector (the cell `[a1, a2]` exact for the group).
pub(crate) fn check_motif_symmetry(
    cell: [Vector2<f64>; 2],
    motif: &[MotifSite],
    group: PlaneGroup,
    origin: [f64; 2],
    tolerance: f64,
) -> Result<(), LatticeError> {
    let basis = Matrix2::from_columns(&cell);
    let Some(inverse) = basis.try_inverse() else {
        return Ok(());
    };
    let order = rotation_order(group);
    let angle = 2.0 * std::f64::consts::PI / order as f64;
    let rotation = Matrix2::new(angle.cos(), -angle.sin(), angle.sin(), angle.cos());
    let w = inverse * rotation * basis;
    let reach = tolerance.max(1e-9) * cell[0].norm().min(cell[1].norm());
    let o = Vector2::from(origin);
    // (description, fractional matrix, fractional translation), acting as f ↦ W·f + t.
    let mut operations: Vec<(String, Matrix2<f64>, Vector2<f64>)> = Vec::new();
    if order > 1 {
        operations.push((format!("the {order}-fold rotation"), w, o - w * o));
    }
    if matches!(group, PlaneGroup::Cm | PlaneGroup::C2mm) {
        operations.push((
            "the centring translation (1/2, 1/2)".into(),
            Matrix2::identity(),
            Vector2::new(0.5, 0.5),
        ));
    }
    for (what, matrix, translation) in &operations {
        for (index, site) in motif.iter().enumerate() {
            let image = matrix * Vector2::from(site.fractional) + translation;
            let lands_on_a_site = motif.iter().any(|other| {
                let d = image - Vector2::from(other.fractional);
                let wrapped = d.map(|v| v - v.round());
                (basis * wrapped).norm() <= reach
                    && (other.relative_height - site.relative_height).abs() <= HEIGHT_TOLERANCE
            });
            if !lands_on_a_site {
                return Err(LatticeError::MotifNotSymmetric {
                    group,
                    operation: what.clone(),
                    origin,
                    index,
                    image: [image.x.rem_euclid(1.0), image.y.rem_euclid(1.0)],
                });
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rounded_hexagonal_vectors_are_made_exact_and_a_wrong_group_is_named() {
        let a1 = Vector2::new(2.46, 0.0);
        let a2 = Vector2::new(1.23, 2.1304);
        let [e1, e2] = exact_cell(a1, a2, PlaneGroup::P6mm, 1e-4).unwrap();
        assert_eq!(e1, a1);
        assert!((e2.norm() - 2.46).abs() < 1e-12);
        assert!((e2.x - 1.23).abs() < 1e-12);
        let error = exact_cell(a1, Vector2::new(1.25, 2.1304), PlaneGroup::P6mm, 1e-4)
            .unwrap_err()
            .to_string();
        assert!(
            error.contains("p6mm") && error.contains("|a1| = |a2|"),
            "{error}"
        );
        assert!(exact_cell(a1, a2, PlaneGroup::P2mm, 1e-4).is_err());
    }

    #[test]
    fn a_honeycomb_about_an_atom_is_not_six_fold() {
        let cell = [
            Vector2::new(2.46, 0.0),
            Vector2::new(1.23, 1.23 * 3f64.sqrt()),
        ];
        let motif = vec![
            MotifSite::new(0.0, 0.0, "A"),
            MotifSite::new(0.3333, 0.3333, "B"),
        ];
        let about_atom = check_motif_symmetry(cell, &motif, PlaneGroup::P6mm, [0.0, 0.0], 4e-4);
        assert!(matches!(
            about_atom,
            Err(LatticeError::MotifNotSymmetric { .. })
        ));
        check_motif_symmetry(cell, &motif, PlaneGroup::P6mm, [0.6667, 0.6667], 4e-4).unwrap();
    }
}
