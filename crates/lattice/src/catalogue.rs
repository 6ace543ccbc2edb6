//! The lattice catalogue: every built-in lattice under its name, the one list the command
//! line, the simulator and the Python package choose from (a lattice file covers the rest).
//!
//! Adding a lattice: implement [`Lattice`] for it (one file, see `presets.rs`) and add one
//! [`CatalogueEntry`] line to [`CATALOGUE`]; the contract tests (`tests/tests/
//! lattice_contract.rs` and `crates/unitcell/tests/motif_symmetry.rs`) then run on it.

use crate::{
    CentredRectangular, Hexagonal, Honeycomb, Kagome, Lattice, LatticeError, Oblique, PlaneGroup,
    Rectangular, Square,
};

/// A lattice built from the catalogue.
pub type CatalogueLattice = Box<dyn Lattice + Send + Sync>;

/// One built-in lattice.
#[derive(Debug, Clone, Copy)]
pub struct CatalogueEntry {
    /// The name to choose it by (e.g. `--lattice graphite`).
    pub name: &'static str,
    /// Other names accepted for it.
    pub aliases: &'static [&'static str],
    /// One line on what it is.
    pub summary: &'static str,
    /// Whether it has a known constant (no nearest-neighbour distance needs to be given).
    pub known_constant: bool,
    build: fn(Option<f64>) -> Result<CatalogueLattice, LatticeError>,
}

impl CatalogueEntry {
    /// The lattice, with its nearest-neighbour distance replaced by `nn_m` (metres) if
    /// given; an entry without a known constant needs one.
    pub fn build(&self, nn_m: Option<f64>) -> Result<CatalogueLattice, LatticeError> {
        (self.build)(nn_m)
    }

    /// Whether `name` (any case) is this entry's name or one of its aliases.
    pub fn answers_to(&self, name: &str) -> bool {
        let name = name.to_ascii_lowercase();
        self.name == name || self.aliases.contains(&name.as_str())
    }
}

fn graphite(nn: Option<f64>) -> Result<CatalogueLattice, LatticeError> {
    Ok(match nn {
        Some(a) => Box::new(Hexagonal::new("graphite", a, PlaneGroup::P3m1)?),
        None => Box::new(Hexagonal::graphite()),
    })
}

fn graphene(nn: Option<f64>) -> Result<CatalogueLattice, LatticeError> {
    Ok(match nn {
        // The honeycomb's nearest-neighbour distance is a/√3.
        Some(nn) => Box::new(Honeycomb::new(nn * 3f64.sqrt())?),
        None => Box::new(Honeycomb::graphene()),
    })
}

fn hexagonal(nn: Option<f64>) -> Result<CatalogueLattice, LatticeError> {
    let a = nn.ok_or(LatticeError::NeedsConstant { name: "hexagonal" })?;
    Ok(Box::new(Hexagonal::new("hexagonal", a, PlaneGroup::P6mm)?))
}

fn sam_sqrt3(nn: Option<f64>) -> Result<CatalogueLattice, LatticeError> {
    Ok(match nn {
        Some(a) => Box::new(Hexagonal::new("sam-sqrt3", a, PlaneGroup::P6mm)?),
        None => Box::new(Hexagonal::sam_sqrt3()),
    })
}

fn si111_7x7(nn: Option<f64>) -> Result<CatalogueLattice, LatticeError> {
    let preset = Hexagonal::si111_7x7();
    Ok(match nn {
        Some(a) => Box::new(preset.with_constant(a)?),
        None => Box::new(preset),
    })
}

fn square(nn: Option<f64>) -> Result<CatalogueLattice, LatticeError> {
    let a = nn.ok_or(LatticeError::NeedsConstant { name: "square" })?;
    Ok(Box::new(Square::new(a)?))
}

/// A lattice of fixed shape whose size is set by its nearest-neighbour distance `nn`
/// (metres): `make` is called with the cell constant that gives that distance.
fn with_nn<L: Lattice + 'static>(
    name: &'static str,
    nn: Option<f64>,
    make: fn(f64) -> Result<L, LatticeError>,
) -> Result<CatalogueLattice, LatticeError> {
    let nn = nn.ok_or(LatticeError::NeedsConstant { name })?;
    if !(nn.is_finite() && nn > 0.0) {
        return Err(LatticeError::BadLength {
            what: "nearest-neighbour distance",
            value: nn,
        });
    }
    let unit = make(1e-10)?;
    let constant = 1e-10 * nn / unit.nearest_neighbour_distance();
    Ok(Box::new(make(constant)?))
}

/// The b/a ratio of the `rectangular` entry: the fcc(110) surface cell (a = NN along
/// [1-10], b = √2·a along [001]).
pub const RECTANGULAR_ASPECT: f64 = std::f64::consts::SQRT_2;

/// The b/a ratio of the conventional cell of the `centred-rectangular` entry.
pub const CENTRED_RECTANGULAR_ASPECT: f64 = 1.25;

/// The `oblique` entry's |a2|/|a1|, angle between a1 and a2 (degrees) and the centre
/// site's relative height.
pub const OBLIQUE_SHAPE: (f64, f64, f64) = (1.15, 78.0, 0.6);

