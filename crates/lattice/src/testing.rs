//! The [`Lattice`] contract, checked rule by rule: [`check`] names the first rule a lattice
//! breaks, [`violations`] lists them all. Every catalogue entry passes (the test below);
//! a researcher's own type or lattice file is checked the same way (`dhct lattice check
//! FILE.toml`). The checks are cheap (no simulation): what the end-to-end contract test
//! (`tests/tests/lattice_contract.rs`) then shows on a simulated image rests on them.
//!
//! ```
//! use dhct_lattice::{CATALOGUE, testing};
//!
//! for entry in CATALOGUE {
//!     let lattice = entry.build(Some(3e-10)).unwrap();
//!     testing::check(lattice.as_ref()).unwrap();
//! }
//! ```

use nalgebra::{Matrix2, Vector2};
use serde::Serialize;
use thiserror::Error;

use crate::Lattice;
use crate::metric::{check_motif_symmetry, exact_cell};

/// Relative heights closer than this are one kind of site.
const HEIGHT_TOLERANCE: f64 = 1e-3;

/// How many neighbour shells the shell rules look at.
const SHELLS_CHECKED: usize = 8;

/// A rule of the [`Lattice`] contract that a lattice breaks, with the values that break it.
#[derive(Debug, Clone, PartialEq, Error, Serialize)]
#[serde(tag = "rule", rename_all = "snake_case")]
pub enum ContractViolation {
    /// `primitive_vectors`: finite, non-zero and not parallel.
    #[error(
        "the primitive vectors a1 = {a1:?} m and a2 = {a2:?} m are not finite, zero or parallel"
    )]
    Cell {
        /// a1, metres.
        a1: [f64; 2],
        /// a2, metres.
        a2: [f64; 2],
    },
    /// `motif`: at least one site, finite positions and heights, no two coinciding.
    #[error("motif: {0}")]
    Motif(String),
    /// `shell_tolerance`: finite, positive and below half the relative gap between any two
    /// distinct neighbour shells.
    #[error(
        "shells {near:.6e} m and {far:.6e} m are {gap:.2e} apart (relative), not more than \
         twice the shell tolerance {tolerance:.2e}: two shells would merge"
    )]
    ShellSeparation {
        /// The nearer shell, metres.
        near: f64,
        /// The farther shell, metres.
        far: f64,
        /// Their relative gap.
        gap: f64,
        /// The lattice's shell tolerance.
        tolerance: f64,
    },
    /// `nearest_neighbours`: every site's vectors span the plane, lead to lattice
    /// features, are sorted by angle from +x, and none is shorter than the
    /// nearest-neighbour distance.
    #[error("site {site}: its nearest-neighbour vectors {problem}")]
    Neighbours {
        /// The motif site.
        site: usize,
        /// What is wrong with them.
        problem: String,
    },
    /// `neighbour_window`: no other shell lies within the window around a
    /// nearest-neighbour distance.
    #[error(
        "the neighbour window ±{window:.3} around {distance:.6e} m holds the shell at \
         {shell:.6e} m: bonds of two shells would be taken as one"
    )]
    WindowHoldsShell {
        /// The window, relative half-width.
        window: f64,
        /// The nearest-neighbour distance, metres.
        distance: f64,
        /// The other shell inside it, metres.
        shell: f64,
    },
    /// `plane_group`: the cell has the metric the group needs.
    #[error("plane group {group}: {reason}")]
    Metric {
        /// The group declared.
        group: String,
        /// Why the cell does not fit it.
        reason: String,
    },
    /// `plane_group` about `symmetry_origin`: every operation maps the motif onto itself,
    /// sites onto sites of equal relative height.
    #[error("plane group {group} about {origin:?}: {reason}")]
    MotifSymmetry {
        /// The group declared.
        group: String,
        /// The symmetry origin declared (fractional).
        origin: [f64; 2],
        /// Which operation moves which site where.
        reason: String,
    },
    /// `translation_cell`: its vectors repeat the motif with its heights.
    #[error(
        "the translation cell vector {vector:?} m moves site {site} off every site of its height"
    )]
    TranslationCell {
        /// The vector, metres.
        vector: [f64; 2],
        /// The site moved.
        site: usize,
    },
    /// `bond_direction_period`: π/k for a whole k ≥ 1, mapping the bond directions onto
    /// themselves.
    #[error("the bond-direction period {period_rad:.6} rad {problem}")]
    BondPeriod {
        /// The period, radians.
        period_rad: f64,
        /// What is wrong with it.
        problem: String,
    },
    /// `feature_appearance`: widths and fractions in their ranges.
    #[error("feature appearance: {0}")]
    Appearance(String),
}

