//! Stages 0–2 alone (the calibration check, the features, the model): what a series of
//! frames needs of each frame before one model is fitted to all of them. No correction,
//! lattice fit, image or unit cell is made, so a frame costs a fraction of [`crate::run`].

use std::time::Instant;

use dhct_distortion::DhctResult;
use dhct_features::FeatureSet;
use dhct_lattice::Lattice;
use dhct_scan::ScanPair;
use ndarray::Array2;

use crate::{
    FoundPass, Inputs, Measured, PipelineError, PipelineOptions, Stage, StageTimings, Warning,
    calibration, check_mask, find_all_features, fit_distortion_model, timed, warnings,
};

/// What [`run_model`] found in one scan.
#[derive(Debug, Clone)]
pub struct ModelRun {
    /// The features of each pass (controller frame).
    pub features: Vec<FeatureSet>,
    /// The model fitted to this scan alone (or the global affine map, when the model could
    /// not be fitted: [`ModelRun::model_failure`] says why).
    pub dhct: DhctResult,
    /// Why the model could not be fitted, when it could not.
    pub model_failure: Option<String>,
    /// What stage 0 found about the inputs (the file's pixel size calibrated from the
    /// lattice, the lattice not measured) and what was assumed for what the file did not
    /// state: the warnings of [`crate::run`] that do not depend on the correction.
    pub input_warnings: Vec<Warning>,
    /// Whether the image's lattice was measured from its Fourier transform (stage 0), so
    /// that a corrected image of it can be checked the same way.
    pub lattice_measured: bool,
    /// Seconds per stage.
    pub timings: StageTimings,
}

/// Stages 0–2 as [`crate::run`] continues from them: the calibration, the features with
/// their correlation maps, the model.
pub(crate) struct ModelStages {
    pub calibration: Measured,
    pub found: Vec<FoundPass>,
    pub dhct: DhctResult,
    pub model_failure: Option<String>,
    pub timings: StageTimings,
}

/// Checks the options and mask, then runs stages 0 (the lattice the image shows, checked
/// against the inputs), 1 (features, the kernel sized from the lattice's spacing as the
/// image shows it) and 2 (the model).
pub(crate) fn model_stages(
    pair: &ScanPair,
    lattice: &dyn Lattice,
    mask: Option<&Array2<bool>>,
    options: &PipelineOptions,
    progress: &(dyn Fn(Stage) + Sync),
) -> Result<ModelStages, PipelineError> {
    options.validate()?;
    check_mask(mask, pair.geometry())?;
    let mut timings = StageTimings::default();
    progress(Stage::Calibration);
    let calibration = timed(&mut timings.calibration_s, || {
        calibration::measure(pair, lattice, mask, &options.calibration)
    })?;
    let inputs = Inputs {
        pair,
        lattice,
        mask,
        options,
        calibration: &calibration,
    };
    progress(Stage::Features);
    let found = timed(&mut timings.features_s, || find_all_features(&inputs))?;
    progress(Stage::Model);
    let (dhct, model_failure) = timed(&mut timings.model_s, || {
        fit_distortion_model(&inputs, &found)
    })?;
    Ok(ModelStages {
        calibration,
        found,
        dhct,
        model_failure,
        timings,
    })
}

/// Runs stages 0–2 of [`crate::run`] on `pair`: the same checks and errors, nothing after
/// the model.
pub fn run_model(
    pair: &ScanPair,
    lattice: &dyn Lattice,
    mask: Option<&Array2<bool>>,
    options: &PipelineOptions,
    progress: &(dyn Fn(Stage) + Sync),
) -> Result<ModelRun, PipelineError> {
    let start = Instant::now();
    let stages = model_stages(pair, lattice, mask, options, progress)?;
    let mut timings = stages.timings;
    timings.total_s = start.elapsed().as_secs_f64();
    Ok(ModelRun {
        input_warnings: warnings::input_warnings(&stages.calibration, pair),
        lattice_measured: stages.calibration.is_ok(),
        features: stages.found.into_iter().map(|(set, _)| set).collect(),
        dhct: stages.dhct,
        model_failure: stages.model_failure,
        timings,
    })
}
