//! The image views of a scanned pair: the images the slices and the residual images are
//! read from, built the same way for `dhct diagnose`, `dhct correct --diagnose` and the
//! image-path validation.

use dhct_features::{FeatureOptions, FeatureSet, signed_flattened};
use dhct_scan::{ScanGeometry, ScanPair};
use ndarray::{Array2, ArrayView2};

use crate::DiagnosisReport;
use crate::image_view::image_residual::{ResidualImage, residual_images};
use crate::image_view::sub_feature::{PassImage, SubFeatureView, sub_feature_view};
use crate::model::base::PassLevelling;

/// `report` (of the features `sets`, found in `pair` with `options`) with what only the
/// images show ([`pair_views`]), the residual images themselves dropped.
pub fn with_pair_views(
    report: DiagnosisReport,
    pair: &ScanPair,
    sets: &[&FeatureSet],
    options: &FeatureOptions,
    mask: Option<&Array2<bool>>,
) -> DiagnosisReport {
    pair_views(report, pair, sets, options, mask).0
}

/// `report` (of the features `sets`, found in `pair` with `options`) with what only the
/// images show: each image's line levelling, the view below one feature
/// ([`sub_feature_view`]) and the final model rendered forward and compared with each
/// image ([`crate::PassResidual`]); and the residual images.
pub fn pair_views(
    mut report: DiagnosisReport,
    pair: &ScanPair,
    sets: &[&FeatureSet],
    options: &FeatureOptions,
    mask: Option<&Array2<bool>>,
) -> (DiagnosisReport, Vec<ResidualImage>) {
    report.base_choice.line_levelling = PassLevelling::of_sets(sets);
    let images = flattened_images(pair, sets, options, mask);
    let sets: Vec<&FeatureSet> = images.iter().map(|(set, _)| *set).collect();
    let views: Vec<ArrayView2<f64>> = images.iter().map(|(_, image)| image.view()).collect();
    let with_units: Vec<(ArrayView2<f64>, &str)> = sets
        .iter()
        .zip(&views)
        .map(|(set, view)| {
            let unit = pair.image(set.pass).map_or("", |c| c.unit.as_str());
            (*view, unit)
        })
        .collect();
    let residuals = residual_images(
        &sets,
        &with_units,
        &report.residuals,
        pair.geometry(),
        options.neighbour_distance,
    );
    let report = report.with_image_residual(residuals.iter().map(|r| r.summary.clone()).collect());
    let report = match slice_view(&sets, &views, pair.geometry()) {
        Some(view) => report.with_sub_feature_view(view),
        None => report,
    };
    (report, residuals)
}

/// The sub-feature view of `pair`, whose passes' features are `sets` (found with
/// `options`, background fitted where `mask` is true). `None` when too few slices can be
/// measured.
pub fn sub_feature_view_of_pair(
    pair: &ScanPair,
    sets: &[&FeatureSet],
    options: &FeatureOptions,
    mask: Option<&Array2<bool>>,
) -> Option<SubFeatureView> {
    let images = flattened_images(pair, sets, options, mask);
    let sets: Vec<&FeatureSet> = images.iter().map(|(set, _)| *set).collect();
    let views: Vec<ArrayView2<f64>> = images.iter().map(|(_, image)| image.view()).collect();
    slice_view(&sets, &views, pair.geometry())
}

/// Each pass's raw image with the background removed and the features made positive,
/// every line's level kept ([`signed_flattened`]), with its features; a pass whose image
/// cannot be so prepared is left out.
fn flattened_images<'a>(
    pair: &ScanPair,
    sets: &[&'a FeatureSet],
    options: &FeatureOptions,
    mask: Option<&Array2<bool>>,
) -> Vec<(&'a FeatureSet, Array2<f64>)> {
    sets.iter()
        .filter_map(|set| {
            let raw = &pair.image(set.pass)?.z;
            Some((*set, signed_flattened(raw, options, mask).ok()?))
        })
        .collect()
}

/// The slices' view of the passes `sets` with their flattened `images`.
fn slice_view(
    sets: &[&FeatureSet],
    images: &[ArrayView2<f64>],
    geometry: &ScanGeometry,
) -> Option<SubFeatureView> {
    let passes: Vec<PassImage> = sets
        .iter()
        .zip(images)
        .map(|(set, image)| PassImage {
            pass: set.pass,
            image: *image,
            features: &set.features,
        })
        .collect();
    sub_feature_view(&passes, geometry)
}