/// One rule of the contract: `Err` names how `lattice` breaks it.
type Rule = fn(&dyn Lattice) -> Result<(), ContractViolation>;

/// The first rule `lattice` breaks, or `Ok` when it keeps the whole contract. The rules are
/// checked in the order of [`ContractViolation`]; the later ones assume the earlier.
pub fn check(lattice: &dyn Lattice) -> Result<(), ContractViolation> {
    match violations(lattice).into_iter().next() {
        Some(v) => Err(v),
        None => Ok(()),
    }
}

/// Every rule `lattice` breaks (the cell and motif rules first; when those fail, the rules
/// that depend on them are not checked).
pub fn violations(lattice: &dyn Lattice) -> Vec<ContractViolation> {
    if let Err(v) = cell_rule(lattice).and_then(|()| motif_rule(lattice)) {
        return vec![v];
    }
    let rules: [Rule; 8] = [
        shell_rule,
        neighbour_rule,
        window_rule,
        metric_rule,
        symmetry_rule,
        translation_rule,
        bond_period_rule,
        appearance_rule,
    ];
    rules
        .iter()
        .filter_map(|rule| rule(lattice).err())
        .collect()
}

fn cell_rule(lattice: &dyn Lattice) -> Result<(), ContractViolation> {
    let [a1, a2] = lattice.primitive_vectors();
    let cross = a1.x * a2.y - a1.y * a2.x;
    let fine = a1.iter().chain(a2.iter()).all(|v| v.is_finite())
        && a1.norm() > 0.0
        && a2.norm() > 0.0
        && cross.abs() > 1e-6 * a1.norm() * a2.norm();
    fine.then_some(()).ok_or(ContractViolation::Cell {
        a1: [a1.x, a1.y],
        a2: [a2.x, a2.y],
    })
}

fn motif_rule(lattice: &dyn Lattice) -> Result<(), ContractViolation> {
    let motif = lattice.motif();
    if motif.is_empty() {
        return Err(ContractViolation::Motif("it has no site".into()));
    }
    for (i, site) in motif.iter().enumerate() {
        if !site.fractional.iter().all(|v| v.is_finite()) || !site.relative_height.is_finite() {
            return Err(ContractViolation::Motif(format!(
                "site {i} has a non-finite position {:?} or height {}",
                site.fractional, site.relative_height
            )));
        }
    }
    let basis = cell_matrix(lattice);
    let reach = 1e-6 * lattice.nearest_neighbour_distance().max(f64::MIN_POSITIVE);
    for i in 0..motif.len() {
        for j in i + 1..motif.len() {
            if wrapped_distance(&basis, motif[i].fractional, motif[j].fractional) <= reach {
                return Err(ContractViolation::Motif(format!(
                    "sites {i} and {j} coincide (modulo a lattice vector)"
                )));
            }
        }
    }
    Ok(())
}

fn shell_rule(lattice: &dyn Lattice) -> Result<(), ContractViolation> {
    let tolerance = lattice.shell_tolerance();
    if !(tolerance.is_finite() && tolerance > 0.0) {
        return Err(ContractViolation::ShellSeparation {
            near: f64::NAN,
            far: f64::NAN,
            gap: f64::NAN,
            tolerance,
        });
    }
    let shells = lattice.neighbour_shells(SHELLS_CHECKED);
    for pair in shells.windows(2) {
        let gap = (pair[1] - pair[0]) / pair[0];
        if gap <= 2.0 * tolerance {
            return Err(ContractViolation::ShellSeparation {
                near: pair[0],
                far: pair[1],
                gap,
                tolerance,
            });
        }
    }
    Ok(())
}

