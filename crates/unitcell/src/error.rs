use thiserror::Error;

/// Why a unit-cell analysis could not be made.
#[derive(Debug, Error)]
pub enum UnitCellError {
    /// Too few deviations for a confidence ellipse.
    #[error("{found} deviations are too few for a confidence ellipse (at least 3 are needed)")]
    TooFewDeviations {
        /// Deviations given.
        found: usize,
    },
    /// No cell has all four corner features.
    #[error("no complete unit cell (all four corner features found) in the image")]
    NoCompleteCell,
    /// The averaging grid has fewer than 2 samples per side; holds the resolution given.
    #[error("the averaging grid must be at least 2 x 2 samples, got {0}")]
    BadResolution(usize),
    /// The plane group's operations are not symmetries of the lattice's cell.
    #[error("plane group {group} is not a symmetry of the {lattice} lattice's cell")]
    IncompatibleGroup {
        /// The plane group asked for.
        group: dhct_lattice::PlaneGroup,
        /// The lattice's name.
        lattice: String,
    },
    /// The pixel pitch is not positive and finite; holds (x, y), metres.
    #[error("the pixel pitch must be positive and finite, got ({0}, {1}) m")]
    BadPitch(f64, f64),
}
