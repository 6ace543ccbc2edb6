//! Lattices defined in a TOML or JSON file, without writing Rust.

use std::path::Path;

use nalgebra::Vector2;
use serde::{Deserialize, Serialize};

use crate::metric::{check_motif_symmetry, exact_cell};
use crate::neighbours::neighbour_search_work;
use crate::precision::file_tolerance;
use crate::{Lattice, LatticeError, MotifSite, PlaneGroup};

/// Most motif sites of a user lattice.
pub const MAX_MOTIF_SITES: usize = 256;

/// Largest |fractional coordinate| of a motif site, in cells.
pub const MAX_FRACTIONAL: f64 = 1000.0;

/// Smallest angle between the primitive vectors, degrees (and 180° minus it the largest).
pub const MIN_VECTOR_ANGLE_DEG: f64 = 10.0;

/// Largest ratio of the primitive vectors' lengths.
pub const MAX_ASPECT_RATIO: f64 = 20.0;

/// Accepted primitive-vector lengths, metres: 0.1 pm to 10 µm.
pub const VECTOR_LENGTH_M: std::ops::RangeInclusive<f64> = 1e-13..=1e-5;

/// Most site comparisons the nearest-neighbour search of a user lattice may need (about a
/// second of work).
pub const MAX_NEIGHBOUR_WORK: f64 = 5e7;

/// Largest lattice file read, bytes.
pub const MAX_FILE_BYTES: u64 = 1 << 20;

/// A lattice read from a file. Its numbers may be rounded (e.g. 4-decimal vectors): the
/// tolerance within which distances are one shell follows from the finest digit given
/// (see [`UserLattice::new`]), and the cell is made exact for the plane group when it
/// agrees with it within that tolerance. Example (TOML):
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
    symmetry_origin: [f64; 2],
    tolerance: f64,
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
    /// Where the plane group's symmetry elements sit, fractional (default the origin).
    #[serde(default)]
    symmetry_origin: [f64; 2],
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
    /// Builds and validates a lattice from primitive vectors (metres), motif and plane group
    /// (about the cell origin; see [`UserLattice::with_symmetry_origin`]).
    ///
    /// Refused, each with an error naming the value: non-finite numbers; vectors shorter
    /// than 0.1 pm or longer than 10 µm, less than 10° from parallel, or differing in length
    /// by more than a factor 20; an empty motif or one of more than 256 sites; a site beyond
    /// ±1000 cells; a non-finite relative height; coincident sites; lattices whose
    /// neighbour search would need more than 5·10^7 site comparisons (about a second); a
    /// cell without the plane group's metric (e.g. p6mm with |a1| ≠ |a2|) and a motif the
    /// group's rotation (or centring) does not map onto itself.
    ///
    /// Tolerance: the numbers may be rounded; the relative tolerance is four times the
    /// rounding error of the finest digit given (4-decimal vectors of 2.46 Å: 8·10^-5),
    /// between 1e-6 and 1e-3 ([`Lattice::shell_tolerance`]).
    pub fn new(
        name: impl Into<String>,
        a1: Vector2<f64>,
        a2: Vector2<f64>,
        plane_group: PlaneGroup,
        motif: Vec<MotifSite>,
    ) -> Result<UserLattice, LatticeError> {
        let fractions: Vec<[f64; 2]> = motif.iter().map(|s| s.fractional).collect();
        let tolerance = file_tolerance([[a1.x, a1.y], [a2.x, a2.y]], &fractions);
        Self::build(
            name.into(),
            [a1, a2],
            plane_group,
            motif,
            [0.0, 0.0],
            tolerance,
        )
    }

    /// Validates everything (see [`UserLattice::new`]) with the symmetry origin `origin`
    /// and the relative `tolerance`.
    fn build(
        name: String,
        [a1, a2]: [Vector2<f64>; 2],
        plane_group: PlaneGroup,
        motif: Vec<MotifSite>,
        origin: [f64; 2],
        tolerance: f64,
    ) -> Result<UserLattice, LatticeError> {
        check_vectors(a1, a2)?;
        check_motif(&motif)?;
        check_distinct_sites(&motif)?;
        let work = neighbour_search_work([a1, a2], &motif);
        if work.is_nan() || work > MAX_NEIGHBOUR_WORK {
            return Err(LatticeError::TooComplex {
                work,
                max: MAX_NEIGHBOUR_WORK,
            });
        }
        if !origin.iter().all(|v| v.is_finite()) {
            return Err(LatticeError::Parse(format!(
                "symmetry_origin must be finite fractional coordinates, got {origin:?}"
            )));
        }
        let origin = origin.map(|v| v.rem_euclid(1.0));
        let vectors = exact_cell(a1, a2, plane_group, tolerance)?;
        check_motif_symmetry(vectors, &motif, plane_group, origin, tolerance)?;
        Ok(UserLattice {
            name,
            vectors,
            plane_group,
            motif,
            symmetry_origin: origin,
            tolerance,
        })
    }

    /// This lattice with its plane group's symmetry elements at `origin` (fractional
    /// coordinates, each finite; see [`Lattice::symmetry_origin`]), checked again.
    pub fn with_symmetry_origin(self, origin: [f64; 2]) -> Result<UserLattice, LatticeError> {
        Self::build(
            self.name,
            self.vectors,
            self.plane_group,
            self.motif,
            origin,
            self.tolerance,
        )
    }

    /// Parses the TOML layout documented on [`UserLattice`].
    pub fn from_toml(text: &str) -> Result<UserLattice, LatticeError> {
        toml::from_str(text).map_err(|e| LatticeError::Parse(e.to_string()))
    }

    /// Parses the same layout as JSON.
    pub fn from_json(text: &str) -> Result<UserLattice, LatticeError> {
        serde_json::from_str(text).map_err(|e| LatticeError::Parse(e.to_string()))
    }

    /// Reads a `.toml` or `.json` file (JSON when the content starts with `{`). Only a
    /// regular file of at most 1 MiB is read: a FIFO, device or directory is
    /// refused before it is opened, so nothing blocks.
    pub fn from_path(path: &Path) -> Result<UserLattice, LatticeError> {
        let text = read_lattice_file(path)?;
        if text.trim_start().starts_with('{') {
            Self::from_json(&text)
        } else {
            Self::from_toml(&text)
        }
    }
}

