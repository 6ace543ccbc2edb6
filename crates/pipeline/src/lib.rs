//! The whole DHCT chain in one call (Yothers, Browder & Bumm, Rev. Sci. Instrum. 88, 013708
//! (2017), steps 1–6): features → neighbours, local distortion and drift/creep/hysteresis
//! model → correction of features and images → whole-image lattice fit per mask region,
//! integer indices and deviations → confidence ellipses → local cells, averaged and
//! symmetry-averaged unit cell.
//!
//! Each stage is its own crate and can be used alone; this crate only wires them together
//! the way the `dhct correct` command and the benchmarks run them, and keeps every
//! intermediate result for plots and tables ([`Analysis`]).
//!
//! Frames: features and masks are in the controller frame (the raw image's pixel grid);
//! corrected positions, lattice fits, deviations and ellipses are in the sample frame
//! (metres, same axes and origin); see `dhct-distortion`.
//!
//! ```
//! use dhct_lattice::Square;
//! use dhct_pipeline::{PipelineOptions, run};
//! use dhct_scan::{ImageChannel, ScanDirection, ScanGeometry, ScanPair};
//! use ndarray::Array2;
//!
//! // A drift-free 128² image of a square lattice (a = 8 px = 0.8 nm), trace only.
//! let geometry = ScanGeometry::new(128, 128, 1e-10, 1e-10, 1e-4,
//!                                  ScanDirection::Right, ScanDirection::Down).unwrap();
//! let z = Array2::from_shape_fn((128, 128), |(r, c)| {
//!     let (x, y) = (c as f64 % 8.0 - 4.0, r as f64 % 8.0 - 4.0);
//!     (-(x * x + y * y) / 4.5).exp() * 1e-10
//! });
//! let pair = ScanPair::new(geometry, ImageChannel::new("Z", "m", z), None).unwrap();
//! let lattice = Square::new(0.8e-9).unwrap();
//! let analysis = run(&pair, &lattice, None, &PipelineOptions::for_lattice(&lattice), &|_| {})
//!     .unwrap();
//! // Every feature away from the border is indexed; the fitted scale is 1.
//! let fit = &analysis.regions[0].fit;
//! assert!((fit.scale[0] - 1.0).abs() < 0.01 && (fit.scale[1] - 1.0).abs() < 0.01);
//! ```

mod affine;
mod analysis;
mod calibration;
mod covered;
mod error;
mod model_run;
mod options;
mod region_fit;
mod regions;
mod results;
mod stage;
mod unit_cells;
mod warnings;

pub use affine::AffineComparison;
pub use analysis::{Analysis, CorrectionSource};
pub use calibration::{
    CORRECTED_ANGLE_TOLERANCE_DEG, CORRECTED_SCALE_TOLERANCE, CalibrationOptions,
    CorrectedImageCheck, MIN_CHECKED_PERIODS, UNIFORM_SCALE_ERROR, check_corrected_images,
};
pub use error::PipelineError;
pub use model_run::{ModelRun, run_model};
pub use options::{CellSelection, PipelineOptions, RegionOptions, UnitCellOptions};
pub use regions::label_regions;
pub use results::{FeatureIndex, PassOutput, RegionFit, SkippedRegion, UnitCellAnalysis};
pub use stage::{Stage, StageTimings};
pub use warnings::{
    CALIBRATION_WARNING, DEVIATION_WARNING, INDEXED_WARNING, SCALE_WARNING, UserInput, Warning,
    WarningCode, image_off_message, image_unchecked_message,
};

use std::time::Instant;

use dhct_calibrate::PairCalibration;
use dhct_distortion::{
    CorrectedFeature, DhctResult, DistortionError, DistortionModel, PassInput, Rdf, analyse_seeded,
    correct_features, correct_image, radial_distribution,
};
use dhct_features::{Feature, FeatureSet, find_features_in_pair_and_correlation};
use dhct_lattice::Lattice;
use dhct_scan::{ScanGeometry, ScanPair, ScanPass};
use ndarray::Array2;
use rayon::prelude::*;

use region_fit::{fit_regions, index_features};
use unit_cells::unit_cell_analysis;

/// Fewest features per image for the chain to start.
pub const MIN_FEATURES: usize = 12;

