//! Lattices for dhct: what a perfect surface looks like, so that its distortion can be
//! measured against it.
//!
//! The [`Lattice`] trait gives the primitive vectors (metres), the motif (imaged features per
//! cell), the plane group, and — derived from those by default — the nearest-neighbour
//! vectors of every motif site, the neighbour-shell distances used to fit a radial
//! distribution function, and how local distortion is measured (ellipse fit for ≥ 5
//! equidistant neighbours, local affine map otherwise).
//!
//! Built in: [`Hexagonal`] (graphite's imaged atoms, a = 2.46 Å; the (√3×√3)R30°
//! alkanethiol SAM on Au(111), a = 4.99 Å), [`Honeycomb`] (graphene, both sublattices),
//! [`Square`], [`Rectangular`]; any other lattice is a [`UserLattice`] read from TOML or
//! JSON, without writing Rust.
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

mod appearance;
pub mod catalogue;
mod error;
mod fit;
mod motif;
mod neighbours;
mod plane_group;
mod presets;
mod user;

pub use appearance::FeatureAppearance;
pub use catalogue::{CATALOGUE, CatalogueEntry, CatalogueLattice};
pub use error::LatticeError;
pub use fit::{
    AngularDistribution, IndexedPoint, LatticeFit, LatticeFitError, LatticeFitOptions,
    angular_distribution, fit_lattice,
};
pub use motif::MotifSite;
pub use neighbours::{LatticeSite, lattice_sites, mean_bond_rotation};
pub use plane_group::PlaneGroup;
pub use presets::{Hexagonal, Honeycomb, Rectangular, SI111_7X7_A, Square};
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
/// Implementors give the primitive vectors, motif and plane group; the neighbour
/// geometry is derived from them by the provided methods, which an implementor may override
/// (e.g. to use only part of a shell).
pub trait Lattice: std::fmt::Debug + Send + Sync {
    /// A short human-readable name, e.g. "graphite".
    fn name(&self) -> &str;

    /// Primitive vectors `[a1, a2]` in metres, sample frame (x right, y down).
    fn primitive_vectors(&self) -> [Vector2<f64>; 2];

    /// The imaged features of one cell (at least one), in fractional coordinates.
    fn motif(&self) -> &[MotifSite];

    /// The plane (wallpaper) group of the ideal image, for symmetry averaging.
    fn plane_group(&self) -> PlaneGroup;

    /// Position of motif site `site` in metres, relative to the cell origin.
    fn site_position(&self, site: usize) -> Vector2<f64> {
        let [a1, a2] = self.primitive_vectors();
        let [f1, f2] = self.motif()[site].fractional;
        a1 * f1 + a2 * f2
    }

    /// Vectors (metres) from motif site `site` to each of its nearest neighbours, sorted by
    /// angle from +x. Neighbours are all features (of any motif site) at the smallest
    /// distance (relative tolerance 1e-6), extended by the next shells until they span the
    /// plane, so that a local affine map is always determined.
    fn nearest_neighbours(&self, site: usize) -> Vec<Vector2<f64>> {
        neighbours::nearest_neighbour_vectors(self.primitive_vectors(), self.motif(), site)
    }

    /// The nearest-neighbour distance (metres): the smallest feature-to-feature distance.
    fn nearest_neighbour_distance(&self) -> f64 {
        self.neighbour_shells(1)[0]
    }

    /// The first `count` distinct neighbour distances (metres) over all motif sites,
    /// ascending: the shells of the radial distribution function (a, √3a, 2a for hexagonal).
    fn neighbour_shells(&self, count: usize) -> Vec<f64> {
        neighbours::shell_distances(self.primitive_vectors(), self.motif(), count)
    }

    /// How to measure local distortion: [`LocalDistortionMethod::Ellipse`] when every site
    /// has ≥ 5 equidistant nearest neighbours (enough to fix a conic), otherwise
    /// [`LocalDistortionMethod::Affine`].
    fn local_distortion_method(&self) -> LocalDistortionMethod {
        let all_on_circles = (0..self.motif().len()).all(|site| {
            let neighbours = self.nearest_neighbours(site);
            let first = neighbours.first().map_or(0.0, |v| v.norm());
            neighbours.len() >= 5
                && neighbours
                    .iter()
                    .all(|v| (v.norm() - first).abs() <= 1e-6 * first)
        });
        if all_on_circles {
            LocalDistortionMethod::Ellipse
        } else {
            LocalDistortionMethod::Affine
        }
    }

    /// Where the plane group's symmetry elements sit, in fractional coordinates: the point
    /// about which [`Lattice::plane_group`]'s rotations and mirrors act (the origin of the
    /// group's standard setting). Contract: every operation of the group about this point
    /// maps the motif onto itself (sites of equal relative height onto each other). The
    /// default is the cell origin; graphene's honeycomb has its six-fold axis at the hexagon
    /// centre (2/3, 2/3), not on an atom.
    fn symmetry_origin(&self) -> [f64; 2] {
        [0.0, 0.0]
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
