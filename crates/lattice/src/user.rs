//! Lattices defined in a TOML or JSON file, without writing Rust.

use std::path::Path;

use nalgebra::Vector2;
use serde::{Deserialize, Serialize};

use crate::{Lattice, LatticeError, MotifSite, PlaneGroup};

/// A lattice read from a file. Example (TOML):
///
/// ```toml
/// name = "Si(111)-7x7 corner holes"
/// length_unit = "nm"          # m (default), nm, A (Å) or pm
/// a1 = [2.688, 0.0]
/// a2 = [1.344, 2.328]
/// plane_group = "p6mm"
///
/// [[motif]]
/// fractional = [0.0, 0.0]     # f1, f2 in units of a1, a2
/// label = "corner hole"
/// ```
///
/// ```
/// use dhct_lattice::{Lattice, UserLattice};
/// let text = "name = 'c(2x2)'\nlength_unit = 'A'\na1 = [3.0, 0.0]\na2 = [0.0, 3.0]\n\
///             plane_group = 'p4mm'\n[[motif]]\nfractional = [0.0, 0.0]\n\
///             [[motif]]\nfractional = [0.5, 0.5]\n";
/// let lattice = UserLattice::from_toml(text).unwrap();
/// assert_eq!(lattice.nearest_neighbours(0).len(), 4);
/// assert!((lattice.nearest_neighbour_distance() - 3e-10 / 2f64.sqrt()).abs() < 1e-16);
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "UserLatticeFile", into = "UserLatticeFile")]
pub struct UserLattice {
    name: String,
    vectors: [Vector2<f64>; 2],
    plane_group: PlaneGroup,
    motif: Vec<MotifSite>,
}

/// The file layout of a [`UserLattice`].
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct UserLatticeFile {
    name: String,
    #[serde(default = "metres")]
    length_unit: String,
    a1: [f64; 2],
    a2: [f64; 2],
    #[serde(default = "oblique")]
    plane_group: PlaneGroup,
    motif: Vec<MotifSite>,
}

fn metres() -> String {
    "m".into()
}

fn oblique() -> PlaneGroup {
    PlaneGroup::P1
}

fn unit_factor(unit: &str) -> Result<f64, LatticeError> {
    match unit.trim() {
        "m" => Ok(1.0),
        "nm" => Ok(1e-9),
        "A" | "Å" | "angstrom" => Ok(1e-10),
        "pm" => Ok(1e-12),
        other => Err(LatticeError::UnknownUnit(other.to_string())),
    }
}

impl UserLattice {
    /// Builds and validates a lattice from primitive vectors (metres), motif and plane group.
    pub fn new(
        name: impl Into<String>,
        a1: Vector2<f64>,
        a2: Vector2<f64>,
        plane_group: PlaneGroup,
        motif: Vec<MotifSite>,
    ) -> Result<UserLattice, LatticeError> {
        let finite = |v: Vector2<f64>| v.x.is_finite() && v.y.is_finite();
        let cross = a1.x * a2.y - a1.y * a2.x;
        if !finite(a1) || !finite(a2) || cross.abs() <= 1e-9 * a1.norm() * a2.norm() {
            return Err(LatticeError::Degenerate {
                a1: [a1.x, a1.y],
                a2: [a2.x, a2.y],
            });
        }
        if motif.is_empty() {
            return Err(LatticeError::EmptyMotif);
        }
        for (index, site) in motif.iter().enumerate() {
            if !site.fractional.iter().all(|f| f.is_finite()) {
                return Err(LatticeError::BadSite {
                    index,
                    position: site.fractional,
                });
            }
        }
        // Two sites that differ by a lattice vector are the same feature.
        for first in 0..motif.len() {
            for second in first + 1..motif.len() {
                let [p, q] = [motif[first].fractional, motif[second].fractional];
                let wrapped = |d: f64| (d - d.round()).abs() < 1e-9;
                if wrapped(p[0] - q[0]) && wrapped(p[1] - q[1]) {
                    return Err(LatticeError::CoincidentSites { first, second });
                }
            }
        }
        Ok(UserLattice {
            name: name.into(),
            vectors: [a1, a2],
            plane_group,
            motif,
        })
    }

    /// Parses the TOML layout documented on [`UserLattice`].
    pub fn from_toml(text: &str) -> Result<UserLattice, LatticeError> {
        toml::from_str(text).map_err(|e| LatticeError::Parse(e.to_string()))
    }

    /// Parses the same layout as JSON.
    pub fn from_json(text: &str) -> Result<UserLattice, LatticeError> {
        serde_json::from_str(text).map_err(|e| LatticeError::Parse(e.to_string()))
    }

    /// Reads a `.toml` or `.json` file (JSON when the content starts with `{`).
    pub fn from_path(path: &Path) -> Result<UserLattice, LatticeError> {
        let text = std::fs::read_to_string(path).map_err(|source| LatticeError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        if text.trim_start().starts_with('{') {
            Self::from_json(&text)
        } else {
            Self::from_toml(&text)
        }
    }
}

impl TryFrom<UserLatticeFile> for UserLattice {
    type Error = LatticeError;
    fn try_from(file: UserLatticeFile) -> Result<Self, Self::Error> {
        let factor = unit_factor(&file.length_unit)?;
        let vector = |v: [f64; 2]| Vector2::new(v[0], v[1]) * factor;
        UserLattice::new(
            file.name,
            vector(file.a1),
            vector(file.a2),
            file.plane_group,
            file.motif,
        )
    }
}

impl From<UserLattice> for UserLatticeFile {
    fn from(lattice: UserLattice) -> Self {
        let [a1, a2] = lattice.vectors;
        UserLatticeFile {
            name: lattice.name,
            length_unit: metres(),
            a1: [a1.x, a1.y],
            a2: [a2.x, a2.y],
            plane_group: lattice.plane_group,
            motif: lattice.motif,
        }
    }
}

impl Lattice for UserLattice {
    fn name(&self) -> &str {
        &self.name
    }
    fn primitive_vectors(&self) -> [Vector2<f64>; 2] {
        self.vectors
    }
    fn motif(&self) -> &[MotifSite] {
        &self.motif
    }
    fn plane_group(&self) -> PlaneGroup {
        self.plane_group
    }
}