/// The calibration stage's result: the lattice the images show, or why it could not be
/// measured.
type Measured = Result<PairCalibration, String>;

/// What every stage of [`run`] after the calibration reads: the images, the lattice, the
/// mask (raw image's rows × columns, true = use), the options and the calibration.
#[derive(Clone, Copy)]
struct Inputs<'a> {
    pair: &'a ScanPair,
    lattice: &'a dyn Lattice,
    mask: Option<&'a Array2<bool>>,
    options: &'a PipelineOptions,
    calibration: &'a Measured,
}

/// The correction kept (the fitted model, or the global affine map when the model did
/// worse than it or could not be fitted), the features it corrected (sample frame) and the
/// region fits made with them.
struct Chosen {
    dhct: DhctResult,
    rejected_model: Option<DistortionModel>,
    correction: CorrectionSource,
    corrected_features: Vec<Vec<CorrectedFeature>>,
    regions: Vec<RegionFit>,
    skipped_regions: Vec<SkippedRegion>,
    comparisons: Vec<AffineComparison>,
    /// Per set, each feature's lattice index from the region fits (`None`: not indexed).
    indices: Vec<Vec<Option<FeatureIndex>>>,
}

/// Runs the chain on `pair` (trace, and retrace when present) for `lattice`. `mask` (rows ×
/// columns of the raw image, true = use) restricts the background fit, the model fit and the
/// lattice fits; each of its 4-connected regions is fitted as its own domain. `progress` is
/// called as each stage starts.
pub fn run(
    pair: &ScanPair,
    lattice: &dyn Lattice,
    mask: Option<&Array2<bool>>,
    options: &PipelineOptions,
    progress: &(dyn Fn(Stage) + Sync),
) -> Result<Analysis, PipelineError> {
    let start = Instant::now();
    let geometry = pair.geometry();
    // 0–2. The lattice the image shows, checked against the inputs; the features; the model.
    let model_run::ModelStages {
        calibration,
        found,
        dhct,
        model_failure,
        mut timings,
    } = model_run::model_stages(pair, lattice, mask, options, progress)?;
    let inputs = Inputs {
        pair,
        lattice,
        mask,
        options,
        calibration: &calibration,
    };

    // 3–4. Features corrected by the model and fitted per region; the global affine
    // correction, fitted the same way, is the floor the model must beat.
    progress(Stage::Correction);
    let sets: Vec<&FeatureSet> = found.iter().map(|(s, _)| s).collect();
    // The fitted model's weak spots, whichever correction is kept.
    let fit_warnings = warnings::fit_warnings(&dhct);
    let corrected_features = timed(&mut timings.correction_s, || {
        correct_sets(&dhct.model, geometry, &sets)
    });
    progress(Stage::LatticeFit);
    let model_failed = model_failure.is_some();
    let chosen = timed(&mut timings.lattice_fit_s, || {
        choose_correction(&inputs, &sets, dhct, model_failed, corrected_features)
    })?;

    // The images, with the correction chosen, and their lattices checked.
    let checked = correct_and_check(&inputs, &sets, chosen, &mut timings)?;
    let (chosen, images, image_checks) = (checked.chosen, checked.images, checked.checks);
    if let Some(error) = calibration::uniform_scale_error(&image_checks, lattice) {
        return Err(error);
    }

    // 5. Unit cells.
    progress(Stage::UnitCells);
    let (unit_cell, unit_cell_note) = timed(&mut timings.unit_cells_s, || {
        unit_cells(&inputs, &sets, &chosen.regions, &images)
    });

    let mut analysis = Analysis {
        passes: pass_outputs(
            &inputs,
            &chosen.dhct,
            found,
            chosen.corrected_features,
            images,
            chosen.indices,
        ),
        dhct: chosen.dhct,
        regions: chosen.regions,
        skipped_regions: chosen.skipped_regions,
        unit_cell,
        unit_cell_note,
        calibration,
        affine: chosen.comparisons,
        correction: chosen.correction,
        rejected_model: chosen.rejected_model,
        corrected_images: image_checks,
        rejected_model_images: checked.rejected_checks,
        warnings: Vec::new(),
        timings,
    };
    analysis.warnings = collect_warnings(&analysis, pair, lattice, fit_warnings, model_failure);
    analysis.timings.total_s = start.elapsed().as_secs_f64();
    Ok(analysis)
}

