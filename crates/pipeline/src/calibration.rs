//! The calibration stage: the lattice the image shows (`dhct-calibrate`), checked against
//! the lattice given before any feature is found; it seeds the feature kernel and the
//! neighbour search, and its global affine map is the floor the full model must beat.

use dhct_calibrate::{CalibrationError, CheckOptions, PairCalibration, calibrate_pair};
use dhct_lattice::Lattice;
use dhct_scan::{ScanGeometry, ScanPair};
use ndarray::Array2;
use serde::{Deserialize, Serialize};

use crate::PipelineError;

/// Options of the calibration stage.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CalibrationOptions {
    /// Measure the lattice the image shows and check the inputs against it. Off: the file's
    /// pixel size is taken as right and nothing is checked (the behaviour before the
    /// stage existed).
    pub enabled: bool,
    /// How strictly the lattice and its constant are checked against the image.
    pub check: CheckOptions,
}

impl Default for CalibrationOptions {
    fn default() -> Self {
        CalibrationOptions {
            enabled: true,
            check: CheckOptions::default(),
        }
    }
}

impl CalibrationOptions {
    /// Checks the ranges of the check options.
    pub fn validate(&self) -> Result<(), PipelineError> {
        self.check.validate().map_err(PipelineError::BadOption)
    }
}

/// The lattice the image shows, or why it could not be measured (then nothing was
/// checked). A lattice that contradicts the inputs is an error.
pub(crate) fn measure(
    pair: &ScanPair,
    lattice: &dyn Lattice,
    mask: Option<&Array2<bool>>,
    options: &CalibrationOptions,
) -> Result<Result<PairCalibration, String>, PipelineError> {
    if !options.enabled {
        return Ok(Err("the calibration stage is off".into()));
    }
    match calibrate_pair(pair, lattice, mask, &options.check) {
        Ok(found) => Ok(Ok(found)),
        Err(CalibrationError::NoLattice { reason }) => Ok(Err(reason)),
        Err(e @ CalibrationError::ImageTooSmall { .. }) => Ok(Err(e.to_string())),
        Err(e) => Err(PipelineError::Calibration(Box::new(e))),
    }
}

/// `geometry` with the pixel size the lattice implies (the file's divided by the
/// calibration's x and y scale): where the neighbour search looks for the lattice.
pub(crate) fn seeded_geometry(
    geometry: &ScanGeometry,
    found: &PairCalibration,
) -> Option<ScanGeometry> {
    let [kx, ky] = found.calibration.scale;
    geometry
        .clone()
        .with_pitch(geometry.pitch_x() / kx, geometry.pitch_y() / ky)
        .ok()
}
