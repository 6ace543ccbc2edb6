//! The built-in lattices.

use nalgebra::Vector2;
use serde::{Deserialize, Serialize};

use crate::{FeatureAppearance, Lattice, LatticeError, MotifSite, PlaneGroup};

fn check_length(what: &'static str, value: f64) -> Result<(), LatticeError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(LatticeError::BadLength { what, value })
    }
}

fn hexagonal_vectors(a: f64) -> [Vector2<f64>; 2] {
    [
        Vector2::new(a, 0.0),
        Vector2::new(0.5 * a, 0.5 * 3f64.sqrt() * a),
    ]
}

/// The Si(111)-7×7 cell constant, metres (7 × 3.840 Å).
pub const SI111_7X7_A: f64 = 2.688e-9;

/// A hexagonal (trigonal) lattice with one imaged feature per cell and 6 nearest neighbours
/// at distance `a`: graphite's imaged atoms, close-packed adsorbates, SAMs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Hexagonal {
    name: String,
    a: f64,
    plane_group: PlaneGroup,
    motif: Vec<MotifSite>,
    #[serde(default)]
    appearance: FeatureAppearance,
}

impl Hexagonal {
    /// A hexagonal lattice with constant `a` (metres) and the given plane group.
    pub fn new(
        name: impl Into<String>,
        a: f64,
        plane_group: PlaneGroup,
    ) -> Result<Hexagonal, LatticeError> {
        check_length("a", a)?;
        Ok(Hexagonal {
            name: name.into(),
            a,
            plane_group,
            motif: vec![MotifSite::new(0.0, 0.0, "")],
            appearance: FeatureAppearance::default(),
        })
    }

    /// HOPG as STM images it: one bright atom (the β site) per cell, a = 2.46 Å, plane
    /// group p3m1 (the AB stacking makes the image three-fold, not six-fold).
    pub fn graphite() -> Hexagonal {
        Hexagonal {
            name: "graphite".into(),
            a: 2.46e-10,
            plane_group: PlaneGroup::P3m1,
            motif: vec![MotifSite::new(0.0, 0.0, "C")],
            appearance: FeatureAppearance::default(),
        }
    }

    /// The (√3×√3)R30° alkanethiol SAM on Au(111): one molecule per cell, a = 4.99 Å.
    pub fn sam_sqrt3() -> Hexagonal {
        Hexagonal {
            name: "sam-sqrt3".into(),
            a: 4.99e-10,
            plane_group: PlaneGroup::P6mm,
            motif: vec![MotifSite::new(0.0, 0.0, "S")],
            appearance: FeatureAppearance::default(),
        }
    }

    /// The Si(111)-7×7 reconstruction tracked by its corner holes: one dark, narrow feature
    /// per cell (σ ≈ a/10; minima shallower than 0.6 of the deepest are dropped), a = 2.688
    /// nm (7 × 3.840 Å), plane group p31m. The 12 adatoms and
    /// the dimer rows inside the cell are not tracked, so the neighbour shells (a, √3a, 2a)
    /// cannot lock onto intra-cell distances.
    pub fn si111_7x7() -> Hexagonal {
        Hexagonal {
            name: "si111-7x7".into(),
            a: SI111_7X7_A,
            plane_group: PlaneGroup::P31m,
            motif: vec![MotifSite::new(0.0, 0.0, "corner hole")],
            appearance: FeatureAppearance {
                dark: true,
                width_fraction: Some(0.1),
                // Corner holes are the deepest minima, about twice as deep as those
                // between the adatoms.
                min_relative_height: 0.6,
                // 2.5 σ of the hole; the nearest adatoms sit at about 0.36 a.
                fit_radius_fraction: Some(0.25),
            },
        }
    }

    /// This lattice with another constant `a` (metres), everything else kept.
    pub fn with_constant(&self, a: f64) -> Result<Hexagonal, LatticeError> {
        check_length("a", a)?;
        Ok(Hexagonal { a, ..self.clone() })
    }

    /// The lattice constant, metres.
    pub fn a(&self) -> f64 {
        self.a
    }
}

