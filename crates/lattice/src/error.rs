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
    #[error(
        "motif site {index} has fractional position {position:?}, beyond ±{max} cells \
         (give positions within the cell, e.g. 0 to 1)"
    )]
    FractionalOutOfRange {
        index: usize,
        position: [f64; 2],
        max: f64,
    },
    #[error("motif site {index} has a non-finite relative height {value}")]
    BadHeight { index: usize, value: f64 },
    #[error("the motif has {count} sites; at most {max} are supported")]
    TooManySites { count: usize, max: usize },
    #[error(
        "primitive vectors a1 and a2 are {angle_deg:.4}° apart, nearly parallel (they must be \
         {min_deg}° to {max_deg}° apart; choose a less skewed primitive cell)",
        max_deg = 180.0 - .min_deg
    )]
    NearlyParallel { angle_deg: f64, min_deg: f64 },
    #[error(
        "primitive vectors differ in length by a factor {ratio:.4e}; at most {max} is supported"
    )]
    AspectRatio { ratio: f64, max: f64 },
    #[error(
        "finding this lattice's neighbours needs {work:.3e} site comparisons, more than the \
         limit of {max:.0e}: use fewer motif sites or a less elongated cell"
    )]
    TooComplex { work: f64, max: f64 },
    #[error("{path} is {kind}, not a regular file", path = .path.display())]
    NotRegularFile {
        path: std::path::PathBuf,
        kind: &'static str,
    },
    #[error("lattice file {path} is {bytes} bytes, more than the {max} a lattice file may have", path = .path.display())]
    FileTooLarge {
        path: std::path::PathBuf,
        bytes: u64,
        max: u64,
    },
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
    /// A catalogue lattice without a known constant was asked for without one.
    #[error("the {name} lattice has no known constant: give its nearest-neighbour distance")]
    NeedsConstant { name: &'static str },
    #[error("cannot read lattice file {path}")]
    Io {
        path: std::path::PathBuf,
        #[source]
        source: std::io::Error,
    },
}