/// Two sites that differ by a lattice vector are the same feature.
fn check_distinct_sites(motif: &[MotifSite]) -> Result<(), LatticeError> {
    for first in 0..motif.len() {
        for second in first + 1..motif.len() {
            let [p, q] = [motif[first].fractional, motif[second].fractional];
            let wrapped = |d: f64| (d - d.round()).abs() < 1e-9;
            if wrapped(p[0] - q[0]) && wrapped(p[1] - q[1]) {
                return Err(LatticeError::CoincidentSites { first, second });
            }
        }
    }
    Ok(())
}

/// Checks the primitive vectors (see [`UserLattice::new`]).
fn check_vectors(a1: Vector2<f64>, a2: Vector2<f64>) -> Result<(), LatticeError> {
    let finite = |v: Vector2<f64>| v.x.is_finite() && v.y.is_finite();
    let cross = a1.x * a2.y - a1.y * a2.x;
    if !finite(a1) || !finite(a2) || cross.abs() <= 1e-9 * a1.norm() * a2.norm() {
        return Err(LatticeError::Degenerate {
            a1: [a1.x, a1.y],
            a2: [a2.x, a2.y],
        });
    }
    for (what, v) in [("|a1|", a1), ("|a2|", a2)] {
        if !VECTOR_LENGTH_M.contains(&v.norm()) {
            return Err(LatticeError::BadLength {
                what,
                value: v.norm(),
            });
        }
    }
    let angle_deg = cross.abs().atan2(a1.dot(&a2)).to_degrees();
    if !(MIN_VECTOR_ANGLE_DEG..=180.0 - MIN_VECTOR_ANGLE_DEG).contains(&angle_deg) {
        return Err(LatticeError::NearlyParallel {
            angle_deg,
            min_deg: MIN_VECTOR_ANGLE_DEG,
        });
    }
    let ratio = a1.norm().max(a2.norm()) / a1.norm().min(a2.norm());
    if ratio > MAX_ASPECT_RATIO {
        return Err(LatticeError::AspectRatio {
            ratio,
            max: MAX_ASPECT_RATIO,
        });
    }
    Ok(())
}

