//! The global affine correction as a floor: the calibration's `K⁻¹` applied to the raw
//! positions, fitted by the same whole-image lattice fit as the full model's corrected
//! positions, so both are judged by one regularity measure (the rms deviation of the
//! region's features from their fitted lattice, and how many the fit could use).

use dhct_calibrate::Calibration;
use dhct_distortion::{DistortionModel, SeedMap};
use dhct_features::FeatureSet;
use dhct_lattice::{Lattice, LatticeFitOptions, fit_lattice};
use dhct_scan::ScanGeometry;
use serde::{Deserialize, Serialize};

use crate::RegionFit;

/// One region's full model against the global affine correction.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct AffineComparison {
    /// Region (index into the analysis' regions).
    pub region: usize,
    /// RMS deviation from the fitted lattice after the full model, metres.
    pub model_rms_m: f64,
    /// The same after the global affine correction, metres.
    pub affine_rms_m: f64,
    /// Points the full model's lattice fit used.
    pub model_used: usize,
    /// Points the affine lattice fit used.
    pub affine_used: usize,
    /// The lattice fit's scales `s_x`, `s_y` after the full model.
    pub model_scale: [f64; 2],
    /// The same after the affine correction.
    pub affine_scale: [f64; 2],
}

/// A model whose lattice fit uses fewer than this fraction of the points the affine fit
/// uses is worse, whatever its rms.
const MIN_USED_FRACTION: f64 = 0.9;

/// The affine correction fits a region's features as well as the model when its rms
/// deviation is at most this many times the model's (the HOPG terrace file: 40.2 vs
/// 39.3 pm; a scan drifting at 30 % of the slow speed: the model at the floor, the affine
/// map 30 × above it).
const AS_GOOD_RATIO: f64 = 1.1;

impl AffineComparison {
    /// Whether the global affine correction fits the region's features about as well as
    /// the model ([`AS_GOOD_RATIO`]): the model then gains nothing there that its corrected
    /// image would have to confirm.
    pub fn affine_is_as_good(&self) -> bool {
        self.affine_rms_m <= AS_GOOD_RATIO * self.model_rms_m
    }

    /// Whether the full model does worse than the global affine correction: a larger rms
    /// deviation, markedly fewer usable points, or a lattice scale farther from 1.
    pub fn model_is_worse(&self) -> bool {
        let scale_error = |s: [f64; 2]| (s[0] - 1.0).abs().max((s[1] - 1.0).abs());
        self.model_rms_m > self.affine_rms_m
            || (self.model_used as f64) < MIN_USED_FRACTION * self.affine_used as f64
            || scale_error(self.model_scale) > scale_error(self.affine_scale).max(0.015)
    }
}

/// Fits the region's features (raw positions mapped by `K⁻¹`) and compares with the full
/// model's fit of the same features. `None` when the affine points cannot be fitted.
pub(crate) fn compare(
    region: &RegionFit,
    sets: &[&FeatureSet],
    geometry: &ScanGeometry,
    calibration: &Calibration,
    lattice: &dyn Lattice,
    options: &LatticeFitOptions,
) -> Option<AffineComparison> {
    let [[a, b], [c, d]] = calibration.file_to_sample();
    let points: Vec<Vec<[f64; 2]>> = region
        .passes
        .iter()
        .zip(&region.members)
        .map(|(pass, members)| {
            let set = sets.iter().find(|s| s.pass == *pass)?;
            Some(
                members
                    .iter()
                    .map(|&i| {
                        let f = &set.features[i];
                        let (x, y) = (f.x_px * geometry.pitch_x(), f.y_px * geometry.pitch_y());
                        [a * x + b * y, c * x + d * y]
                    })
                    .collect(),
            )
        })
        .collect::<Option<_>>()?;
    let refs: Vec<&[[f64; 2]]> = points.iter().map(|p| p.as_slice()).collect();
    let affine = fit_lattice(lattice, &refs, options).ok()?;
    Some(AffineComparison {
        region: region.region,
        model_rms_m: region.fit.rms_deviation_m,
        affine_rms_m: affine.rms_deviation_m,
        model_used: region.fit.used,
        affine_used: affine.used,
        model_scale: region.fit.scale,
        affine_scale: affine.scale,
    })
}

/// Largest anisotropy of a calibration the affine correction may stand in for a model that
/// could not be fitted: beyond it the image is distorted more than drift and a miscalibrated
/// head commonly do, and a lattice matched that far is not to be trusted without the model.
pub const ALONE_MAX_ANISOTROPY: f64 = 1.4;

/// Largest shear (degrees) of such a calibration.
pub const ALONE_MAX_SHEAR_DEG: f64 = 12.0;

/// Whether the affine correction of `calibration` may stand alone (no drift model).
pub(crate) fn trusted_alone(calibration: &Calibration) -> bool {
    calibration.anisotropy <= ALONE_MAX_ANISOTROPY
        && calibration.shear_deg.abs() <= ALONE_MAX_SHEAR_DEG
}

/// The global affine correction `K⁻¹` as a distortion model ([`SeedMap::as_model`]), to
/// correct images with when it beats the full model.
pub(crate) fn affine_model(
    geometry: &ScanGeometry,
    calibration: &Calibration,
) -> Option<DistortionModel> {
    SeedMap::new(calibration.matrix)?.as_model(geometry)
}

#[cfg(test)]
mod tests {
    use super::*;
    use dhct_scan::{ScanDirection, ScanPass};

    #[test]
    fn the_affine_model_maps_controller_positions_by_k_inverse() {
        for slow in [ScanDirection::Down, ScanDirection::Up] {
            let geometry =
                ScanGeometry::new(64, 48, 1e-10, 1.2e-10, 1e-3, ScanDirection::Right, slow)
                    .unwrap();
            let mut calibration = Calibration::identity();
            calibration.scale = [1.25, 0.8];
            calibration.matrix = [[1.25, 0.1], [0.0, 0.8]];
            let model = affine_model(&geometry, &calibration).unwrap();
            let [[a, b], [c, d]] = calibration.file_to_sample();
            let map = |pass, x: f64, y: f64| model.to_sample(&geometry, pass, x, y);
            for pass in [ScanPass::Trace, ScanPass::Retrace] {
                let origin = map(pass, 0.0, 0.0);
                for (x, y) in [(10.0, 0.0), (0.0, 20.0), (40.0, 30.0)] {
                    let p = map(pass, x, y);
                    let (xm, ym) = (x * 1e-10, y * 1.2e-10);
                    let expected = [a * xm + b * ym, c * xm + d * ym];
                    let within_line = 0.5 * (1.0 / 0.8 - 1.0) * 1.2e-10 + 1e-13;
                    for k in 0..2 {
                        let error = (p[k] - origin[k] - expected[k]).abs();
                        assert!(
                            error <= within_line,
                            "{slow:?} {pass:?} ({x}, {y}) axis {k}: {error:e}"
                        );
                    }
                }
            }
        }
    }
}