/// One image's features and, when kept, its correlation map (single precision).
type FoundPass = (FeatureSet, Option<Array2<f32>>);

/// Runs `stage`, adding its wall time (seconds) to `slot`.
fn timed<T>(slot: &mut f64, stage: impl FnOnce() -> T) -> T {
    let t = Instant::now();
    let result = stage();
    *slot += t.elapsed().as_secs_f64();
    result
}

/// Checks that `mask`, if given, has the image's size and selects at least one pixel.
fn check_mask(mask: Option<&Array2<bool>>, geometry: &ScanGeometry) -> Result<(), PipelineError> {
    if let Some(mask) = mask {
        let (rows, columns) = mask.dim();
        if (rows, columns) != (geometry.rows(), geometry.columns()) {
            return Err(PipelineError::MaskShape {
                mask_columns: columns,
                mask_rows: rows,
                columns: geometry.columns(),
                rows: geometry.rows(),
            });
        }
        if !mask.iter().any(|&m| m) {
            return Err(PipelineError::EmptyMask);
        }
    }
    Ok(())
}

/// Step 1: the features of every image with its correlation map (when kept), the kernel sized from
/// the lattice's nearest-neighbour distance (metres) as the image shows it (scaled by the
/// calibration's mean scale when the lattice was measured). An error when an image has
/// fewer than [`MIN_FEATURES`].
fn find_all_features(inputs: &Inputs) -> Result<Vec<FoundPass>, PipelineError> {
    let feature_options = feature_options_of(inputs);
    let found = find_features_in_pair_and_correlation(inputs.pair, &feature_options, inputs.mask)?;
    // A correlation map is kept (for plots) in single precision, and one not asked for is
    // let go now, not at the end of the run.
    let keep = inputs.options.keep_correlation;
    let found: Vec<_> = found
        .into_iter()
        .map(|(set, correlation)| (set, keep.then(|| correlation.mapv(|v| v as f32))))
        .collect();
    for (set, _) in &found {
        if set.features.len() < MIN_FEATURES {
            return Err(PipelineError::TooFewFeatures {
                pass: set.pass.to_string(),
                found: set.features.len(),
                needed: MIN_FEATURES,
                opposite_polarity: opposite_polarity(inputs, set),
            });
        }
    }
    Ok(found)
}

/// The feature options of the run: the kernel sized from the lattice's nearest-neighbour
/// distance (metres) as the image shows it (scaled by the calibration's mean scale when the
/// lattice was measured).
fn feature_options_of(inputs: &Inputs) -> dhct_features::FeatureOptions {
    let mut feature_options = inputs.options.features.clone();
    if !feature_options.neighbour_distance.is_finite() {
        feature_options.neighbour_distance = inputs.lattice.nearest_neighbour_distance();
    }
    if let Ok(found) = inputs.calibration {
        feature_options.neighbour_distance *= found.calibration.mean_scale;
    }
    feature_options
}

/// When `too_few` (an image with too few features) gives more features of the other
/// polarity, enough for the whole chain (the lattice fit's per-region minimum): that
/// polarity and the count (atoms that appear
/// dark, read as bright, leave the minima between them).
fn opposite_polarity(
    inputs: &Inputs,
    too_few: &FeatureSet,
) -> Option<(dhct_features::Polarity, usize)> {
    use dhct_features::Polarity;
    let options = feature_options_of(inputs);
    let other = match options.polarity {
        Polarity::Bright => Polarity::Dark,
        Polarity::Dark => Polarity::Bright,
    };
    let image = inputs.pair.image(too_few.pass)?;
    let flipped = dhct_features::FeatureOptions {
        polarity: other,
        ..options.clone()
    };
    let found = dhct_features::find_features(
        image,
        inputs.pair.geometry(),
        too_few.pass,
        &flipped,
        inputs.mask,
    )
    .ok()?
    .features
    .len();
    let needed = MIN_FEATURES.max(inputs.options.regions.min_features);
    (found >= needed && found > too_few.features.len()).then_some((other, found))
}

