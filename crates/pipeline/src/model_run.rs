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
    Inputs, PipelineError, PipelineOptions, Stage, StageTimings, calibration, check_mask,
    find_all_features, fit_distortion_model, timed,
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
    /// Seconds per stage.
    pub timings: StageTimings,
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
    options.validate()?;
    check_mask(mask, pair.geometry())?;
    let mut timings = StageTimings::default();
    progress(Stage::Calibration);
    let measured = timed(&mut timings.calibration_s, || {
        calibration::measure(pair, lattice, mask, &options.calibration)
    })?;
    let inputs = Inputs {
        pair,
        lattice,
        mask,
        options,
        calibration: &measured,
    };
    progress(Stage::Features);
    let found = timed(&mut timings.features_s, || find_all_features(&inputs))?;
    progress(Stage::Model);
    let (dhct, model_failure) = timed(&mut timings.model_s, || {
        fit_distortion_model(&inputs, &found)
    })?;
    timings.total_s = start.elapsed().as_secs_f64();
    Ok(ModelRun {
        features: found.into_iter().map(|(set, _)| set).collect(),
        dhct,
        model_failure,
        timings,
    })
}
