//! The sub-feature view of a scanned pair: the images the slices are read from, built the
//! same way for `dhct diagnose`, `dhct correct --diagnose` and the image-path validation.

use dhct_features::{FeatureOptions, FeatureSet, signed_flattened};
use dhct_scan::ScanPair;
use ndarray::Array2;

use crate::DiagnosisReport;
use crate::base::PassLevelling;
use crate::sub_feature::{PassImage, SubFeatureView, sub_feature_view};

/// `report` (of the features `sets`, found in `pair` with `options`) with what only the
/// images show: each image's line levelling and the view below one feature
/// ([`sub_feature_view_of_pair`]).
pub fn with_pair_views(
    mut report: DiagnosisReport,
    pair: &ScanPair,
    sets: &[&FeatureSet],
    options: &FeatureOptions,
    mask: Option<&Array2<bool>>,
) -> DiagnosisReport {
    report.base_choice.line_levelling = PassLevelling::of_sets(sets);
    match sub_feature_view_of_pair(pair, sets, options, mask) {
        Some(view) => report.with_sub_feature_view(view),
        None => report,
    }
}

/// The sub-feature view of `pair`, whose passes' features are `sets` (found with
/// `options`, background fitted where `mask` is true). Each pass's image is its raw
/// image with the background removed and the features made positive, every line's level
/// kept ([`signed_flattened`]); a pass whose image cannot be so prepared is left out.
/// `None` when too few slices can be measured.
pub fn sub_feature_view_of_pair(
    pair: &ScanPair,
    sets: &[&FeatureSet],
    options: &FeatureOptions,
    mask: Option<&Array2<bool>>,
) -> Option<SubFeatureView> {
    let images: Vec<(&FeatureSet, Array2<f64>)> = sets
        .iter()
        .filter_map(|set| {
            let raw = &pair.image(set.pass)?.z;
            Some((*set, signed_flattened(raw, options, mask).ok()?))
        })
        .collect();
    let passes: Vec<PassImage> = images
        .iter()
        .map(|(set, image)| PassImage {
            pass: set.pass,
            image: image.view(),
            features: &set.features,
        })
        .collect();
    sub_feature_view(&passes, pair.geometry())
}
