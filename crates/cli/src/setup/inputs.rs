//! What a config resolves to (lattice, constant, pipeline options), `--nn auto`, and the
//! hints that turn the pipeline's typed errors into which flag to change.

use anyhow::{Context, Result};
use dhct_calibrate::{CalibrationError, CheckOptions, calibrate_pair, length};
use dhct_lattice::Lattice;
use dhct_pipeline::{PipelineError, PipelineOptions};
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

/// For `--nn auto`: the lattice rebuilt with the nearest-neighbour distance the image shows
/// in the file's units (the pixel size taken as right); otherwise `resolved` unchanged.
pub fn with_measured_nn(
    mut resolved: Resolved,
    pair: &ScanPair,
    mask: Option<&Array2<bool>>,
) -> Result<Resolved> {
    if !resolved.nn_auto {
        return Ok(resolved);
    }
    let options = CheckOptions {
        pitch_tolerance: f64::MAX,
        ..resolved.options.calibration.check
    };
    let found = calibrate_pair(pair, resolved.lattice.as_ref(), mask, &options)
        .map_err(|e| anyhow::anyhow!("--nn auto: {}", explain_calibration(&e)))?;
    let nn = resolved.lattice.nearest_neighbour_distance() * found.calibration.mean_scale;
    resolved.lattice = build_lattice(&resolved.lattice_name, Some(nn))?;
    resolved.options.features.neighbour_distance = nn;
    resolved.nn_m = Some(nn);
    Ok(resolved)
}

/// The pipeline's error with what to change on the command line.
pub fn explain(error: &PipelineError) -> String {
    match error {
        PipelineError::Calibration(e) => explain_calibration(e),
        PipelineError::TooFewFeatures {
            opposite_polarity: Some((polarity, _)),
            ..
        } => format!(
            "{error}\nhint: add --polarity {}, or check --lattice and --nn against the image",
            match polarity {
                dhct_features::Polarity::Dark => "dark",
                dhct_features::Polarity::Bright => "bright",
            }
        ),
        PipelineError::TooFewFeatures { .. } | PipelineError::LatticeMismatch { .. } => format!(
            "{error}\nhint: check --lattice and --nn against the image, --polarity, and that \
             the mask covers the atomically resolved part"
        ),
        PipelineError::LatticeFit(_) => format!(
            "{error}\nhint: check --lattice and --nn against the image, or give a --mask over \
             one domain"
        ),
        PipelineError::Features(dhct_features::FeatureError::ImageTooSmall { .. }) => {
            format!("{error}\nhint: check --nn and the pixel size (--pitch)")
        }
        _ => error.to_string(),
    }
}

fn explain_calibration(error: &CalibrationError) -> String {
    match error {
        CalibrationError::WrongScale {
            given_nn_m,
            measured_nn_m,
            ..
        } => format!(
            "{error}\nhint: if the file's pixel size is right, use --nn {} (or --nn auto); if \
             {} is right and the file's pixel size is wrong, add --calibrate; \
             --trust-inputs skips this check",
            length(*measured_nn_m).replace(' ', ""),
            length(*given_nn_m)
        ),
        CalibrationError::WrongLatticeType { .. } => format!(
            "{error}\nhint: choose the lattice the image shows with --lattice ({} or a \
             lattice file); --trust-inputs skips this check",
            dhct_lattice::catalogue::names()
        ),
        _ => error.to_string(),
    }
}