/// Step 2: the drift/creep/hysteresis model, its neighbour search seeded with the affine
/// map the measured lattice implies. Returns the model, or the global affine correction
/// with the reason the model failed.
fn fit_distortion_model(
    inputs: &Inputs,
    found: &[FoundPass],
) -> Result<(DhctResult, Option<String>), PipelineError> {
    let (geometry, lattice, calibration) =
        (inputs.pair.geometry(), inputs.lattice, inputs.calibration);
    let passes: Vec<PassInput> = found
        .iter()
        .map(|(set, _)| PassInput {
            features: &set.features,
            mask: inputs.mask,
        })
        .collect();
    let seeded = calibration.as_ref().ok().and_then(calibration::seed_map);
    // A model that cannot be fitted (too few features with full neighbour shells: a large
    // cell on a small frame) falls back to the global affine correction when the lattice
    // was measured: never worse than it.
    match analyse_seeded(
        &passes,
        geometry,
        lattice,
        &inputs.options.dhct,
        seeded.as_ref(),
    ) {
        Ok(dhct) => Ok((dhct, None)),
        Err(e) => {
            let affine = calibration
                .as_ref()
                .ok()
                .filter(|found| affine::trusted_alone(&found.calibration))
                .and_then(|found| affine::affine_model(geometry, &found.calibration));
            match affine {
                Some(model) => Ok((
                    DhctResult::of_model(model),
                    Some(model_error(e, found, lattice).to_string()),
                )),
                None => Err(model_error(e, found, lattice)),
            }
        }
    }
}

/// A too-few-features error of the lattice fit with the other polarity's count (when it
/// finds more in the first image).
fn with_opposite_polarity(
    error: PipelineError,
    inputs: &Inputs,
    sets: &[&FeatureSet],
) -> PipelineError {
    match (error, sets.first()) {
        (
            PipelineError::TooFewFeatures {
                pass,
                found,
                needed,
                opposite_polarity: None,
            },
            Some(first),
        ) => PipelineError::TooFewFeatures {
            pass,
            found,
            needed,
            opposite_polarity: opposite_polarity(inputs, first).filter(|&(_, n)| n > found),
        },
        (error, _) => error,
    }
}

/// Steps 3–4: the lattice fitted per region to the features `dhct` corrected. When the
/// lattice was measured and the model was fitted, each region is compared with the global
/// affine correction; if the affine map does better in the largest region it replaces the
/// model, and the features are corrected and the regions fitted again. Every feature is
/// then indexed from the region fits kept.
fn choose_correction(
    inputs: &Inputs,
    sets: &[&FeatureSet],
    dhct: DhctResult,
    model_failed: bool,
    corrected_features: Vec<Vec<CorrectedFeature>>,
) -> Result<Chosen, PipelineError> {
    let Inputs {
        pair,
        lattice,
        mask,
        options,
        calibration,
    } = *inputs;
    let geometry = pair.geometry();
    let (regions, skipped_regions) =
        fit_regions(pair, lattice, mask, options, sets, &corrected_features)
            .map_err(|e| with_opposite_polarity(e, inputs, sets))?;
    let mut comparisons = Vec::new();
    if let (Ok(found), false) = (calibration, model_failed) {
        let c = &found.calibration;
        comparisons = regions
            .iter()
            .filter_map(|r| affine::compare(r, sets, geometry, c, lattice, &options.lattice_fit))
            .collect();
    }
    let indices = index_features(sets, &regions);
    let chosen = Chosen {
        dhct,
        rejected_model: None,
        correction: if model_failed {
            CorrectionSource::Affine
        } else {
            CorrectionSource::DriftModel
        },
        corrected_features,
        regions,
        skipped_regions,
        comparisons,
        indices,
    };
    // The largest region decides.
    if chosen
        .comparisons
        .first()
        .is_some_and(AffineComparison::model_is_worse)
        && let Some(affine) = with_affine(inputs, sets, &chosen)?
    {
        return Ok(affine);
    }
    Ok(chosen)
}