fn rectangular(nn: Option<f64>) -> Result<CatalogueLattice, LatticeError> {
    with_nn("rectangular", nn, |a| {
        Rectangular::new(a, RECTANGULAR_ASPECT * a)
    })
}

fn centred_rectangular(nn: Option<f64>) -> Result<CatalogueLattice, LatticeError> {
    with_nn("centred-rectangular", nn, |a| {
        CentredRectangular::new(a, CENTRED_RECTANGULAR_ASPECT * a)
    })
}

fn oblique(nn: Option<f64>) -> Result<CatalogueLattice, LatticeError> {
    with_nn("oblique", nn, |a| {
        let (ratio, gamma_deg, height) = OBLIQUE_SHAPE;
        Oblique::new(a, ratio * a, gamma_deg.to_radians(), height)
    })
}

fn kagome(nn: Option<f64>) -> Result<CatalogueLattice, LatticeError> {
    with_nn("kagome", nn, Kagome::new)
}

/// Every built-in lattice.
pub static CATALOGUE: &[CatalogueEntry] = &[
    CatalogueEntry {
        name: "graphite",
        aliases: &["hopg"],
        summary: "HOPG as STM images it: one bright atom per cell, a = 2.46 Å, p3m1",
        known_constant: true,
        build: graphite,
    },
    CatalogueEntry {
        name: "honeycomb",
        aliases: &["graphene"],
        summary: "graphene with both sublattices imaged, a = 2.46 Å (C–C 1.42 Å), p6mm about \
                  the hexagon centre",
        known_constant: true,
        build: graphene,
    },
    CatalogueEntry {
        name: "hexagonal",
        aliases: &["trigonal"],
        summary: "one feature per hexagonal cell, p6mm (give the constant)",
        known_constant: false,
        build: hexagonal,
    },
    CatalogueEntry {
        name: "sam-sqrt3",
        aliases: &["sam"],
        summary: "the (√3×√3)R30° alkanethiol SAM on Au(111), a = 4.99 Å, p6mm",
        known_constant: true,
        build: sam_sqrt3,
    },
    CatalogueEntry {
        name: "si111-7x7",
        aliases: &["si-7x7", "7x7"],
        summary: "Si(111)-7×7 tracked by its dark corner holes, a = 2.688 nm, p31m",
        known_constant: true,
        build: si111_7x7,
    },
    CatalogueEntry {
        name: "square",
        aliases: &[],
        summary: "one feature per square cell, p4mm (give the constant)",
        known_constant: false,
        build: square,
    },
    CatalogueEntry {
        name: "rectangular",
        aliases: &["fcc110"],
        summary: "one feature per a × √2·a cell (the fcc(110) surface), p2mm; the constant \
                  given is a, the nearest-neighbour distance",
        known_constant: false,
        build: rectangular,
    },
    CatalogueEntry {
        name: "centred-rectangular",
        aliases: &["centered-rectangular", "c-rectangular"],
        summary: "features at the corners and centre of an a × 1.25·a cell, c2mm (give the \
                  nearest-neighbour distance, the half-diagonal)",
        known_constant: false,
        build: centred_rectangular,
    },
    CatalogueEntry {
        name: "oblique",
        aliases: &[],
        summary: "two sites of heights 1 and 0.6 at the corner and centre of an oblique cell \
                  (|a2| = 1.15·|a1|, 78°), p2 (give the nearest-neighbour distance)",
        known_constant: false,
        build: oblique,
    },
    CatalogueEntry {
        name: "kagome",
        aliases: &[],
        summary: "three sites per hexagonal cell, 4 neighbours each at a/2, p6mm about the \
                  hexagon centre (give the nearest-neighbour distance)",
        known_constant: false,
        build: kagome,
    },
];

/// The catalogue entry called `name` (or one of its aliases), if any.
pub fn lookup(name: &str) -> Option<&'static CatalogueEntry> {
    CATALOGUE.iter().find(|e| e.answers_to(name))
}

/// The catalogue's names, for messages: "graphite, honeycomb, …".
pub fn names() -> String {
    CATALOGUE
        .iter()
        .map(|e| e.name)
        .collect::<Vec<_>>()
        .join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_entry_builds_and_answers_to_its_names() {
        for entry in CATALOGUE {
            let lattice = entry.build(Some(3e-10)).unwrap();
            assert!(
                (lattice.nearest_neighbour_distance() - 3e-10).abs() < 1e-15,
                "{}",
                entry.name
            );
            assert_eq!(
                entry.build(None).is_ok(),
                entry.known_constant,
                "{}",
                entry.name
            );
            assert!(std::ptr::eq(
                lookup(&entry.name.to_uppercase()).unwrap(),
                entry
            ));
            for alias in entry.aliases {
                assert!(std::ptr::eq(lookup(alias).unwrap(), entry));
            }
        }
        assert!(CATALOGUE.len() >= 10);
        assert!(lookup("lieb").is_none());
        assert!(matches!(
            lookup("square").unwrap().build(None),
            Err(LatticeError::NeedsConstant { name: "square" })
        ));
    }
}
