//! Lattices for dhct: what a perfect surface looks like, so that its distortion can be
//! measured against it.
//!
//! The [`Lattice`] trait gives the primitive vectors (metres), the motif (imaged features per
//! cell), the plane group, and — derived from those by default — the nearest-neighbour
//! vectors of every motif site, the neighbour-shell distances used to fit a radial
//! distribution function, and how local distortion is measured (ellipse fit for ≥ 5
//! equidistant neighbours, local affine map otherwise).
//!
//! Built in, by name in [`catalogue::CATALOGUE`] (docs/lattices.md): graphite's imaged
//! atoms (a = 2.46 Å), honeycomb (graphene, both sublattices), hexagonal, the (√3×√3)R30°
//! alkanethiol SAM on Au(111) (a = 4.99 Å), Si(111)-7×7, square, rectangular, centred
//! rectangular, an oblique two-site cell and kagome (types [`Hexagonal`], [`Honeycomb`],
//! [`Square`], [`Rectangular`], [`CentredRectangular`], [`Oblique`], [`Kagome`] and the 7×7
//! preset). Any other lattice is a [`UserLattice`] read from TOML or JSON, without writing
//! Rust.
//!
//! Frames: lattice vectors are in the *sample frame*, x to the right and y down (the display
//! convention of `dhct-scan`), in metres, with `a1` along +x unless a lattice says otherwise.
//! Orientation in an image is a separate rotation applied by the caller.
//!
//! ```
//! use dhct_lattice::{Hexagonal, Lattice, LocalDistortionMethod};
//!
//! let graphite = Hexagonal::graphite();
//! assert_eq!(graphite.nearest_neighbours(0).len(), 6);
//! assert!((graphite.nearest_neighbour_distance() - 2.46e-10).abs() < 1e-15);
//! assert_eq!(graphite.local_distortion_method(), LocalDistortionMethod::Ellipse);
//! let shells = graphite.neighbour_shells(3); // a, √3 a, 2a
//! assert!((shells[1] / shells[0] - 3f64.sqrt()).abs() < 1e-9);
//! ```

#![warn(missing_docs)]

mod appearance;
pub mod catalogue;
mod error;
mod fit;
mod fit_refine;
mod fit_result;
mod metric;
mod motif;
mod neighbours;
mod plane_group;
mod precision;
mod presets;
mod rotation;
mod sites;
pub mod testing;
mod translations;
mod user;

pub use appearance::FeatureAppearance;
pub use catalogue::{CATALOGUE, CatalogueEntry, CatalogueLattice};
pub use error::LatticeError;
pub use fit::{
    AngularDistribution, LatticeFitError, LatticeFitOptions, angular_distribution,
    fit_calibrated_lattice, fit_lattice,
};
pub use fit_result::{IndexedPoint, LatticeFit};
pub use motif::MotifSite;
pub use neighbours::{DEFAULT_SHELL_TOLERANCE, MAX_NEIGHBOUR_WINDOW};
pub use plane_group::{PlaneGroup, UnknownPlaneGroup};
pub use presets::{
    CentredRectangular, Hexagonal, Honeycomb, Kagome, Oblique, Rectangular, SI111_7X7_A, Square,
};
pub use rotation::{
    direction_period, estimate_rotation, mean_bond_rotation, undirected_directions,
};
pub use sites::{LatticeSite, MAX_REGION_CELLS, lattice_sites};
pub use user::UserLattice;

use nalgebra::Vector2;
use serde::{Deserialize, Serialize};

/// How the local distortion at a feature is measured from its nearest neighbours.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum LocalDistortionMethod {
    /// Fit an ellipse through ≥ 5 neighbours that lie on a circle in the ideal lattice
    /// (the DHCT paper's eq. 6).
    Ellipse,
    /// Least-squares affine map from the ideal neighbour vectors to the observed ones.
    Affine,
}

/// A 2-D lattice with a motif: the internal standard DHCT measures distortion against.
///
/// Implementors give the primitive vectors, the motif, the plane group and (when it is not
/// the cell origin) the group's symmetry origin; everything else the stages use is derived
/// from those by the provided methods, and this trait is where it is stated. The stages
/// assume nothing beyond these items:
///
/// * motif sites may have different neighbour counts ([`Lattice::neighbour_count`]) and
///   their nearest neighbours may lie at several distances
///   ([`Lattice::nearest_neighbour_distances`]), not equally spaced in angle;
/// * neighbour shells are told apart by [`Lattice::neighbour_window`] (derived from the
///   gaps between shells, never a fixed ratio) and distances are one shell within
///   [`Lattice::shell_tolerance`];
/// * the plane group acts about [`Lattice::symmetry_origin`], not about motif site 0;
/// * the lattice's rotation in an image is found from [`Lattice::bond_directions`] modulo
///   [`Lattice::bond_direction_period`];
/// * the image repeats with [`Lattice::translation_cell`], which may be smaller than the
///   declared cell (a centred cell).
///
/// An implementor may override a derived item (e.g. to use only part of a shell) but must
/// keep its invariant. `tests/tests/lattice_contract.rs` and
/// `crates/unitcell/tests/motif_symmetry.rs` check every catalogue entry against them.
pub trait Lattice: std::fmt::Debug + Send + Sync {
    /// A short human-readable name, e.g. "graphite".
    fn name(&self) -> &str;