/// `chosen` (the drift model) with the global affine correction in its place: the features
/// corrected by it, the regions fitted and indexed again, the model kept as the rejected
/// one. `None` when the lattice was not measured or its affine map cannot be inverted.
fn with_affine(
    inputs: &Inputs,
    sets: &[&FeatureSet],
    chosen: &Chosen,
) -> Result<Option<Chosen>, PipelineError> {
    let geometry = inputs.pair.geometry();
    let Some(model) = inputs
        .calibration
        .as_ref()
        .ok()
        .and_then(|found| affine::affine_model(geometry, &found.calibration))
    else {
        return Ok(None);
    };
    let corrected_features = correct_sets(&model, geometry, sets);
    let (regions, skipped_regions) = fit_regions(
        inputs.pair,
        inputs.lattice,
        inputs.mask,
        inputs.options,
        sets,
        &corrected_features,
    )?;
    let indices = index_features(sets, &regions);
    Ok(Some(Chosen {
        dhct: DhctResult {
            model,
            passes: chosen.dhct.passes.clone(),
            routes: chosen.dhct.routes.clone(),
            route_note: chosen.dhct.route_note.clone(),
        },
        rejected_model: Some(chosen.dhct.model.clone()),
        correction: CorrectionSource::Affine,
        corrected_features,
        regions,
        skipped_regions,
        comparisons: chosen.comparisons.clone(),
        indices,
    }))
}

/// The correction kept after its images were checked, the images and their checks.
struct Checked {
    chosen: Chosen,
    images: Vec<Array2<f64>>,
    checks: Vec<CorrectedImageCheck>,
    /// The drift model's checks when its images failed and the affine correction's did
    /// better (it is then `chosen`); empty otherwise.
    rejected_checks: Vec<CorrectedImageCheck>,
}

/// The images corrected with the correction `chosen` and their lattices checked. When the
/// drift model's images fail the check and the global affine correction fits the largest
/// region's features about as well ([`AffineComparison::affine_is_as_good`]), the affine
/// correction is tried: a model can fit the features of the region it was fitted in and
/// still be wrong between and beyond them (a degenerate creep extrapolated over the frame:
/// the HOPG terrace file's trace came out 147 % × 105 % with the model, 99.6 % × 100.4 %
/// with the affine map). It is kept when fewer of its images fail. A model that fits the
/// features far better than the affine map is kept whatever its images' check says.
fn correct_and_check(
    inputs: &Inputs,
    sets: &[&FeatureSet],
    chosen: Chosen,
    timings: &mut StageTimings,
) -> Result<Checked, PipelineError> {
    let (images, checks) = correct_images(inputs, sets, &chosen.dhct.model, timings)?;
    let failing = |checks: &[CorrectedImageCheck]| checks.iter().filter(|c| !c.passes()).count();
    let kept = |chosen, images, checks| Checked {
        chosen,
        images,
        checks,
        rejected_checks: Vec::new(),
    };
    let affine_as_good = chosen
        .comparisons
        .first()
        .is_some_and(AffineComparison::affine_is_as_good);
    if chosen.correction != CorrectionSource::DriftModel || failing(&checks) == 0 || !affine_as_good
    {
        return Ok(kept(chosen, images, checks));
    }
    let affine = timed(&mut timings.lattice_fit_s, || {
        with_affine(inputs, sets, &chosen)
    })?;
    let Some(affine) = affine else {
        return Ok(kept(chosen, images, checks));
    };
    let (affine_images, affine_checks) = correct_images(inputs, sets, &affine.dhct.model, timings)?;
    if failing(&affine_checks) < failing(&checks) {
        Ok(Checked {
            chosen: affine,
            images: affine_images,
            checks: affine_checks,
            rejected_checks: checks,
        })
    } else {
        Ok(kept(chosen, images, checks))
    }
}

/// The images, with the correction chosen (`model`), and their lattices measured as an
/// outside check would measure them; the times are added to the correction and
/// calibration stages.
fn correct_images(
    inputs: &Inputs,
    sets: &[&FeatureSet],
    model: &DistortionModel,
    timings: &mut StageTimings,
) -> Result<(Vec<Array2<f64>>, Vec<CorrectedImageCheck>), PipelineError> {
    let images = timed(&mut timings.correction_s, || {
        resample_images(inputs.pair, model, sets)
    })?;
    let checks = timed(&mut timings.calibration_s, || {
        check_images(inputs, sets, &images)
    });
    Ok((images, checks))
}

