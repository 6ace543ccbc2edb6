//! Which fit the model comes from: the paper's local-distortion route or the global
//! registration ([`crate::registration`]), chosen by cross-validation on the image's own
//! features. Folds are interleaved bands of lines one NN distance high, so every fold spans
//! the whole frame in time; each route is fitted without a fold, the lattice is placed on
//! the features it was fitted to, and the fold's features are scored by their deviation from
//! that lattice. The route with the smaller held-out deviation is the better one (the
//! local route keeps ties within [`GLOBAL_MARGIN`]); whether it is used depends on the
//! [`RoutePolicy`].

use dhct_scan::ScanGeometry;
use serde::{Deserialize, Serialize};

use crate::fit::{FitOptions, fit_model};
use crate::registration::{
    RegisteredFeature, Registration, StartQuality, deviations, place_lattice, register,
};
use crate::thinning::thin;
use crate::{DistortionError, DistortionModel, LocalDistortion};

/// Number of cross-validation folds.
pub const FOLDS: usize = 3;

/// The global registration replaces the local route only when its held-out deviation is
/// below this fraction of the local route's.
pub const GLOBAL_MARGIN: f64 = 0.97;

/// Most features (registered positions, or local distortions) a fold's fit of either route
/// uses (evenly thinned beyond): the comparison is of the routes' form, and both see about
/// as many features.
pub const MAX_FOLD_FEATURES: usize = 1500;

/// Huber rounds of the folds' fits (the full fits use the options').
const FOLD_ROBUST_ROUNDS: usize = 2;

/// A held-out deviation is capped at this fraction of the NN distance (a mis-indexed
/// feature weighs no more than a half-way one, for either route).
const DEVIATION_CAP: f64 = 0.3;

/// Which fit produced the model.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ModelRoute {
    /// Local distortions from each feature's neighbour shell, then the model (the paper).
    LocalDistortion,
    /// Every indexed feature's position against the ideal lattice.
    GlobalRegistration,
}

/// Which route's model is used.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RoutePolicy {
    /// The route that cross-validates better (the default). On real files it has been the
    /// registration where the two differ (Pb/Pt(111): the corrected image's lattice 1.0013
    /// instead of 1.0101 of the constant along y).
    #[default]
    CrossValidated,
    /// The paper's local route; the global registration only when the local route cannot
    /// fit a model. Both are still compared and reported. A smooth global model can absorb
    /// part of an event outside it (a tip change's jump, as a creep of nanometres) and so fit
    /// positions better while describing the scan worse; the local route, measuring
    /// derivatives, does not, which is why the diagnosis's base model is fitted this way.
    Local,
    /// The paper's local route alone: the global registration is not fitted (only when the
    /// local route cannot fit a model). The cheapest; a series of frames uses it for each
    /// frame's own model, which only starts the series fit.
    LocalOnly,
}

/// Both routes' cross-validated deviations and the one chosen.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RouteComparison {
    /// The route whose model is used.
    pub chosen: ModelRoute,
    /// The route with the smaller held-out deviation.
    pub better: ModelRoute,
    /// Held-out RMS deviation from the ideal lattice, local route, metres (NaN when a fold
    /// could not be fitted).
    pub local_held_out_rms_m: f64,
    /// Held-out RMS deviation from the ideal lattice, global registration, metres.
    pub global_held_out_rms_m: f64,
    /// Folds.
    pub folds: usize,
    /// Registered features scored.
    pub features: usize,
    /// The global registration fitted to every feature.
    pub registration: Registration,
}

/// The fold of a feature at controller row position `y_m` (metres): bands `band_m` high.
fn fold_of(y_m: f64, band_m: f64) -> usize {
    ((y_m / band_m).floor().max(0.0) as usize) % FOLDS
}

