//! Shared by the feature tests against simulator ground truth.

use dhct_features::{Feature, FeatureSet};
use dhct_scan::ScanPass;
use dhct_simulate::{GroundTruth, SimulationConfig, presets};

/// The headline preset cut to 512 × 512 px at the same pixel pitch (12.2 pm).
pub fn headline_512() -> SimulationConfig {
    let mut config = presets::headline_2048();
    config.scan.columns = 512;
    config.scan.rows = 512;
    config.scan.width_m = 25e-9 / 4.0;
    config.scan.height_m = 25e-9 / 4.0;
    config
}

/// Each feature of `set` matched (within 1 px) to the nearest true controller position of
/// its pass, with its error `[dx, dy]` px.
#[allow(dead_code)] // not every test file that shares this module matches features
pub fn matched_errors<'a>(
    set: &'a FeatureSet,
    truth: &GroundTruth,
) -> Vec<(&'a Feature, [f64; 2])> {
    let mut out = Vec::new();
    for f in &set.features {
        let distance = |p: &[f64; 2]| (p[0] - f.x_px).hypot(p[1] - f.y_px);
        let nearest = truth
            .features
            .iter()
            .map(|t| match set.pass {
                ScanPass::Trace => t.trace.controller_position_px,
                ScanPass::Retrace => t.retrace.controller_position_px,
            })
            .min_by(|a, b| distance(a).total_cmp(&distance(b)))
            .expect("atoms");
        if distance(&nearest) < 1.0 {
            out.push((f, [f.x_px - nearest[0], f.y_px - nearest[1]]));
        }
    }
    assert!(out.len() > 300, "{} features matched", out.len());
    out
}
