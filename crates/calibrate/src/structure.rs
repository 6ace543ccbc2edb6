//! What a lattice predicts for its own spectrum: the amplitude of each reflection from the
//! motif (structure factor, sites weighted by their relative heights) and the features'
//! Gaussian width (form factor). A motif can make a second-order reflection the strongest
//! (kagome: |F(2,0)| = 3, |F(1,0)| = 1), which is the lattice itself, not a superstructure.

use dhct_lattice::Lattice;
use nalgebra::{Matrix2, Vector2};

use crate::image_lattice::real_basis;

/// Width σ of a feature as a fraction of the nearest-neighbour distance when the lattice
/// does not say (the DHCT kernel).
const DEFAULT_WIDTH_FRACTION: f64 = 0.25;

/// The motif's structure factor `|Σ_j w_j·exp(2πi G·s_j)|` of reflection `index` over
/// its largest possible value `Σ_j |w_j|` (0 for a systematic absence), lattice on `target`.
pub(crate) fn structure_factor(
    lattice: &dyn Lattice,
    target: &Matrix2<f64>,
    index: [i64; 2],
) -> f64 {
    let Some(reciprocal) = real_basis(target) else {
        return 0.0;
    };
    let g = reciprocal * Vector2::new(index[0] as f64, index[1] as f64);
    let (mut re, mut im, mut total) = (0.0, 0.0, 0.0);
    for (j, site) in lattice.motif().iter().enumerate() {
        let phase = 2.0 * std::f64::consts::PI * g.dot(&lattice.site_position(j));
        re += site.relative_height * phase.cos();
        im += site.relative_height * phase.sin();
        total += site.relative_height.abs();
    }
    re.hypot(im) / total.max(f64::MIN_POSITIVE)
}

/// The predicted amplitude of reflection `index` of the lattice placed on basis `target`
/// (columns, metres, lattice frame: the lattice's translation cell times an integer basis
/// change): `|Σ_j w_j·exp(2πi G·s_j)|·exp(−2π²σ²|G|²)`.
pub(crate) fn amplitude(
    lattice: &dyn Lattice,
    target: &Matrix2<f64>,
    index: [i64; 2],
) -> Option<f64> {
    let reciprocal = real_basis(target)?;
    let g = reciprocal * Vector2::new(index[0] as f64, index[1] as f64);
    let (mut re, mut im) = (0.0, 0.0);
    for (j, site) in lattice.motif().iter().enumerate() {
        let phase = 2.0 * std::f64::consts::PI * g.dot(&lattice.site_position(j));
        re += site.relative_height * phase.cos();
        im += site.relative_height * phase.sin();
    }
    let width = lattice
        .feature_appearance()
        .width_fraction
        .unwrap_or(DEFAULT_WIDTH_FRACTION)
        * lattice.nearest_neighbour_distance();
    let form = (-2.0 * std::f64::consts::PI.powi(2) * width.powi(2) * g.norm_squared()).exp();
    Some(re.hypot(im) * form)
}

#[cfg(test)]
mod tests {
    use super::*;
    use dhct_lattice::{Hexagonal, Kagome, PlaneGroup};

    fn basis(lattice: &dyn Lattice) -> Matrix2<f64> {
        let [a1, a2] = lattice.translation_cell();
        Matrix2::from_columns(&[a1, a2])
    }

    #[test]
    fn kagome_predicts_its_second_order_reflection_strong_a_plain_lattice_does_not() {
        let kagome = Kagome::new(6.4e-10).unwrap();
        let k = |h| amplitude(&kagome, &basis(&kagome), h).unwrap();
        assert!(k([2, 0]) > 0.5 * k([1, 0]), "{} {}", k([2, 0]), k([1, 0]));
        let plain = Hexagonal::new("hexagonal", 6.4e-10, PlaneGroup::P6mm).unwrap();
        let p = |h| amplitude(&plain, &basis(&plain), h).unwrap();
        assert!(p([2, 0]) < 0.1 * p([1, 0]));
    }
}