impl Lattice for Hexagonal {
    fn name(&self) -> &str {
        &self.name
    }
    fn primitive_vectors(&self) -> [Vector2<f64>; 2] {
        hexagonal_vectors(self.a)
    }
    fn motif(&self) -> &[MotifSite] {
        &self.motif
    }
    fn plane_group(&self) -> PlaneGroup {
        self.plane_group
    }
    fn feature_appearance(&self) -> FeatureAppearance {
        self.appearance
    }
}

/// The honeycomb lattice of graphene with both sublattices imaged: two sites per hexagonal
/// cell of constant `a`, 3 nearest neighbours at `a/√3`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Honeycomb {
    a: f64,
    motif: Vec<MotifSite>,
}

impl Honeycomb {
    /// A honeycomb lattice with cell constant `a` (metres).
    pub fn new(a: f64) -> Result<Honeycomb, LatticeError> {
        check_length("a", a)?;
        Ok(Honeycomb {
            a,
            motif: vec![
                MotifSite::new(0.0, 0.0, "A"),
                MotifSite::new(1.0 / 3.0, 1.0 / 3.0, "B"),
            ],
        })
    }

    /// Graphene: a = 2.46 Å, C–C distance 1.42 Å.
    pub fn graphene() -> Honeycomb {
        Honeycomb::new(2.46e-10).expect("2.46 Å is a valid lattice constant")
    }
}

impl Lattice for Honeycomb {
    fn name(&self) -> &str {
        "honeycomb"
    }
    /// The hexagon centre: p6mm holds about it, not about an atom (about an atom the
    /// honeycomb is only p3m1).
    fn symmetry_origin(&self) -> [f64; 2] {
        [2.0 / 3.0, 2.0 / 3.0]
    }
    fn primitive_vectors(&self) -> [Vector2<f64>; 2] {
        hexagonal_vectors(self.a)
    }
    fn motif(&self) -> &[MotifSite] {
        &self.motif
    }
    fn plane_group(&self) -> PlaneGroup {
        PlaneGroup::P6mm
    }
}

/// A square lattice, one feature per cell, 4 nearest neighbours.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Square {
    a: f64,
    motif: Vec<MotifSite>,
}

impl Square {
    /// A square lattice with constant `a` (metres).
    pub fn new(a: f64) -> Result<Square, LatticeError> {
        check_length("a", a)?;
        Ok(Square {
            a,
            motif: vec![MotifSite::new(0.0, 0.0, "")],
        })
    }
}

impl Lattice for Square {
    fn name(&self) -> &str {
        "square"
    }
    fn primitive_vectors(&self) -> [Vector2<f64>; 2] {
        [Vector2::new(self.a, 0.0), Vector2::new(0.0, self.a)]
    }
    fn motif(&self) -> &[MotifSite] {
        &self.motif
    }
    fn plane_group(&self) -> PlaneGroup {
        PlaneGroup::P4mm
    }
}

/// A rectangular lattice `a x b`, one feature per cell; 2 nearest neighbours along the
/// shorter side (4 when `a = b`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Rectangular {
    a: f64,
    b: f64,
    motif: Vec<MotifSite>,
}

impl Rectangular {
    /// A rectangular lattice with sides `a` along x and `b` along y (metres).
    pub fn new(a: f64, b: f64) -> Result<Rectangular, LatticeError> {
        check_length("a", a)?;
        check_length("b", b)?;
        Ok(Rectangular {
            a,
            b,
            motif: vec![MotifSite::new(0.0, 0.0, "")],
        })
    }
}

impl Lattice for Rectangular {
    fn name(&self) -> &str {
        "rectangular"
    }
    fn primitive_vectors(&self) -> [Vector2<f64>; 2] {
        [Vector2::new(self.a, 0.0), Vector2::new(0.0, self.b)]
    }
    fn motif(&self) -> &[MotifSite] {
        &self.motif
    }
    fn plane_group(&self) -> PlaneGroup {
        PlaneGroup::P2mm
    }
}

/// A centred rectangular lattice given by its conventional cell `a × b` with sites at the
/// corner and the centre (plane group c2mm); its image repeats with the rhombic primitive
/// cell ([`Lattice::translation_cell`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CentredRectangular {
    a: f64,
    b: f64,
    motif: Vec<MotifSite>,
}