/// Every image resampled onto the sample-frame grid by `model` (z unchanged; in `sets`
/// order).
fn resample_images(
    pair: &ScanPair,
    model: &DistortionModel,
    sets: &[&FeatureSet],
) -> Result<Vec<Array2<f64>>, PipelineError> {
    let geometry = pair.geometry();
    sets.par_iter()
        .map(|set| {
            let image = pair
                .image(set.pass)
                .expect("features were found in this image");
            correct_image(model, geometry, set.pass, &image.z).map_err(PipelineError::from)
        })
        .collect()
}

/// Each corrected image's lattice, measured as an outside check would measure it; none
/// when the raw images' lattice could not be measured.
fn check_images(
    inputs: &Inputs,
    sets: &[&FeatureSet],
    images: &[Array2<f64>],
) -> Vec<CorrectedImageCheck> {
    if inputs.calibration.is_ok() {
        let passes: Vec<(ScanPass, &Array2<f64>)> =
            sets.iter().map(|s| s.pass).zip(images.iter()).collect();
        calibration::check_corrected_images(&passes, inputs.pair.geometry(), inputs.lattice)
    } else {
        Vec::new()
    }
}

/// Step 5 (the unit cell of the corrected `images`), or the note why there is none.
fn unit_cells(
    inputs: &Inputs,
    sets: &[&FeatureSet],
    regions: &[RegionFit],
    images: &[Array2<f64>],
) -> (Option<UnitCellAnalysis>, Option<String>) {
    let Inputs {
        pair,
        lattice,
        options,
        ..
    } = *inputs;
    let corrected_images: Vec<&Array2<f64>> = images.iter().collect();
    match unit_cell_analysis(pair, lattice, options, sets, regions, &corrected_images) {
        Ok(analysis) => (Some(analysis), None),
        Err(note) => (None, Some(note)),
    }
}

/// Each image's results: its features, correlation map (when kept), corrected features
/// and image, lattice indices, and the RDF of the corrected features on the raw RDF's bins
/// (paper Fig. 6).
fn pass_outputs(
    inputs: &Inputs,
    dhct: &DhctResult,
    found: Vec<FoundPass>,
    corrected_features: Vec<Vec<CorrectedFeature>>,
    images: Vec<Array2<f64>>,
    indices: Vec<Vec<Option<FeatureIndex>>>,
) -> Vec<PassOutput> {
    let (geometry, mask) = (inputs.pair.geometry(), inputs.mask);
    let corrected: Vec<(Vec<CorrectedFeature>, Array2<f64>)> =
        corrected_features.into_iter().zip(images).collect();
    // RDF of the corrected features on the raw RDF's bins (paper Fig. 6).
    let area = mask
        .map(|m| m.iter().filter(|&&v| v).count() as f64)
        .unwrap_or((geometry.rows() * geometry.columns()) as f64)
        * geometry.pitch_x()
        * geometry.pitch_y();
    found
        .into_iter()
        .zip(corrected)
        .zip(indices)
        .map(|(((set, correlation), (corrected, image)), indices)| {
            let raw = dhct
                .passes
                .iter()
                .find(|p| p.pass == set.pass)
                .map(|p| &p.selection.rdf);
            let rdf_corrected =
                raw.and_then(|raw| corrected_rdf(raw, &set.features, &corrected, mask, area));
            PassOutput {
                pass: set.pass,
                features: set,
                correlation,
                corrected,
                corrected_image: image,
                indices,
                rdf_corrected,
            }
        })
        .collect()
}

/// The warnings of `analysis`, in report order: calibration, assumptions, the fitted
/// model's weak spots (`fit_warnings`), its failure (`model_failure`), the affine
/// comparison, plausibility of the result, the corrected images' lattices.
fn collect_warnings(
    analysis: &Analysis,
    pair: &ScanPair,
    lattice: &dyn Lattice,
    fit_warnings: Vec<Warning>,
    model_failure: Option<String>,
) -> Vec<Warning> {
    let mut warnings = warnings::input_warnings(&analysis.calibration, pair);
    warnings.extend(fit_warnings);
    warnings.extend(model_failure.map(warnings::model_failure_warning));
    warnings.extend(warnings::affine_warnings(
        &analysis.affine,
        analysis.correction == CorrectionSource::Affine,
    ));
    warnings.extend(warnings::plausibility_warnings(
        lattice,
        &analysis.regions,
        &analysis.passes,
    ));
    warnings.extend(warnings::corrected_image_warnings(
        lattice,
        &analysis.corrected_images,
    ));
    warnings.extend(warnings::model_image_warnings(
        lattice,
        &analysis.rejected_model_images,
    ));
    let corrected: Vec<ScanPass> = analysis.passes.iter().map(|p| p.pass).collect();
    warnings.extend(warnings::unchecked_image_warnings(
        analysis.calibration.is_ok(),
        &corrected,
        &analysis.corrected_images,
    ));
    warnings
}

