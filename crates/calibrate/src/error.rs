//! Why a lattice could not be measured, or why the inputs cannot describe the image.

use thiserror::Error;

use crate::{ImageLattice, LatticeMatch};

/// Errors of [`crate::measure_lattice`] and [`crate::check_inputs`].
///
/// The variants carry the measured values so that a caller (e.g. a command line) can say
/// which of its own options to change; the messages speak only of lattices and images.
#[derive(Debug, Error)]
pub enum CalibrationError {
    /// The image is too small or has no finite pixels.
    #[error(
        "the image is too small for a Fourier analysis ({columns} x {rows} px, at least 16 x 16 needed)"
    )]
    ImageTooSmall {
        /// Image columns, pixels.
        columns: usize,
        /// Image rows, pixels.
        rows: usize,
    },
    /// The pixel size is not a positive finite length.
    #[error("the pixel size {pitch_x:e} x {pitch_y:e} m is not a positive length")]
    BadPitch {
        /// Pixel size along x, metres.
        pitch_x: f64,
        /// Pixel size along y, metres.
        pitch_y: f64,
    },
    /// No two independent periodicities stand out of the image's power spectrum.
    #[error("no lattice is visible in the image's Fourier transform: {reason}")]
    NoLattice {
        /// Why not, in words.
        reason: String,
    },
    /// The image's lattice has the wrong symmetry for the lattice given.
    #[error("the image shows {shows}; the {lattice} lattice cannot match it: {evidence}")]
    WrongLatticeType {
        /// What the image shows, in words (cell vectors, angle, in file units).
        shows: String,
        /// The lattice given.
        lattice: String,
        /// Why not, with the numbers.
        evidence: String,
        /// The measurement.
        measured: Box<ImageLattice>,
        /// The best match found inside the bounds (or at any pixel size), if any: its
        /// calibration, the peaks it explains and those it leaves.
        best: Option<Box<LatticeMatch>>,
    },
    /// The image's lattice is the right kind but of another size than the lattice given,
    /// beyond what a miscalibrated pixel size is allowed to explain.
    #[error(
        "the image shows {shows}, i.e. the {lattice} lattice's nearest-neighbour distance is \
         {measured} ± {sigma} in file units; {given} cannot match it: the file's pixel size \
         would be wrong by a factor {factor:.3} (at most {tolerance_percent:.0} % is accepted along the fast axis){at_given}",
        measured = crate::length(*measured_nn_m),
        sigma = crate::length(*measured_nn_sigma_m),
        given = crate::length(*given_nn_m),
        tolerance_percent = 100.0 * tolerance
    )]
    WrongScale {
        /// What the image shows, in words.
        shows: String,
        /// The lattice given.
        lattice: String,
        /// The lattice's nearest-neighbour distance as given, metres.
        given_nn_m: f64,
        /// The nearest-neighbour distance the image shows in file units, metres.
        measured_nn_m: f64,
        /// Its 1σ uncertainty, metres.
        measured_nn_sigma_m: f64,
        /// `measured / given` along the axis that failed (the fast axis, unless only the
        /// slow axis is beyond its wider limit): the factor by which the file's pixel size
        /// would be wrong.
        factor: f64,
        /// The largest relative pixel-size error accepted.
        tolerance: f64,
        /// What the lattice explains at the constant given, when it explains something
        /// there (e.g. "; at 3.780 Å it explains only 24 % of the strong Fourier peaks'
        /// amplitude"), else empty.
        at_given: String,
    },
}

impl From<crate::spectrum::SpectrumError> for CalibrationError {
    fn from(e: crate::spectrum::SpectrumError) -> Self {
        use crate::spectrum::SpectrumError;
        match e {
            SpectrumError::ImageTooSmall { columns, rows } => {
                CalibrationError::ImageTooSmall { columns, rows }
            }
            SpectrumError::Unusable(reason) => CalibrationError::NoLattice { reason },
        }
    }
}
