//! The calibration stage: the lattice the image shows (`dhct-calibrate`), checked against
//! the lattice given before any feature is found; it seeds the feature kernel and the
//! neighbour search, and its global affine map is the floor the full model must beat.

use dhct_calibrate::{
    Calibration, CalibrationError, CheckOptions, PairCalibration, binning_factor, calibrate_pair,
    match_lattice, measure_lattice_binned,
};
use dhct_distortion::SeedMap;
use dhct_features::PARALLEL_PASSES_MAX_PIXELS;
use dhct_lattice::Lattice;
use dhct_scan::{ScanGeometry, ScanPair, ScanPass};
use ndarray::Array2;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::PipelineError;
use crate::covered::{Window, covered_window, crop};

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

/// The affine map the lattice measured (file metres per sample metres): the neighbour
/// search looks for the lattice among the raw positions with it undone.
pub(crate) fn seed_map(found: &PairCalibration) -> Option<SeedMap> {
    SeedMap::new(found.calibration.matrix)
}

/// The lattice of one corrected image, measured by FFT as an outside check would measure
/// it (not by dhct's own lattice fit), against the lattice given.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CorrectedImageCheck {
    /// Trace or retrace.
    pub pass: ScanPass,
    /// Apparent over true lengths along x and y, shear (1, 1, 0° when the corrected image
    /// has exactly the lattice given).
    pub calibration: Calibration,
    /// Largest change of an angle between the lattice's vectors `a1`, `a2`, `a2 − a1` in the
    /// corrected image, degrees.
    pub angle_error_deg: f64,
}

/// Largest deviation of a corrected image's lattice (scale along x or y) from the lattice
/// given before a warning is given.
pub const CORRECTED_SCALE_TOLERANCE: f64 = 0.015;

/// Fewest lattice periods (nearest-neighbour distances) the covered part of a corrected
/// image must hold along x and along y for its lattice to be measured.
pub const MIN_CHECKED_PERIODS: f64 = 4.0;

/// Largest change of a lattice angle in a corrected image, degrees, before a warning.
pub const CORRECTED_ANGLE_TOLERANCE_DEG: f64 = 1.0;

impl CorrectedImageCheck {
    /// Whether the corrected image's lattice is the lattice given to within the tolerances.
    pub fn passes(&self) -> bool {
        self.calibration
            .scale
            .iter()
            .all(|k| (k - 1.0).abs() <= CORRECTED_SCALE_TOLERANCE)
            && self.angle_error_deg <= CORRECTED_ANGLE_TOLERANCE_DEG
    }

    /// How far the image's lattice is from `lattice`: "`x` % × `y` % of the … lattice
    /// along x × y with angles `a`° off".
    pub fn describe(&self, lattice: &dyn Lattice) -> String {
        let k = &self.calibration;
        format!(
            "{:.2} % × {:.2} % of the {} lattice along x × y with angles {:.2}° off",
            100.0 * k.scale[0],
            100.0 * k.scale[1],
            lattice.name(),
            self.angle_error_deg
        )
    }
}

/// The grid of `geometry` inside `window` (same pitch, directions and timing).
fn window_geometry(geometry: &ScanGeometry, window: Window) -> Option<ScanGeometry> {
    ScanGeometry::new(
        window.columns(),
        window.rows(),
        geometry.pitch_x(),
        geometry.pitch_y(),
        geometry.pixel_period(),
        geometry.trace_fast(),
        geometry.slow_direction(),
    )
    .ok()
}

/// A corrected image's lattice off by more than this fraction, by one scale along x and y
/// (within [`CORRECTED_SCALE_TOLERANCE`] of each other, angles within
/// [`CORRECTED_ANGLE_TOLERANCE_DEG`]), in every pass, is the constant given being wrong:
/// timing, hysteresis and drift errors stretch one axis, not both alike.
pub const UNIFORM_SCALE_ERROR: f64 = 0.05;