/// Every set's features moved to the sample frame by `model`.
fn correct_sets(
    model: &dhct_distortion::DistortionModel,
    geometry: &dhct_scan::ScanGeometry,
    sets: &[&FeatureSet],
) -> Vec<Vec<CorrectedFeature>> {
    sets.par_iter()
        .map(|set| correct_features(model, geometry, &set.features))
        .collect()
}

/// The model stage's error, with the spacing the features show when too few of them sit in
/// the lattice's neighbour pattern.
fn model_error(
    error: DistortionError,
    found: &[FoundPass],
    lattice: &dyn Lattice,
) -> PipelineError {
    let DistortionError::TooFewFeatures {
        found: usable,
        needed,
        ..
    } = error
    else {
        return error.into();
    };
    let features = &found_sets_first(found).features;
    let median_nn_m = median_nearest_distance(features);
    let expected_nn_m = lattice.nearest_neighbour_distance();
    let ratio = median_nn_m / expected_nn_m;
    let suggestion = if (0.8..1.25).contains(&ratio) {
        ": the spacing matches, so check the mask, the lattice type (neighbour count), \
         the image quality, and whether the drift is near half the slow-scan speed or \
         more (the raw lattice is then squeezed beyond recognition)"
            .to_string()
    } else {
        format!(
            ": if the image is calibrated, try a nearest-neighbour distance of {:.3} Å (or \
             check the lattice type; a wrong pixel size in the file scales every distance)",
            median_nn_m * 1e10
        )
    };
    PipelineError::LatticeMismatch {
        found: features.len(),
        usable,
        needed,
        median_nn_m,
        expected_nn_m,
        suggestion,
    }
}

fn found_sets_first(found: &[FoundPass]) -> &FeatureSet {
    &found[0].0
}

/// Median over features of the distance to the nearest other feature (metres).
fn median_nearest_distance(features: &[Feature]) -> f64 {
    let step = (features.len() / 400).max(1);
    let mut nearest: Vec<f64> = features
        .iter()
        .step_by(step)
        .map(|a| {
            features
                .iter()
                .filter(|b| !std::ptr::eq(*b, a))
                .map(|b| (a.x_m - b.x_m).hypot(a.y_m - b.y_m))
                .fold(f64::INFINITY, f64::min)
        })
        .filter(|d| d.is_finite())
        .collect();
    dhct_numerics::robust::median(&mut nearest).unwrap_or(f64::NAN)
}

/// RDF of the corrected positions of the features the raw RDF used (those inside the mask,
/// by raw position), on the raw RDF's bins.
fn corrected_rdf(
    raw: &Rdf,
    features: &[Feature],
    corrected: &[CorrectedFeature],
    mask: Option<&Array2<bool>>,
    area_m2: f64,
) -> Option<Rdf> {
    if raw.r_m.len() < 2 {
        return None;
    }
    let bin = raw.r_m[1] - raw.r_m[0];
    let r_max = raw.r_m[raw.r_m.len() - 1] + 0.5 * bin;
    let raw_px: Vec<[f64; 2]> = features.iter().map(|f| [f.x_px, f.y_px]).collect();
    let inside = dhct_distortion::neighbours::inside_mask(&raw_px, mask);
    let points: Vec<[f64; 2]> = corrected
        .iter()
        .zip(inside)
        .filter(|(c, inside)| *inside && c.x_m.is_finite() && c.y_m.is_finite())
        .map(|(c, _)| [c.x_m, c.y_m])
        .collect();
    radial_distribution(&points, area_m2, r_max, bin).ok()
}