    /// Primitive vectors `[a1, a2]` in metres, sample frame (x right, y down); not
    /// parallel. With a motif of several sites this may be a conventional (e.g. centred)
    /// cell.
    fn primitive_vectors(&self) -> [Vector2<f64>; 2];

    /// The imaged features of one cell (at least one, none coinciding), in fractional
    /// coordinates of [`Lattice::primitive_vectors`].
    fn motif(&self) -> &[MotifSite];

    /// The plane (wallpaper) group of the ideal image, for symmetry averaging. Invariant:
    /// every operation of the group about [`Lattice::symmetry_origin`] maps the motif onto
    /// itself, sites onto sites of equal relative height, and the cell's metric onto itself.
    fn plane_group(&self) -> PlaneGroup;

    /// Where the plane group's symmetry elements sit, in fractional coordinates: the point
    /// about which [`Lattice::plane_group`]'s rotations and mirrors act (the origin of the
    /// group's standard setting). The default is the cell origin; graphene's honeycomb has
    /// its six-fold axis at the hexagon centre (2/3, 2/3), not on an atom.
    fn symmetry_origin(&self) -> [f64; 2] {
        [0.0, 0.0]
    }

    /// Relative tolerance within which two distances (or directions, in radians) are one:
    /// [`DEFAULT_SHELL_TOLERANCE`] (1e-6) for exact vectors, larger for a lattice file
    /// given with rounded numbers. Invariant: smaller than half the relative gap between
    /// any two distinct neighbour shells.
    fn shell_tolerance(&self) -> f64 {
        DEFAULT_SHELL_TOLERANCE
    }

    /// Position of motif site `site` in metres, relative to the cell origin.
    fn site_position(&self, site: usize) -> Vector2<f64> {
        let [a1, a2] = self.primitive_vectors();
        let [f1, f2] = self.motif()[site].fractional;
        a1 * f1 + a2 * f2
    }

    /// Vectors (metres) from motif site `site` to each of its nearest neighbours, sorted by
    /// angle from +x. Neighbours are all features (of any motif site) in the nearest shell
    /// (within [`Lattice::shell_tolerance`]), extended by the next shells until they span
    /// the plane, so that a local affine map is always determined. Different sites may
    /// have different counts and directions (kagome, a two-site oblique cell).
    fn nearest_neighbours(&self, site: usize) -> Vec<Vector2<f64>> {
        neighbours::nearest_neighbour_vectors(
            self.primitive_vectors(),
            self.motif(),
            site,
            self.shell_tolerance(),
        )
    }

    /// How many nearest neighbours motif site `site` has: `nearest_neighbours(site).len()`.
    fn neighbour_count(&self, site: usize) -> usize {
        self.nearest_neighbours(site).len()
    }

    /// The distinct neighbour counts of the motif's sites, ascending (one value when every
    /// site has as many neighbours).
    fn neighbour_counts(&self) -> Vec<usize> {
        let mut counts: Vec<usize> = (0..self.motif().len())
            .map(|s| self.neighbour_count(s))
            .collect();
        counts.sort_unstable();
        counts.dedup();
        counts
    }

    /// The nearest-neighbour distance (metres): the smallest feature-to-feature distance.
    fn nearest_neighbour_distance(&self) -> f64 {
        self.neighbour_shells(1)[0]
    }

    /// The distinct lengths (metres, ascending) of the nearest-neighbour vectors of every
    /// motif site: one for hexagonal, two for rectangular (a and b).
    fn nearest_neighbour_distances(&self) -> Vec<f64> {
        let lengths = (0..self.motif().len())
            .flat_map(|s| self.nearest_neighbours(s))
            .map(|v| v.norm())
            .collect();
        neighbours::cluster_distances(lengths, self.shell_tolerance())
    }

