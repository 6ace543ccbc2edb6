//! What a config resolves to (lattice, constant, pipeline options) and `--nn auto`.

use anyhow::{Context, Result};
use dhct_calibrate::{CalibrationError, CheckOptions, calibrate_pair};
use dhct_lattice::Lattice;
use dhct_pipeline::PipelineOptions;
use dhct_scan::ScanPair;
use ndarray::Array2;

use super::{CorrectConfig, Length, build_lattice};

/// The largest pixel-size error accepted for a lattice whose constant the user did not
/// type (a preset's known constant, e.g. graphite or Si(111)-7×7): a factor 1.75 either
/// way along the fast axis, so a head off by 40 % either way (the lattice 1.67× or 0.71× as
/// long in the file) passes, while a 2 × 2 superstructure taken for the lattice does not.
/// A constant the user types is held to `CheckOptions::default()`'s 15 %.
pub const PRESET_PITCH_TOLERANCE: f64 = 0.75;

/// With `--calibrate`: the constant is right, the pixel size may be off by up to ×10.
pub const CALIBRATE_PITCH_TOLERANCE: f64 = 9.0;

/// A placeholder constant for `--nn auto` until the image has been measured, metres.
const AUTO_PLACEHOLDER_M: f64 = 1e-9;

/// What a config resolves to before any data is read.
pub struct Resolved {
    /// The lattice as named (preset or file).
    pub lattice_name: String,
    /// The nearest-neighbour distance given (or measured, for `auto`), metres.
    pub nn_m: Option<f64>,
    /// `--nn auto`: the constant still has to be measured from the image.
    pub nn_auto: bool,
    /// The lattice built from the name and the nearest-neighbour distance (a placeholder
    /// distance while it is still to be measured).
    pub lattice: Box<dyn Lattice + Send + Sync>,
    /// The config's pipeline options (or the lattice's defaults) with the flags applied.
    pub options: PipelineOptions,
}

/// The lattice and pipeline options of `config` (shared by `correct` and `diagnose`).
pub fn resolve(config: &CorrectConfig) -> Result<Resolved> {
    let lattice_name = config.lattice.clone().unwrap_or_else(|| "graphite".into());
    let nn_auto = config.nn.as_ref().is_some_and(Length::is_auto);
    let nn_m = if nn_auto {
        Some(AUTO_PLACEHOLDER_M)
    } else {
        config
            .nn
            .as_ref()
            .map(Length::metres)
            .transpose()
            .context("--nn")?
    };
    let lattice = build_lattice(&lattice_name, nn_m)?;
    let mut options = config.pipeline_options(lattice.as_ref())?;
    if nn_m.is_some() || !options.features.neighbour_distance.is_finite() {
        options.features.neighbour_distance = lattice.nearest_neighbour_distance();
    }
    if let Some(p) = config.polarity {
        options.features.polarity = p;
    }
    if let Some(group) = config.plane_group {
        options.unit_cell.plane_group = Some(group);
    }
    // A lattice nobody named is an assumption: it may be checked against the image but
    // never rescale the pixel size beyond what a typed constant may.
    let constant_given = (nn_m.is_some() && !nn_auto) || config.lattice.is_none();
    apply_check_policy(config, constant_given, &mut options);
    Ok(Resolved {
        lattice_name,
        nn_m: if nn_auto { None } else { nn_m },
        nn_auto,
        lattice,
        options,
    })
}

/// How far the file's pixel size may be off: 15 % for a typed constant (or a lattice
/// assumed because none was named), a factor 1.75 for a named preset's, ×10 with
/// `--calibrate`; `--trust-inputs` turns the check (and the calibration
/// from the lattice) off. A tolerance set in a config file is kept.
fn apply_check_policy(config: &CorrectConfig, typed: bool, options: &mut PipelineOptions) {
    let check = &mut options.calibration.check;
    let default = CheckOptions::default().pitch_tolerance;
    if !typed && check.pitch_tolerance == default {
        check.pitch_tolerance = PRESET_PITCH_TOLERANCE;
    }
    if config.calibrate == Some(true) {
        check.pitch_tolerance = check.pitch_tolerance.max(CALIBRATE_PITCH_TOLERANCE);
    }
    if config.trust_inputs == Some(true) {
        options.calibration.enabled = false;
    }
}

/// Why the nearest-neighbour distance could not be measured for `--nn auto`.
#[derive(Debug)]
pub enum MeasuredNnError {
    /// The image's lattice could not be matched to the lattice named.
    Mismatch(CalibrationError),
    /// The lattice could not be rebuilt with the measured distance.
    Options(anyhow::Error),
}

/// For `--nn auto`: the lattice rebuilt with the nearest-neighbour distance the image shows
/// in the file's units (the pixel size taken as right); otherwise `resolved` unchanged.
pub fn with_measured_nn(
    mut resolved: Resolved,
    pair: &ScanPair,
    mask: Option<&Array2<bool>>,
) -> Result<Resolved, MeasuredNnError> {
    if !resolved.nn_auto {
        return Ok(resolved);
    }
    let options = CheckOptions {
        pitch_tolerance: f64::MAX,
        ..resolved.options.calibration.check
    };
    let found = calibrate_pair(pair, resolved.lattice.as_ref(), mask, &options)
        .map_err(MeasuredNnError::Mismatch)?;
    let nn = resolved.lattice.nearest_neighbour_distance() * found.calibration.mean_scale;
    resolved.lattice =
        build_lattice(&resolved.lattice_name, Some(nn)).map_err(MeasuredNnError::Options)?;
    resolved.options.features.neighbour_distance = nn;
    resolved.nn_m = Some(nn);
    Ok(resolved)
}
