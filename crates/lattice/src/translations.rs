//! The translation cell of a lattice's image: the smallest cell that repeats it, which is
//! smaller than the declared cell when the motif repeats inside it (a centred cell given
//! by its conventional rectangle, a superstructure cell with equal sites).

use nalgebra::{Matrix2, Vector2};

use crate::MotifSite;

/// Relative heights closer than this are one kind of site.
const HEIGHT_TOLERANCE: f64 = 1e-9;

/// Fractional translations `t` (in `[0, 1)²`, not zero) that map every motif site onto a
/// site of equal relative height, within `tolerance` (fractional).
fn internal_translations(motif: &[MotifSite], tolerance: f64) -> Vec<[f64; 2]> {
    let wrapped = |d: f64| {
        let w = d - d.round();
        w.abs() <= tolerance
    };
    let first = motif[0].fractional;
    motif[1..]
        .iter()
        .map(|s| {
            [
                (s.fractional[0] - first[0]).rem_euclid(1.0),
                (s.fractional[1] - first[1]).rem_euclid(1.0),
            ]
        })
        .filter(|t| {
            motif.iter().all(|site| {
                motif.iter().any(|other| {
                    (other.relative_height - site.relative_height).abs() <= HEIGHT_TOLERANCE
                        && wrapped(site.fractional[0] + t[0] - other.fractional[0])
                        && wrapped(site.fractional[1] + t[1] - other.fractional[1])
                })
            })
        })
        .collect()
}

/// The primitive vectors of the image's own translation lattice (metres, a reduced basis
/// with the handedness of `vectors`): `vectors` themselves unless the motif repeats inside
/// the cell.
pub(crate) fn translation_cell(
    vectors: [Vector2<f64>; 2],
    motif: &[MotifSite],
    tolerance: f64,
) -> [Vector2<f64>; 2] {
    if motif.len() < 2 {
        return vectors;
    }
    let translations = internal_translations(motif, tolerance);
    if translations.is_empty() {
        return vectors;
    }
    let cell = Matrix2::from_columns(&vectors);
    let area = cell.determinant();
    let target = area.abs() / (translations.len() + 1) as f64;
    let mut candidates: Vec<Vector2<f64>> = Vec::new();
    for t in std::iter::once([0.0, 0.0]).chain(translations) {
        for n in -2..=2 {
            for m in -2..=2 {
                let v = cell * Vector2::new(t[0] + n as f64, t[1] + m as f64);
                if v.norm() > 1e-9 * vectors[0].norm() {
                    candidates.push(v);
                }
            }
        }
    }
    candidates.sort_by(|a, b| a.norm().total_cmp(&b.norm()));
    let first = candidates[0];
    let second = candidates.iter().find(|v| {
        let cross = first.x * v.y - first.y * v.x;
        (cross.abs() - target).abs() <= 1e-6 * target
    });
    match second {
        Some(&v) if (first.x * v.y - first.y * v.x) * area > 0.0 => [first, v],
        Some(&v) => [first, -v],
        None => vectors,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_centred_rectangle_repeats_by_its_half_diagonal() {
        let vectors = [Vector2::new(3.0, 0.0), Vector2::new(0.0, 4.0)];
        let motif = vec![MotifSite::new(0.0, 0.0, ""), MotifSite::new(0.5, 0.5, "")];
        let [t1, t2] = translation_cell(vectors, &motif, 1e-9);
        let area = (t1.x * t2.y - t1.y * t2.x).abs();
        assert!((area - 6.0).abs() < 1e-12, "{t1} {t2}");
        assert!((t1.norm() - 2.5).abs() < 1e-12);
        // Sites of different heights do not repeat: the cell stays.
        let mut motif = motif;
        motif[1].relative_height = 0.5;
        assert_eq!(translation_cell(vectors, &motif, 1e-9), vectors);
    }
}