/// Cross-validates the local route (refitted from `local` without each fold) against the
/// global registration (refitted from `features` without each fold, started from
/// `registration`), and chooses the route by `policy` (no local distortions: the
/// registration). `band_m` is the fold band height (the NN distance), metres.
pub fn compare_routes(
    local: &[LocalDistortion],
    features: &[RegisteredFeature],
    registration: Registration,
    geometry: &ScanGeometry,
    band_m: f64,
    options: &FitOptions,
    policy: RoutePolicy,
) -> Result<RouteComparison, DistortionError> {
    let passes = registration.origins_m.len();
    let cap2 = (DEVIATION_CAP * band_m).powi(2);
    let mut sums = [0.0f64; 2];
    let mut counts = [0usize; 2];
    for fold in 0..FOLDS {
        let (train, test): (Vec<RegisteredFeature>, Vec<RegisteredFeature>) = features
            .iter()
            .partition(|f| fold_of(f.controller_m[1], band_m) != fold);
        if test.is_empty() || train.is_empty() {
            continue;
        }
        let training_local: Vec<LocalDistortion> = local
            .iter()
            .filter(|l| fold_of(l.y_px * geometry.pitch_y(), band_m) != fold)
            .cloned()
            .collect();
        // The folds refit the law family the whole data chose.
        let fold_options = FitOptions {
            robust_rounds: options.robust_rounds.min(FOLD_ROBUST_ROUNDS),
            hysteresis: options.hysteresis.resolved(&registration.model.hysteresis),
            ..*options
        };
        let local_model = fit_model(
            &thin(&training_local, MAX_FOLD_FEATURES),
            geometry.frame_duration(),
            geometry.line_scan_time(),
            &fold_options,
        );
        let thinned = thin(&train, MAX_FOLD_FEATURES);
        let fitted = StartQuality::Fitted;
        let start = &registration.model;
        let global_model = register(&thinned, geometry, start, fitted, &fold_options);
        for (route, model) in [local_model.ok(), global_model.ok().map(|g| g.model)]
            .into_iter()
            .enumerate()
        {
            let Some(model) = model else {
                sums[route] = f64::NAN;
                continue;
            };
            sums[route] += held_out_squares(&model, &train, &test, geometry, passes, cap2);
            counts[route] += test.len();
        }
    }
    let rms = |k: usize| (sums[k] / counts[k].max(1) as f64).sqrt();
    let (local_rms, global_rms) = (rms(0), rms(1));
    let better = if global_rms < GLOBAL_MARGIN * local_rms
        || (local_rms.is_nan() && global_rms.is_finite())
    {
        ModelRoute::GlobalRegistration
    } else {
        ModelRoute::LocalDistortion
    };
    let chosen = match policy {
        RoutePolicy::CrossValidated => better,
        RoutePolicy::Local if local.is_empty() => ModelRoute::GlobalRegistration,
        RoutePolicy::Local | RoutePolicy::LocalOnly => ModelRoute::LocalDistortion,
    };
    Ok(RouteComparison {
        chosen,
        better,
        local_held_out_rms_m: local_rms,
        global_held_out_rms_m: global_rms,
        folds: FOLDS,
        features: features.len(),
        registration,
    })
}

/// The sum of squared deviations (metres², each capped at `cap2`) of `test` corrected by
/// `model` from the lattice placed on `train` corrected by `model`.
fn held_out_squares(
    model: &DistortionModel,
    train: &[RegisteredFeature],
    test: &[RegisteredFeature],
    geometry: &ScanGeometry,
    passes: usize,
    cap2: f64,
) -> f64 {
    let corrected: Vec<[f64; 2]> = train
        .iter()
        .map(|f| crate::registration::corrected_position(f, model, geometry))
        .collect();
    let (theta, origins) = place_lattice(train, &corrected, passes);
    deviations(test, model, geometry, theta, &origins)
        .iter()
        .map(|d| (d[0] * d[0] + d[1] * d[1]).min(cap2))
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn folds_interleave_bands_of_lines() {
        let band = 2.5e-10;
        let folds: Vec<usize> = (0..2 * FOLDS)
            .map(|k| fold_of((k as f64 + 0.5) * band, band))
            .collect();
        let expected: Vec<usize> = (0..2 * FOLDS).map(|k| k % FOLDS).collect();
        assert_eq!(folds, expected);
        assert_eq!(fold_of(-1e-9, band), 0);
    }
}
