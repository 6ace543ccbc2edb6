//! Unit-cell analysis on top of a whole-image lattice fit (DHCT paper §V; none of this is in
//! the authors' Matlab).
//!
//! * [`ConfidenceEllipse`]: the covariance of feature deviations from their fitted sites as
//!   1σ and 2σ in-plane ellipses (and σ_z of the heights), for the whole-image fit or for
//!   [`LocalCell`] fits.
//! * [`local_cells`]: every cell whose four corner features were found, fitted on its own
//!   (origin and x/y scales; orientation fixed to the whole-image fit, paper Fig. 10b).
//! * [`average_unit_cell`]: the translationally averaged unit-cell image: each selected cell
//!   is resampled through its own linear map onto a fine grid in fractional coordinates and
//!   the cells are averaged; [`tile`] repeats it to check that the boundaries are seamless.
//! * [`symmetrize`]: the average over a plane group's operations ([`operations`], all 17
//!   wallpaper groups), and [`symmetry_residuals`]: how far a cell is from each group
//!   compatible with its lattice, so the user can choose; [`asymmetric_unit`] outlines the
//!   group's asymmetric unit on the cell.
//!
//! ```
//! use dhct_lattice::{Hexagonal, PlaneGroup};
//! use dhct_unitcell::{ConfidenceEllipse, operations};
//!
//! // Deviations of features from their fitted sites (metres): an ellipse along x.
//! let deviations = [[3e-12, 0.0], [-3e-12, 0.0], [0.0, 1e-12], [0.0, -1e-12]];
//! let ellipse = ConfidenceEllipse::from_deviations(&deviations, None).unwrap();
//! assert!(ellipse.sigma_major_m > ellipse.sigma_minor_m && ellipse.angle_rad.abs() < 1e-9);
//! // p3m1 has 6 operations and is a symmetry of the hexagonal lattice; p4 is not.
//! let graphite = Hexagonal::graphite();
//! assert_eq!(operations(PlaneGroup::P3m1, &graphite).unwrap().len(), 6);
//! assert!(operations(PlaneGroup::P4, &graphite).is_err());
//! ```
//!
//! Frames and units: positions are metres in the frame of the points given to the lattice
//! fit (normally the corrected sample frame); images are in display orientation with pixel
//! `(column, row)` at `(column·pitch_x, row·pitch_y)`.

mod asymmetric_unit;
mod average;
mod ellipse;
mod error;
mod local;
mod symmetry;

pub use asymmetric_unit::asymmetric_unit;
pub use average::{AveragedCell, average_unit_cell, tile};
pub use ellipse::ConfidenceEllipse;
pub use error::UnitCellError;
pub use local::{LocalCell, local_cells};
pub use symmetry::{
    SymmetryOperation, SymmetryResidual, operations, symmetrize, symmetry_residuals,
};
