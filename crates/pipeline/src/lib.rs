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
mod error;
mod options;
mod regions;
mod warnings;

pub use affine::AffineComparison;
pub use analysis::{
    Analysis, CorrectionSource, FeatureIndex, PassOutput, RegionFit, SkippedRegion, Stage,
    StageTimings, UnitCellAnalysis,
};
pub use calibration::{
    CORRECTED_ANGLE_TOLERANCE_DEG, CORRECTED_SCALE_TOLERANCE, CalibrationOptions,
    CorrectedImageCheck,
};
pub use error::PipelineError;
pub use options::{CellSelection, PipelineOptions, RegionOptions, UnitCellOptions};
pub use regions::label_regions;
pub use warnings::{
    CALIBRATION_WARNING, DEVIATION_WARNING, INDEXED_WARNING, SCALE_WARNING, UserInput, Warning,
    WarningCode,
};

use std::time::Instant;

use dhct_distortion::{
    CorrectedFeature, DhctResult, DistortionError, PassInput, Rdf, analyse_seeded,
    correct_features, correct_image, radial_distribution,
};
use dhct_features::{Feature, FeatureSet, find_features_in_pair_and_correlation};
use dhct_lattice::{Lattice, angular_distribution, fit_lattice};
use dhct_scan::{ScanPair, ScanPass};
use dhct_unitcell::{
    AveragedCell, ConfidenceEllipse, LocalCell, asymmetric_unit, average_unit_cell, local_cells,
    operations, symmetrize, symmetry_residuals,
};
use ndarray::Array2;
use rayon::prelude::*;

