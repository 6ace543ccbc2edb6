use thiserror::Error;

/// Why a lattice definition is unusable.
#[derive(Debug, Error)]
pub enum LatticeError {
    #[error("lattice constant {what} must be finite and positive, got {value} m")]
    BadLength { what: &'static str, value: f64 },
    #[error("primitive vectors a1 = {a1:?} m and a2 = {a2:?} m are parallel or zero")]
    Degenerate { a1: [f64; 2], a2: [f64; 2] },
    #[error("the motif is empty: a lattice needs at least one imaged feature per cell")]
    EmptyMotif,
    #[error("motif site {index} has a non-finite fractional position {position:?}")]
    BadSite { index: usize, position: [f64; 2] },
    #[error("motif sites {first} and {second} coincide")]
    CoincidentSites { first: usize, second: usize },
    #[error("unknown length unit '{0}' (use m, nm, A or pm)")]
    UnknownUnit(String),
    #[error(
        "unknown plane group '{0}' (use one of the 17 wallpaper groups, e.g. p3m1, p6mm, p4mm)"
    )]
    UnknownPlaneGroup(String),
    #[error("cannot parse lattice file: {0}")]
    Parse(String),
    #[error("cannot read lattice file {path}")]
    Io {
        path: std::path::PathBuf,
        #[source]
        source: std::io::Error,
    },
}
