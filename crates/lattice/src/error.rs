use thiserror::Error;

use crate::PlaneGroup;
use crate::plane_group::UnknownPlaneGroup;

/// Why a lattice definition is unusable.
#[derive(Debug, Error)]
pub enum LatticeError {
    /// A length is not finite and positive (or outside the accepted range).
    #[error("lattice constant {what} must be finite and positive, got {value} m")]
    BadLength {
        /// Which length.
        what: &'static str,
        /// The value given, metres.
        value: f64,
    },
    /// The primitive vectors are parallel or zero.
    #[error("primitive vectors a1 = {a1:?} m and a2 = {a2:?} m are parallel or zero")]
    Degenerate {
        /// a1, metres.
        a1: [f64; 2],
        /// a2, metres.
        a2: [f64; 2],
    },
    /// The motif has no site.
    #[error("the motif is empty: a lattice needs at least one imaged feature per cell")]
    EmptyMotif,
    /// A site's position is not finite.
    #[error("motif site {index} has a non-finite fractional position {position:?}")]
    BadSite {
        /// The site.
        index: usize,
        /// Its fractional position.
        position: [f64; 2],
    },
    /// A site lies too many cells away.
    #[error(
        "motif site {index} has fractional position {position:?}, beyond ±{max} cells \
         (give positions within the cell, e.g. 0 to 1)"
    )]
    FractionalOutOfRange {
        /// The site.
        index: usize,
        /// Its fractional position.
        position: [f64; 2],
        /// The largest accepted |coordinate|.
        max: f64,
    },
    /// A site's height is not finite (or not positive).
    #[error("motif site {index} has an unusable relative height {value}")]
    BadHeight {
        /// The site.
        index: usize,
        /// The height given.
        value: f64,
    },
    /// Too many motif sites.
    #[error("the motif has {count} sites; at most {max} are supported")]
    TooManySites {
        /// Sites given.
        count: usize,
        /// The limit.
        max: usize,
    },
    /// The primitive vectors are nearly parallel.
    #[error(
        "primitive vectors a1 and a2 are {angle_deg:.4}° apart, nearly parallel (they must be \
         {min_deg}° to {max_deg}° apart; choose a less skewed primitive cell)",
        max_deg = 180.0 - .min_deg
    )]
    NearlyParallel {
        /// Their angle, degrees.
        angle_deg: f64,
        /// The smallest accepted angle, degrees.
        min_deg: f64,
    },
    /// The primitive vectors differ too much in length.
    #[error(
        "primitive vectors differ in length by a factor {ratio:.4e}; at most {max} is supported"
    )]
    AspectRatio {
        /// Longer over shorter.
        ratio: f64,
        /// The limit.
        max: f64,
    },
    /// The neighbour search would take too long.
    #[error(
        "finding this lattice's neighbours needs {work:.3e} site comparisons, more than the \
         limit of {max:.0e}: use fewer motif sites or a less elongated cell"
    )]
    TooComplex {
        /// Comparisons needed.
        work: f64,
        /// The limit.
        max: f64,
    },
    /// The cell does not have the metric its plane group needs.
    #[error(
        "plane group {group} needs {needs}, but |a1| = {:.6e} m and |a2| = {:.6e} m are \
         {angle_deg:.4}° apart (allowed: {tolerance:.1e} relative, the precision of the \
         numbers given): correct the vectors or choose a lower group (e.g. p2)",
        lengths[0], lengths[1]
    )]
    MetricMismatch {
        /// The plane group given.
        group: PlaneGroup,
        /// What it needs of the cell.
        needs: &'static str,
        /// |a1| and |a2|, metres.
        lengths: [f64; 2],
        /// The angle between them, degrees.
        angle_deg: f64,
        /// The relative tolerance used.
        tolerance: f64,
    },
    /// An operation of the plane group does not map the motif onto itself.
    #[error(
        "the motif does not have plane group {group} about the symmetry origin {origin:?}: \
         {operation} takes site {index} to {image:.4?}, where no site of equal height is \
         (give the symmetry_origin where the group's axes are, e.g. a hexagon centre, or a \
         lower group)"
    )]
    MotifNotSymmetric {
        /// The plane group given.
        group: PlaneGroup,
        /// The operation that fails.
        operation: String,
        /// The symmetry origin, fractional.
        origin: [f64; 2],
        /// The site it fails on.
        index: usize,
        /// Where the site lands, fractional.
        image: [f64; 2],
    },
    /// The path is not a regular file.
    #[error("{path} is {kind}, not a regular file", path = .path.display())]
    NotRegularFile {
        /// The path.
        path: std::path::PathBuf,
        /// What it is.
        kind: &'static str,
    },
    /// The lattice file is too large.
    #[error("lattice file {path} is {bytes} bytes, more than the {max} a lattice file may have", path = .path.display())]
    FileTooLarge {
        /// The path.
        path: std::path::PathBuf,
        /// Its size.
        bytes: u64,
        /// The limit.
        max: u64,
    },
    /// Two sites are the same feature.
    #[error("motif sites {first} and {second} coincide")]
    CoincidentSites {
        /// One site.
        first: usize,
        /// The other.
        second: usize,
    },
    /// An unknown length unit.
    #[error("unknown length unit '{0}' (use m, nm, A or pm)")]
    UnknownUnit(String),
    /// An unknown plane group.
    #[error(transparent)]
    UnknownPlaneGroup(#[from] UnknownPlaneGroup),
    /// The file cannot be parsed.
    #[error("cannot parse lattice file: {0}")]
    Parse(String),
    /// A catalogue lattice without a known constant was asked for without one (the command
    /// line maps this to its own option).
    #[error("the {name} lattice has no known constant: give its nearest-neighbour distance")]
    NeedsConstant {
        /// The catalogue name.
        name: &'static str,
    },
    /// The file cannot be read.
    #[error("cannot read lattice file {path}")]
    Io {
        /// The path.
        path: std::path::PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
}