/// Fewest features per image for the chain to start.
pub const MIN_FEATURES: usize = 12;

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
    options.validate()?;
    let geometry = pair.geometry();
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
    let mut timings = StageTimings::default();

    // 0. The lattice the image shows, checked against the inputs.
    progress(Stage::Calibration);
    let t = Instant::now();
    let calibration = calibration::measure(pair, lattice, mask, &options.calibration)?;
    timings.calibration_s = t.elapsed().as_secs_f64();

    // 1. Features (the kernel sized from the lattice's spacing as the image shows it).
    progress(Stage::Features);
    let t = Instant::now();
    let mut feature_options = options.features.clone();
    if !feature_options.neighbour_distance.is_finite() {
        feature_options.neighbour_distance = lattice.nearest_neighbour_distance();
    }
    if let Ok(found) = &calibration {
        feature_options.neighbour_distance *= found.calibration.mean_scale;
    }
    let found = find_features_in_pair_and_correlation(pair, &feature_options, mask)?;
    for (set, _) in &found {
        if set.features.len() < MIN_FEATURES {
            return Err(PipelineError::TooFewFeatures {
                pass: set.pass.to_string(),
                found: set.features.len(),
                needed: MIN_FEATURES,
            });
        }
    }
    timings.features_s = t.elapsed().as_secs_f64();

    // 2. Model.
    progress(Stage::Model);
    let t = Instant::now();
    let inputs: Vec<PassInput> = found
        .iter()
        .map(|(set, _)| PassInput {
            features: &set.features,
            mask,
        })
        .collect();
    let seeded = calibration
        .as_ref()
        .ok()
        .and_then(|found| calibration::seeded_geometry(geometry, found));
    // A model that cannot be fitted (too few features with full neighbour shells: a large
    // cell on a small frame) falls back to the global affine correction when the lattice
    // was measured: never worse than it.
    let (dhct, model_failure) =
        match analyse_seeded(&inputs, geometry, lattice, &options.dhct, seeded.as_ref()) {
            Ok(dhct) => (dhct, None),
            Err(e) => {
                let affine = calibration
                    .as_ref()
                    .ok()
                    .filter(|found| affine::trusted_alone(&found.calibration))
                    .and_then(|found| affine::affine_model(geometry, &found.calibration));
                match affine {
                    Some(model) => (
                        DhctResult {
                            model,
                            passes: Vec::new(),
                        },
                        Some(model_error(e, &found, lattice).to_string()),
                    ),
                    None => return Err(model_error(e, &found, lattice)),
                }
            }
        };
    timings.model_s = t.elapsed().as_secs_f64();

    // 3–4. Features corrected by the model and fitted per region; the global affine
    // correction, fitted the same way, is the floor the model must beat.
    progress(Stage::Correction);
    let t = Instant::now();
    let mut dhct = dhct;
    // The fitted model's weak spots, whichever correction is kept.
    let fit_warnings = warnings::fit_warnings(&dhct);
    let mut rejected_model = None;
    let sets: Vec<&FeatureSet> = found.iter().map(|(s, _)| s).collect();
    let mut corrected_features = correct_sets(&dhct.model, geometry, &sets);
    timings.correction_s = t.elapsed().as_secs_f64();
    progress(Stage::LatticeFit);
    let t = Instant::now();
    let (mut regions, mut skipped_regions) =
        fit_regions(pair, lattice, mask, options, &sets, &corrected_features)?;
    let mut correction = if model_failure.is_some() {
        CorrectionSource::Affine
    } else {
        CorrectionSource::DriftModel
    };
    let mut comparisons = Vec::new();
    if let (Ok(found), None) = (&calibration, &model_failure) {
        let c = &found.calibration;
        comparisons = regions
            .iter()
            .filter_map(|r| affine::compare(r, &sets, geometry, c, lattice, &options.lattice_fit))
            .collect();
        // The largest region decides.
        if comparisons
            .first()
            .is_some_and(AffineComparison::model_is_worse)
            && let Some(model) = affine::affine_model(geometry, c)
        {
            rejected_model = Some(std::mem::replace(&mut dhct.model, model));
            corrected_features = correct_sets(&dhct.model, geometry, &sets);
            (regions, skipped_regions) =
                fit_regions(pair, lattice, mask, options, &sets, &corrected_features)?;
            correction = CorrectionSource::Affine;
        }
    }
    let mut indices: Vec<Vec<Option<FeatureIndex>>> =
        sets.iter().map(|s| vec![None; s.features.len()]).collect();
    for (r, region) in regions.iter().enumerate() {
        for (k, members) in region.members.iter().enumerate() {
            let pass_slot = sets
                .iter()
                .position(|s| s.pass == region.passes[k])
                .expect("region sets are passes of the pair");
            for (point, &feature) in region.fit.points[k].iter().zip(members) {
                indices[pass_slot][feature] = Some(FeatureIndex {
                    region: r,
                    n: point.n,
                    m: point.m,
                    site: point.site,
                    deviation_m: point.deviation_m,
                });
            }
        }
    }
    timings.lattice_fit_s = t.elapsed().as_secs_f64();

    // The images, with the correction chosen.
    let t = Instant::now();
    let images: Vec<Array2<f64>> = sets
        .par_iter()
        .map(|set| {
            let image = pair
                .image(set.pass)
                .expect("features were found in this image");
            correct_image(&dhct.model, geometry, set.pass, &image.z).map_err(PipelineError::from)
        })
        .collect::<Result<_, _>>()?;
    timings.correction_s += t.elapsed().as_secs_f64();
    // The corrected images measured as an outside check would measure them.
    let t = Instant::now();
    let image_checks = if calibration.is_ok() {
        let passes: Vec<(ScanPass, &Array2<f64>)> =
            sets.iter().map(|s| s.pass).zip(images.iter()).collect();
        calibration::check_corrected(&passes, geometry, lattice)
    } else {
        Vec::new()
    };
    timings.calibration_s += t.elapsed().as_secs_f64();
    let corrected: Vec<(Vec<CorrectedFeature>, Array2<f64>)> =
        corrected_features.into_iter().zip(images).collect();

    // 5. Unit cells.
    progress(Stage::UnitCells);
    let t = Instant::now();
    let corrected_images: Vec<&Array2<f64>> = corrected.iter().map(|(_, z)| z).collect();
    let (unit_cell, unit_cell_note) =
        match unit_cell_analysis(pair, lattice, options, &sets, &regions, &corrected_images) {
            Ok(analysis) => (Some(analysis), None),
            Err(note) => (None, Some(note)),
        };
    timings.unit_cells_s = t.elapsed().as_secs_f64();

    // RDF of the corrected features on the raw RDF's bins (paper Fig. 6).
    let area = mask
        .map(|m| m.iter().filter(|&&v| v).count() as f64)
        .unwrap_or((geometry.rows() * geometry.columns()) as f64)
        * geometry.pitch_x()
        * geometry.pitch_y();
    let passes: Vec<PassOutput> = found
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
                correlation: options.keep_correlation.then_some(correlation),
                corrected,
                corrected_image: image,
                indices,
                rdf_corrected,
            }
        })
        .collect();
    let mut warnings = warnings::calibration_warnings(&calibration);
    warnings.extend(warnings::assumption_warnings(geometry));
    warnings.extend(fit_warnings);
    warnings.extend(model_failure.map(warnings::model_failure_warning));
    warnings.extend(warnings::affine_warnings(
        &comparisons,
        correction == CorrectionSource::Affine,
    ));
    warnings.extend(warnings::plausibility_warnings(lattice, &regions, &passes));
    warnings.extend(warnings::corrected_image_warnings(lattice, &image_checks));
    timings.total_s = start.elapsed().as_secs_f64();
    Ok(Analysis {
        passes,
        dhct,
        regions,
        skipped_regions,
        unit_cell,
        unit_cell_note,
        calibration,
        affine: comparisons,
        correction,
        rejected_model,
        corrected_images: image_checks,
        warnings,
        timings,
    })
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
    found: &[(FeatureSet, Array2<f64>)],
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