impl CentredRectangular {
    /// A centred rectangular lattice with conventional sides `a` along x and `b` along y
    /// (metres).
    pub fn new(a: f64, b: f64) -> Result<CentredRectangular, LatticeError> {
        check_length("a", a)?;
        check_length("b", b)?;
        Ok(CentredRectangular {
            a,
            b,
            motif: vec![
                MotifSite::new(0.0, 0.0, "corner"),
                MotifSite::new(0.5, 0.5, "centre"),
            ],
        })
    }
}

impl Lattice for CentredRectangular {
    fn name(&self) -> &str {
        "centred-rectangular"
    }
    fn primitive_vectors(&self) -> [Vector2<f64>; 2] {
        [Vector2::new(self.a, 0.0), Vector2::new(0.0, self.b)]
    }
    fn motif(&self) -> &[MotifSite] {
        &self.motif
    }
    fn plane_group(&self) -> PlaneGroup {
        PlaneGroup::C2mm
    }
}

/// An oblique lattice with two sites of different heights, at the cell corner and the cell
/// centre (both two-fold centres, plane group p2): `a1 = a` along x, `a2` of length `b` at
/// `gamma` (radians) from `a1`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Oblique {
    a: f64,
    b: f64,
    gamma: f64,
    motif: Vec<MotifSite>,
}

impl Oblique {
    /// An oblique two-site lattice; `centre_height` is the centre site's height relative
    /// to the corner site's (finite, > 0).
    pub fn new(a: f64, b: f64, gamma: f64, centre_height: f64) -> Result<Oblique, LatticeError> {
        check_length("a", a)?;
        check_length("b", b)?;
        if !(gamma.is_finite() && gamma > 0.0 && gamma < std::f64::consts::PI) {
            return Err(LatticeError::NearlyParallel {
                angle_deg: gamma.to_degrees(),
                min_deg: 0.0,
            });
        }
        if !(centre_height.is_finite() && centre_height > 0.0) {
            return Err(LatticeError::BadHeight {
                index: 1,
                value: centre_height,
            });
        }
        let mut centre = MotifSite::new(0.5, 0.5, "B");
        centre.relative_height = centre_height;
        Ok(Oblique {
            a,
            b,
            gamma,
            motif: vec![MotifSite::new(0.0, 0.0, "A"), centre],
        })
    }
}

impl Lattice for Oblique {
    fn name(&self) -> &str {
        "oblique"
    }
    fn primitive_vectors(&self) -> [Vector2<f64>; 2] {
        let (sin, cos) = self.gamma.sin_cos();
        [
            Vector2::new(self.a, 0.0),
            Vector2::new(self.b * cos, self.b * sin),
        ]
    }
    fn motif(&self) -> &[MotifSite] {
        &self.motif
    }
    fn plane_group(&self) -> PlaneGroup {
        PlaneGroup::P2
    }
}

/// The kagome lattice: three sites per hexagonal cell of constant `a`, at the midpoints of
/// the triangular lattice's edges, each with 4 nearest neighbours at `a/2`; p6mm about the
/// hexagon centre (1/2, 1/2).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Kagome {
    a: f64,
    motif: Vec<MotifSite>,
}

impl Kagome {
    /// A kagome lattice with cell constant `a` (metres; nearest-neighbour distance `a/2`).
    pub fn new(a: f64) -> Result<Kagome, LatticeError> {
        check_length("a", a)?;
        Ok(Kagome {
            a,
            motif: vec![
                MotifSite::new(0.0, 0.0, "A"),
                MotifSite::new(0.5, 0.0, "B"),
                MotifSite::new(0.0, 0.5, "C"),
            ],
        })
    }
}

impl Lattice for Kagome {
    fn name(&self) -> &str {
        "kagome"
    }
    fn primitive_vectors(&self) -> [Vector2<f64>; 2] {
        hexagonal_vectors(self.a)
    }
    fn motif(&self) -> &[MotifSite] {
        &self.motif
    }
    fn plane_group(&self) -> PlaneGroup {
        PlaneGroup::P6mm
    }
    /// The hexagon centre: about a site the kagome is only p2mm.
    fn symmetry_origin(&self) -> [f64; 2] {
        [0.5, 0.5]
    }
}