/// Checks the motif's size and every site's numbers (see [`UserLattice::new`]).
fn check_motif(motif: &[MotifSite]) -> Result<(), LatticeError> {
    if motif.is_empty() {
        return Err(LatticeError::EmptyMotif);
    }
    if motif.len() > MAX_MOTIF_SITES {
        return Err(LatticeError::TooManySites {
            count: motif.len(),
            max: MAX_MOTIF_SITES,
        });
    }
    for (index, site) in motif.iter().enumerate() {
        if !site.fractional.iter().all(|f| f.is_finite()) {
            return Err(LatticeError::BadSite {
                index,
                position: site.fractional,
            });
        }
        if site.fractional.iter().any(|f| f.abs() > MAX_FRACTIONAL) {
            return Err(LatticeError::FractionalOutOfRange {
                index,
                position: site.fractional,
                max: MAX_FRACTIONAL,
            });
        }
        if !site.relative_height.is_finite() {
            return Err(LatticeError::BadHeight {
                index,
                value: site.relative_height,
            });
        }
    }
    Ok(())
}

/// The text of a lattice file: only a regular file (checked before opening) of at most
/// [`MAX_FILE_BYTES`].
fn read_lattice_file(path: &Path) -> Result<String, LatticeError> {
    use std::io::Read;
    let io = |source| LatticeError::Io {
        path: path.to_path_buf(),
        source,
    };
    let metadata = std::fs::metadata(path).map_err(io)?;
    if !metadata.is_file() {
        let kind = file_kind(&metadata);
        return Err(LatticeError::NotRegularFile {
            path: path.to_path_buf(),
            kind,
        });
    }
    let too_large = |bytes| LatticeError::FileTooLarge {
        path: path.to_path_buf(),
        bytes,
        max: MAX_FILE_BYTES,
    };
    if metadata.len() > MAX_FILE_BYTES {
        return Err(too_large(metadata.len()));
    }
    let mut text = String::new();
    std::fs::File::open(path)
        .map_err(io)?
        .take(MAX_FILE_BYTES + 1)
        .read_to_string(&mut text)
        .map_err(io)?;
    if text.len() as u64 > MAX_FILE_BYTES {
        return Err(too_large(text.len() as u64));
    }
    Ok(text)
}

/// What a non-regular file is, for error messages.
fn file_kind(metadata: &std::fs::Metadata) -> &'static str {
    let kind = metadata.file_type();
    if kind.is_dir() {
        return "a directory";
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if kind.is_fifo() {
            return "a named pipe (FIFO)";
        }
        if kind.is_char_device() || kind.is_block_device() {
            return "a device";
        }
    }
    "not a regular file"
}

impl TryFrom<UserLatticeFile> for UserLattice {
    type Error = LatticeError;
    fn try_from(file: UserLatticeFile) -> Result<Self, Self::Error> {
        let factor = unit_factor(&file.length_unit)?;
        let vector = |v: [f64; 2]| Vector2::new(v[0], v[1]) * factor;
        // The precision is that of the numbers as written, before the unit conversion.
        let fractions: Vec<[f64; 2]> = file.motif.iter().map(|s| s.fractional).collect();
        let tolerance = file_tolerance([file.a1, file.a2], &fractions);
        UserLattice::build(
            file.name,
            [vector(file.a1), vector(file.a2)],
            file.plane_group,
            file.motif,
            file.symmetry_origin,
            tolerance,
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
            symmetry_origin: lattice.symmetry_origin,
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
    fn symmetry_origin(&self) -> [f64; 2] {
        self.symmetry_origin
    }
    fn shell_tolerance(&self) -> f64 {
        self.tolerance
    }
}