fn neighbour_rule(lattice: &dyn Lattice) -> Result<(), ContractViolation> {
    let nn = lattice.nearest_neighbour_distance();
    let tolerance = lattice.shell_tolerance();
    let basis = cell_matrix(lattice);
    let motif = lattice.motif();
    for site in 0..motif.len() {
        let fail = |problem: String| ContractViolation::Neighbours { site, problem };
        let vectors = lattice.nearest_neighbours(site);
        let spans = vectors.iter().enumerate().any(|(i, a)| {
            vectors[i + 1..]
                .iter()
                .any(|b| (a.x * b.y - a.y * b.x).abs() > 1e-6 * a.norm() * b.norm())
        });
        if !spans {
            return Err(fail(format!(
                "({}) do not span the plane: no local affine map is determined",
                vectors.len()
            )));
        }
        if let Some(short) = vectors.iter().find(|v| v.norm() < nn * (1.0 - tolerance)) {
            return Err(fail(format!(
                "include {:.6e} m, shorter than the nearest-neighbour distance {nn:.6e} m",
                short.norm()
            )));
        }
        let angles: Vec<f64> = vectors.iter().map(|v| v.y.atan2(v.x)).collect();
        if angles.windows(2).any(|w| w[1] < w[0]) {
            return Err(fail("are not sorted by angle from +x".into()));
        }
        let from = motif[site].fractional;
        let inverse = basis.try_inverse().unwrap_or_else(Matrix2::zeros);
        for v in &vectors {
            let to = inverse * v + Vector2::from(from);
            let lands = motif.iter().any(|other| {
                wrapped_distance(&basis, [to.x, to.y], other.fractional) <= tolerance * nn
            });
            if !lands {
                return Err(fail(format!(
                    "include {:?} m, which leads to no feature of the lattice",
                    [v.x, v.y]
                )));
            }
        }
    }
    Ok(())
}

fn window_rule(lattice: &dyn Lattice) -> Result<(), ContractViolation> {
    let window = lattice.neighbour_window();
    let tolerance = lattice.shell_tolerance();
    let distances = lattice.nearest_neighbour_distances();
    let shells = lattice.neighbour_shells(distances.len() + SHELLS_CHECKED);
    for &distance in &distances {
        for &shell in &shells {
            let own = distances.iter().any(|d| (shell - d).abs() <= tolerance * d);
            if !own && (shell - distance).abs() < window * distance {
                return Err(ContractViolation::WindowHoldsShell {
                    window,
                    distance,
                    shell,
                });
            }
        }
    }
    Ok(())
}

fn metric_rule(lattice: &dyn Lattice) -> Result<(), ContractViolation> {
    let [a1, a2] = lattice.primitive_vectors();
    let group = lattice.plane_group();
    match exact_cell(a1, a2, group, lattice.shell_tolerance().max(1e-9)) {
        Ok(_) => Ok(()),
        Err(e) => Err(ContractViolation::Metric {
            group: group.symbol().into(),
            reason: e.to_string(),
        }),
    }
}

fn symmetry_rule(lattice: &dyn Lattice) -> Result<(), ContractViolation> {
    let group = lattice.plane_group();
    let origin = lattice.symmetry_origin();
    let violation = |reason: String| ContractViolation::MotifSymmetry {
        group: group.symbol().into(),
        origin,
        reason,
    };
    if !origin.iter().all(|v| v.is_finite()) {
        return Err(violation("the origin is not finite".into()));
    }
    match check_motif_symmetry(
        lattice.primitive_vectors(),
        lattice.motif(),
        group,
        origin,
        lattice.shell_tolerance().max(1e-9),
    ) {
        Ok(()) => Ok(()),
        Err(e) => Err(violation(e.to_string())),
    }
}

fn translation_rule(lattice: &dyn Lattice) -> Result<(), ContractViolation> {
    let basis = cell_matrix(lattice);
    let inverse = basis.try_inverse().unwrap_or_else(Matrix2::zeros);
    let motif = lattice.motif();
    let reach = lattice.shell_tolerance().max(1e-9) * lattice.nearest_neighbour_distance();
    for t in lattice.translation_cell() {
        let shift = inverse * t;
        for (site, s) in motif.iter().enumerate() {
            let moved = [s.fractional[0] + shift.x, s.fractional[1] + shift.y];
            let lands = motif.iter().any(|other| {
                wrapped_distance(&basis, moved, other.fractional) <= reach
                    && (other.relative_height - s.relative_height).abs() <= HEIGHT_TOLERANCE
            });
            if !lands {
                return Err(ContractViolation::TranslationCell {
                    vector: [t.x, t.y],
                    site,
                });
            }
        }
    }
    Ok(())
}