    /// The first `count` distinct neighbour distances (metres) over all motif sites,
    /// ascending (clustered within [`Lattice::shell_tolerance`]): the shells of the radial
    /// distribution function (a, √3a, 2a for hexagonal).
    fn neighbour_shells(&self, count: usize) -> Vec<f64> {
        neighbours::shell_distances(
            self.primitive_vectors(),
            self.motif(),
            count,
            self.shell_tolerance(),
        )
    }

    /// The relative half-width of the window around each nearest-neighbour distance within
    /// which an observed bond counts as a nearest-neighbour bond: half the relative gap to
    /// the nearest other shell, at most [`MAX_NEIGHBOUR_WINDOW`] (the DHCT paper's 35 %).
    /// Invariant: no other shell lies within the window.
    fn neighbour_window(&self) -> f64 {
        let nn = self.nearest_neighbour_distances();
        let last = nn.last().copied().unwrap_or(0.0);
        let others: Vec<f64> = self
            .neighbour_shells(nn.len() + 4)
            .into_iter()
            .filter(|s| {
                !nn.iter()
                    .any(|d| (s - d).abs() <= self.shell_tolerance() * d)
                    && *s <= 2.0 * last
            })
            .collect();
        neighbours::separating_window(&nn, &others)
    }

    /// The relative window around the first shell that keeps the second shell out (half
    /// their relative gap, at most [`MAX_NEIGHBOUR_WINDOW`]): the bonds that give the
    /// lattice's rotation ([`Lattice::bond_directions`]) are those within it.
    fn first_shell_window(&self) -> f64 {
        let shells = self.neighbour_shells(2);
        neighbours::separating_window(&shells[..1], &shells[1..])
    }

    /// The undirected directions (radians in `[0, π)`, ascending) of the first-shell bonds
    /// of every motif site, in the lattice's own frame: what the lattice's rotation in an
    /// image is measured against. Not necessarily equally spaced.
    fn bond_directions(&self) -> Vec<f64> {
        let first = self.nearest_neighbour_distance();
        let tolerance = self.shell_tolerance();
        let bonds = (0..self.motif().len())
            .flat_map(|s| self.nearest_neighbours(s))
            .filter(|v| (v.norm() - first).abs() <= tolerance * first)
            .map(|v| [v.x, v.y]);
        rotation::undirected_directions(bonds, direction_tolerance(tolerance))
    }

    /// The smallest rotation (radians, π/k) that maps [`Lattice::bond_directions`] onto
    /// themselves: the lattice's rotation in an image is known modulo it (π/3 hexagonal,
    /// π/2 square, π for an oblique or rectangular first shell).
    fn bond_direction_period(&self) -> f64 {
        rotation::direction_period(
            &self.bond_directions(),
            direction_tolerance(self.shell_tolerance()),
        )
    }

    /// How to measure local distortion: [`LocalDistortionMethod::Ellipse`] when every site
    /// has ≥ 5 nearest neighbours on one circle (enough to fix a conic), otherwise
    /// [`LocalDistortionMethod::Affine`].
    fn local_distortion_method(&self) -> LocalDistortionMethod {
        let tolerance = self.shell_tolerance();
        let all_on_circles = (0..self.motif().len()).all(|site| {
            let neighbours = self.nearest_neighbours(site);
            let first = neighbours.first().map_or(0.0, |v| v.norm());
            neighbours.len() >= 5
                && neighbours
                    .iter()
                    .all(|v| (v.norm() - first).abs() <= tolerance * first)
        });
        if all_on_circles {
            LocalDistortionMethod::Ellipse
        } else {
            LocalDistortionMethod::Affine
        }
    }

    /// The primitive vectors (metres) of the image's own translation lattice: the smallest
    /// cell that repeats the motif with its heights. Equal to
    /// [`Lattice::primitive_vectors`] unless the motif repeats inside the cell (a centred
    /// cell): what a Fourier transform of the image shows.
    fn translation_cell(&self) -> [Vector2<f64>; 2] {
        translations::translation_cell(
            self.primitive_vectors(),
            self.motif(),
            self.shell_tolerance().max(1e-9),
        )
    }

    /// How the tracked features look (bright or dark, how wide): the default is bright
    /// atoms with the DHCT kernel.
    fn feature_appearance(&self) -> FeatureAppearance {
        FeatureAppearance::default()
    }

    /// Area of the primitive cell, m².
    fn cell_area(&self) -> f64 {
        let [a1, a2] = self.primitive_vectors();
        (a1.x * a2.y - a1.y * a2.x).abs()
    }
}

/// The tolerance (radians) for two bond directions to be one, from a lattice's relative
/// shell tolerance: at least 1e-6, at most 1°.
fn direction_tolerance(shell_tolerance: f64) -> f64 {
    (10.0 * shell_tolerance).clamp(1e-6, 1f64.to_radians())
}