fn found_sets_first(found: &[(FeatureSet, Array2<f64>)]) -> &FeatureSet {
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

/// Whether the raw-frame position `(x, y)` px lies in region `label` with every point at
/// `margin_px` around it too (8 directions).
fn inside_region(
    labels: &Array2<Option<u32>>,
    label: u32,
    x: f64,
    y: f64,
    margin_px: [f64; 2],
) -> bool {
    let (rows, columns) = labels.dim();
    let at = |x: f64, y: f64| {
        let (c, r) = (x.round(), y.round());
        c >= 0.0
            && r >= 0.0
            && (c as usize) < columns
            && (r as usize) < rows
            && labels[[r as usize, c as usize]] == Some(label)
    };
    const D: f64 = std::f64::consts::FRAC_1_SQRT_2;
    const DIRECTIONS: [(f64, f64); 9] = [
        (0.0, 0.0),
        (1.0, 0.0),
        (-1.0, 0.0),
        (0.0, 1.0),
        (0.0, -1.0),
        (D, D),
        (-D, D),
        (D, -D),
        (-D, -D),
    ];
    DIRECTIONS
        .iter()
        .all(|(dx, dy)| at(x + dx * margin_px[0], y + dy * margin_px[1]))
}

fn fit_regions(
    pair: &ScanPair,
    lattice: &dyn Lattice,
    mask: Option<&Array2<bool>>,
    options: &PipelineOptions,
    sets: &[&FeatureSet],
    corrected: &[Vec<CorrectedFeature>],
) -> Result<(Vec<RegionFit>, Vec<SkippedRegion>), PipelineError> {
    let geometry = pair.geometry();
    let (labels, sizes) = match mask {
        Some(mask) => label_regions(mask),
        None => (
            Array2::from_elem((geometry.rows(), geometry.columns()), Some(0)),
            vec![geometry.rows() * geometry.columns()],
        ),
    };
    let nn = lattice.nearest_neighbour_distance();
    let margin_px = if mask.is_some() {
        let m = options.regions.edge_margin_nn * nn;
        [m / geometry.pitch_x(), m / geometry.pitch_y()]
    } else {
        [0.0, 0.0]
    };
    let mut fits = Vec::new();
    let mut skipped = Vec::new();
    let mut first_error = None;
    for (region, &pixels) in sizes.iter().enumerate() {
        let label = region as u32;
        let members: Vec<Vec<usize>> = sets
            .iter()
            .zip(corrected)
            .map(|(set, corrected)| {
                (0..set.features.len())
                    .filter(|&i| {
                        let f: &Feature = &set.features[i];
                        corrected[i].x_m.is_finite()
                            && corrected[i].y_m.is_finite()
                            && inside_region(&labels, label, f.x_px, f.y_px, margin_px)
                    })
                    .collect()
            })
            .collect();
        let count = members[0].len();
        if count < options.regions.min_features {
            skipped.push(SkippedRegion {
                region,
                pixels,
                features: count,
                reason: format!(
                    "{count} features inside (at least {} needed)",
                    options.regions.min_features
                ),
            });
            continue;
        }
        // Retrace sets with too few features are left out of the joint fit.
        let usable: Vec<usize> = (0..sets.len())
            .filter(|&k| k == 0 || members[k].len() >= options.regions.min_features)
            .collect();
        let points: Vec<Vec<[f64; 2]>> = usable
            .iter()
            .map(|&k| {
                members[k]
                    .iter()
                    .map(|&i| [corrected[k][i].x_m, corrected[k][i].y_m])
                    .collect()
            })
            .collect();
        let refs: Vec<&[[f64; 2]]> = points.iter().map(|p| p.as_slice()).collect();
        let fit = match fit_lattice(lattice, &refs, &options.lattice_fit) {
            Ok(fit) => fit,
            Err(e) => {
                skipped.push(SkippedRegion {
                    region,
                    pixels,
                    features: count,
                    reason: e.to_string(),
                });
                first_error.get_or_insert(e);
                continue;
            }
        };
        let members: Vec<Vec<usize>> = usable.iter().map(|&k| members[k].clone()).collect();
        let passes: Vec<ScanPass> = usable.iter().map(|&k| sets[k].pass).collect();
        let mut deviations = Vec::new();
        let mut heights = Vec::new();
        for (k, set_members) in members.iter().enumerate() {
            for (point, &i) in fit.points[k].iter().zip(set_members) {
                deviations.push(point.deviation_m);
                heights.push(sets[usable[k]].features[i].height);
            }
        }
        let whole_ellipse = ConfidenceEllipse::from_deviations(&deviations, Some(&heights))?;
        let cells: Vec<Vec<LocalCell>> = (0..points.len())
            .map(|k| local_cells(lattice, &fit, &points[k], k))
            .collect();
        let local: Vec<[f64; 2]> = cells
            .iter()
            .flatten()
            .flat_map(|c| c.deviations_m)
            .collect();
        let local_ellipse = ConfidenceEllipse::from_deviations(&local, None).ok();
        let adf =
            angular_distribution(lattice, &points[0], options.lattice_fit.nn_window, 180).ok();
        fits.push(RegionFit {
            region,
            pixels,
            fit,
            passes,
            members,
            whole_ellipse,
            local_cells: cells,
            local_ellipse,
            adf,
        });
    }
    if fits.is_empty() {
        return Err(match first_error {
            Some(e) => PipelineError::LatticeFit(e),
            None => PipelineError::TooFewFeatures {
                pass: if mask.is_some() {
                    "largest mask region of the trace".into()
                } else {
                    "trace".into()
                },
                found: skipped.iter().map(|s| s.features).max().unwrap_or(0),
                needed: options.regions.min_features,
            },
        });
    }
    Ok((fits, skipped))
}

/// Median and robust standard deviation (1.4826 × MAD).
fn robust_location(values: &[f64]) -> (f64, f64) {
    use dhct_numerics::robust::{finite_median, mad_sigma_about};
    match finite_median(values.iter().copied()) {
        Some(median) => (median, mad_sigma_about(values, median).unwrap_or(f64::NAN)),
        None => (f64::NAN, f64::NAN),
    }
}

/// Whether a cell's corner features pass the selection.
fn keep_cell(
    cell: &LocalCell,
    features: &[Feature],
    members: &[usize],
    selection: &CellSelection,
    height_stats: (f64, f64),
    width_stats: (f64, f64),
) -> bool {
    cell.corners.iter().all(|&corner| {
        let f = &features[members[corner]];
        let in_range =
            |range: Option<[f64; 2]>, v: f64| range.is_none_or(|[lo, hi]| v >= lo && v <= hi);
        let typical = |stats: (f64, f64), v: f64, k: f64| {
            stats.1.is_nan() || stats.1 <= 0.0 || (v - stats.0).abs() <= k * stats.1
        };
        in_range(selection.height_m, f.height)
            && in_range(selection.width_px, f.sigma_major_px)
            && selection.exclude_outliers_sigma.is_none_or(|k| {
                typical(height_stats, f.height, k) && typical(width_stats, f.sigma_major_px, k)
            })
    })
}

fn unit_cell_analysis(
    pair: &ScanPair,
    lattice: &dyn Lattice,
    options: &PipelineOptions,
    sets: &[&FeatureSet],
    regions: &[RegionFit],
    corrected_images: &[&Array2<f64>],
) -> Result<UnitCellAnalysis, String> {
    let geometry = pair.geometry();
    let selection = &options.unit_cell.selection;
    let mut available = 0;
    let mut averages: Vec<AveragedCell> = Vec::new();
    for (slot, set) in sets.iter().enumerate() {
        let heights: Vec<f64> = set.features.iter().map(|f| f.height).collect();
        let widths: Vec<f64> = set.features.iter().map(|f| f.sigma_major_px).collect();
        let (height_stats, width_stats) = (robust_location(&heights), robust_location(&widths));
        let mut kept = Vec::new();
        for region in regions {
            let Some(k) = region.passes.iter().position(|&p| p == set.pass) else {
                continue;
            };
            available += region.local_cells[k].len();
            kept.extend(
                region.local_cells[k]
                    .iter()
                    .filter(|cell| {
                        keep_cell(
                            cell,
                            &set.features,
                            &region.members[k],
                            selection,
                            height_stats,
                            width_stats,
                        )
                    })
                    .cloned(),
            );
        }
        if kept.is_empty() {
            continue;
        }
        match average_unit_cell(
            corrected_images[slot].view(),
            (geometry.pitch_x(), geometry.pitch_y()),
            lattice,
            &kept,
            options.unit_cell.resolution,
        ) {
            Ok(average) => averages.push(average),
            Err(e) => return Err(format!("averaging the {} cells failed: {e}", set.pass)),
        }
    }
    if averages.is_empty() {
        return Err(format!(
            "no local cell was selected ({available} found): every cell needs its four corner \
             features indexed{}",
            if available > 0 {
                "; loosen the cell selection"
            } else {
                ""
            }
        ));
    }
    // Cell-count weighted mean of the per-image averages.
    let cells: usize = averages.iter().map(|a| a.cells).sum();
    let skipped: usize = averages.iter().map(|a| a.skipped).sum();
    let mut values = Array2::zeros(averages[0].values.dim());
    for a in &averages {
        values.scaled_add(a.cells as f64 / cells as f64, &a.values);
    }
    let averaged = AveragedCell {
        values,
        cells,
        skipped,
    };
    let group = options
        .unit_cell
        .plane_group
        .unwrap_or_else(|| lattice.plane_group());
    let ops = operations(group, lattice).map_err(|e| e.to_string())?;
    let symmetrized = symmetrize(&averaged, &ops).map_err(|e| e.to_string())?;
    let residuals = symmetry_residuals(&averaged, lattice).map_err(|e| e.to_string())?;
    let asymmetric_unit = asymmetric_unit(group, lattice).map_err(|e| e.to_string())?;
    Ok(UnitCellAnalysis {
        group,
        averaged,
        symmetrized,
        residuals,
        asymmetric_unit,
        cells_available: available,
        cells_selected: cells,
    })
}
