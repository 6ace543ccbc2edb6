use thiserror::Error;

/// Why a unit-cell analysis could not be made.
#[derive(Debug, Error)]
pub enum UnitCellError {
    #[error("{found} deviations are too few for a confidence ellipse (at least 3 are needed)")]
    TooFewDeviations { found: usize },
    #[error("no complete unit cell (all four corner features found) in the image")]
    NoCompleteCell,
    #[error("the averaging grid must be at least 2 x 2 samples, got {0}")]
    BadResolution(usize),
    #[error("plane group {group} is not a symmetry of the {lattice} lattice's cell")]
    IncompatibleGroup {
        group: dhct_lattice::PlaneGroup,
        lattice: String,
    },
    #[error("the pixel pitch must be positive and finite, got ({0}, {1}) m")]
    BadPitch(f64, f64),
}