/// The error when every corrected image in `checks` (at least one) shows `lattice` at one
/// scale, the same along x and y, off by more than [`UNIFORM_SCALE_ERROR`].
pub(crate) fn uniform_scale_error(
    checks: &[CorrectedImageCheck],
    lattice: &dyn Lattice,
) -> Option<PipelineError> {
    let uniform = |c: &CorrectedImageCheck| {
        let [kx, ky] = c.calibration.scale;
        let mean = 0.5 * (kx + ky);
        ((kx - ky).abs() <= CORRECTED_SCALE_TOLERANCE * mean
            && c.angle_error_deg <= CORRECTED_ANGLE_TOLERANCE_DEG
            && (mean - 1.0).abs() > UNIFORM_SCALE_ERROR)
            .then_some(mean)
    };
    let scales: Vec<f64> = checks.iter().map(uniform).collect::<Option<_>>()?;
    if scales.is_empty() {
        return None;
    }
    let scale = scales.iter().sum::<f64>() / scales.len() as f64;
    // One scale for every pass, not two passes off in opposite senses.
    if scales
        .iter()
        .any(|s| (s - scale).abs() > CORRECTED_SCALE_TOLERANCE)
    {
        return None;
    }
    Some(PipelineError::CorrectedScale {
        lattice: lattice.name().to_string(),
        given_nn_m: lattice.nearest_neighbour_distance(),
        scale,
        passes: checks
            .iter()
            .map(|c| {
                format!(
                    "{} {:.2} % × {:.2} %",
                    c.pass,
                    100.0 * c.calibration.scale[0],
                    100.0 * c.calibration.scale[1]
                )
            })
            .collect(),
    })
}

/// The largest change of the angles between `a1`, `a2` and `a2 − a1` of `lattice` (placed
/// with the calibration's rotation) under the calibration's `K`, degrees.
fn angle_error_deg(lattice: &dyn Lattice, calibration: &Calibration) -> f64 {
    let [a1, a2] = lattice.primitive_vectors();
    let (s, c) = calibration.rotation_deg.to_radians().sin_cos();
    let [[kx, kxy], [_, ky]] = calibration.matrix;
    let place = |v: nalgebra::Vector2<f64>| {
        let r = nalgebra::Vector2::new(c * v.x - s * v.y, s * v.x + c * v.y);
        (r, nalgebra::Vector2::new(kx * r.x + kxy * r.y, ky * r.y))
    };
    let vectors = [place(a1), place(a2), place(a2 - a1)];
    let mut worst: f64 = 0.0;
    for i in 0..3 {
        for j in i + 1..3 {
            let before = vectors[i].0.angle(&vectors[j].0);
            let after = vectors[i].1.angle(&vectors[j].1);
            worst = worst.max((after - before).abs().to_degrees());
        }
    }
    worst
}

/// The bounds a corrected image's lattice is looked for in: any stretch or shear the
/// calibration stage accepts, and a scale within `1 + tolerance` either way along both axes.
fn corrected_bounds(geometry: &ScanGeometry, tolerance: f64) -> dhct_calibrate::MapBounds {
    let options = CheckOptions {
        pitch_tolerance: tolerance,
        ..CheckOptions::default()
    };
    let mut bounds = options.bounds(geometry.fast_axis());
    bounds.slow_scale = bounds.fast_scale;
    bounds
}

/// Measures each corrected image's lattice (grid of `geometry`, sample units) by its
/// Fourier transform, as an outside check would, against `lattice`, on the rectangle of
/// the image that holds values; images whose lattice cannot be measured are left out.
pub fn check_corrected_images(
    images: &[(ScanPass, &Array2<f64>)],
    geometry: &ScanGeometry,
    lattice: &dyn Lattice,
) -> Vec<CorrectedImageCheck> {
    let factor = binning_factor(geometry, lattice.nearest_neighbour_distance());
    let check = |&(pass, z): &(ScanPass, &Array2<f64>)| {
        let window = covered_window(z.view())?;
        let periods = |length: f64| length / lattice.nearest_neighbour_distance();
        if periods(window.columns() as f64 * geometry.pitch_x())
            .min(periods(window.rows() as f64 * geometry.pitch_y()))
            < MIN_CHECKED_PERIODS
        {
            return None;
        }
        let (z, geometry) = (crop(z.view(), window), window_geometry(geometry, window)?);
        let geometry = &geometry;
        let measured = measure_lattice_binned(z.view(), geometry, None, factor).ok()?;
        // Near the lattice given first (a corrected image should show it), then anywhere
        // within a factor 2 (so that one that went wrong is measured and flagged).
        let calibration = [0.15, 1.0]
            .into_iter()
            .filter_map(|tolerance| {
                match_lattice(&measured, lattice, &corrected_bounds(geometry, tolerance))
            })
            .find(|m| m.explains_image)?
            .calibration;
        Some(CorrectedImageCheck {
            pass,
            calibration,
            angle_error_deg: angle_error_deg(lattice, &calibration),
        })
    };
    // Side by side, except for huge images (one working set at a time).
    if geometry.rows() * geometry.columns() <= PARALLEL_PASSES_MAX_PIXELS {
        images.par_iter().filter_map(check).collect()
    } else {
        images.iter().filter_map(check).collect()
    }
}