fn bond_period_rule(lattice: &dyn Lattice) -> Result<(), ContractViolation> {
    let period = lattice.bond_direction_period();
    let pi = std::f64::consts::PI;
    let k = pi / period;
    if !(period.is_finite() && period > 0.0 && (k - k.round()).abs() < 1e-6 && k >= 1.0) {
        return Err(ContractViolation::BondPeriod {
            period_rad: period,
            problem: "is not π/k for a whole k ≥ 1".into(),
        });
    }
    let directions = lattice.bond_directions();
    let tolerance = 1e-6f64
        .max(lattice.shell_tolerance())
        .min(1f64.to_radians());
    let on_a_direction = |angle: f64| {
        directions.iter().any(|d| {
            let diff = (angle - d).rem_euclid(pi);
            diff <= tolerance || pi - diff <= tolerance
        })
    };
    match directions.iter().find(|&&d| !on_a_direction(d + period)) {
        Some(d) => Err(ContractViolation::BondPeriod {
            period_rad: period,
            problem: format!("turns the bond direction {d:.6} rad onto no bond direction"),
        }),
        None => Ok(()),
    }
}

fn appearance_rule(lattice: &dyn Lattice) -> Result<(), ContractViolation> {
    let a = lattice.feature_appearance();
    let in_range = |name: &str, v: Option<f64>, lo: f64, hi: f64| match v {
        Some(v) if !(v.is_finite() && v > lo && v <= hi) => Err(ContractViolation::Appearance(
            format!("{name} {v} is outside ({lo}, {hi}]"),
        )),
        _ => Ok(()),
    };
    in_range("width_fraction", a.width_fraction, 0.0, 1.0)?;
    in_range("fit_radius_fraction", a.fit_radius_fraction, 0.0, 1.0)?;
    if !(a.min_relative_height.is_finite() && (0.0..1.0).contains(&a.min_relative_height)) {
        return Err(ContractViolation::Appearance(format!(
            "min_relative_height {} is outside [0, 1)",
            a.min_relative_height
        )));
    }
    Ok(())
}

/// The primitive vectors as matrix columns.
fn cell_matrix(lattice: &dyn Lattice) -> Matrix2<f64> {
    let [a1, a2] = lattice.primitive_vectors();
    Matrix2::from_columns(&[a1, a2])
}

/// The distance (metres) between fractional positions `a` and `b`, modulo a lattice vector.
fn wrapped_distance(basis: &Matrix2<f64>, a: [f64; 2], b: [f64; 2]) -> f64 {
    let d = Vector2::new(a[0] - b[0], a[1] - b[1]).map(|v| v - v.round());
    (basis * d).norm()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{CATALOGUE, Hexagonal, MotifSite, PlaneGroup};

    #[test]
    fn every_catalogue_lattice_keeps_the_contract() {
        for entry in CATALOGUE {
            for nn in [None, Some(3e-10), Some(2.7e-9)] {
                let Ok(lattice) = entry.build(nn) else {
                    continue;
                };
                assert_eq!(violations(lattice.as_ref()), [], "{} at {nn:?}", entry.name);
            }
        }
    }

    /// A graphene-like two-site cell that declares p6mm about an atom (the six-fold axis
    /// is at the hexagon centre), and whose neighbour vectors are not sorted.
    #[derive(Debug)]
    struct Broken {
        motif: Vec<MotifSite>,
        unsorted: bool,
    }

    impl Lattice for Broken {
        fn name(&self) -> &str {
            "broken"
        }
        fn primitive_vectors(&self) -> [Vector2<f64>; 2] {
            Hexagonal::graphite().primitive_vectors()
        }
        fn motif(&self) -> &[MotifSite] {
            &self.motif
        }
        fn plane_group(&self) -> PlaneGroup {
            PlaneGroup::P6mm
        }
        fn nearest_neighbours(&self, site: usize) -> Vec<Vector2<f64>> {
            let mut v = crate::neighbours::nearest_neighbour_vectors(
                self.primitive_vectors(),
                &self.motif,
                site,
                self.shell_tolerance(),
            );
            if self.unsorted {
                v.reverse();
            }
            v
        }
    }

    #[test]
    fn a_broken_rule_is_named() {
        let honeycomb = vec![
            MotifSite::new(0.0, 0.0, "A"),
            MotifSite::new(1.0 / 3.0, 1.0 / 3.0, "B"),
        ];
        let about_an_atom = Broken {
            motif: honeycomb.clone(),
            unsorted: false,
        };
        let found = violations(&about_an_atom);
        assert!(
            matches!(found.as_slice(), [ContractViolation::MotifSymmetry { .. }]),
            "{found:?}"
        );
        let unsorted = Broken {
            motif: vec![MotifSite::new(0.0, 0.0, "A")],
            unsorted: true,
        };
        let error = check(&unsorted).unwrap_err();
        assert!(
            matches!(&error, ContractViolation::Neighbours { site: 0, problem } if problem.contains("sorted")),
            "{error}"
        );
    }
}
