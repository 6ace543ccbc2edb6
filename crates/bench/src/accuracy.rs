//! Accuracy of one pipeline run against the simulator's ground truth.
//!
//! Found features are matched to the true feature whose controller-frame position (where
//! that pass imaged it) is nearest, within 0.3 nearest-neighbour distances. Only features
//! at least [`EDGE_MARGIN_NN`] NN distances from the image border are compared (edge-cut
//! features are not fitted on a full disc).

use dhct_lattice::Lattice;
use dhct_numerics::moments::rms_about_mean;
use dhct_pipeline::Analysis;
use dhct_scan::{ScanGeometry, ScanPass};
use dhct_simulate::GroundTruth;
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use serde::Serialize;

/// Features closer than this many NN distances to the border are not compared.
pub const EDGE_MARGIN_NN: f64 = 1.5;

/// Largest distance from a found feature to its true controller position that still
/// counts as a match, in NN distances.
pub const MATCH_RADIUS_NN: f64 = 0.3;

/// Accuracy of one run (both passes pooled).
#[derive(Debug, Clone, Serialize)]
pub struct Accuracy {
    /// Features found away from the border (both passes).
    pub found: usize,
    /// Of those, matched to a true feature.
    pub matched: usize,
    /// True features imaged away from the border (both passes).
    pub truth_in_image: usize,
    /// `matched / truth_in_image`.
    pub recall: f64,
    /// Per-axis rms of found − true controller position, pixels.
    pub feature_rms_px: f64,
    /// The same along x (fast axis) and y (slow axis) separately, pixels.
    pub feature_rms_xy_px: [f64; 2],
    /// Per-axis rms of the fits' own 1σ position uncertainties (the Cramér–Rao bound
    /// evaluated at the fitted parameters with the fit's residual noise), pixels.
    pub crlb_px: f64,
    /// `feature_rms_px / crlb_px`.
    pub feature_rms_over_crlb: f64,
    /// Per-axis CRLB for the simulated feature shape under the simulated white noise alone
    /// (an isolated Gaussian; see [`crate::crlb`]), pixels. NaN without white noise or for
    /// molecule-like features.
    pub crlb_white_px: f64,
    /// `feature_rms_px / crlb_white_px`.
    pub feature_rms_over_crlb_white: f64,
    /// 2-D rms of found − true controller position (localisation noise floor), metres.
    pub noise_floor_m: f64,
    /// 2-D rms of raw position − true sample position after one translation, metres.
    pub uncorrected_rms_m: f64,
    /// 2-D rms of DHCT-corrected − true sample position after one translation, metres.
    pub corrected_rms_m: f64,
    /// `corrected_rms_m / noise_floor_m`.
    pub corrected_over_floor: f64,
    /// Features given a lattice index / features found (whole image, both passes).
    pub indexed_fraction: f64,
    /// Relative lattice-constant error along x and y of the largest region's lattice fit
    /// (fitted scale − 1; the simulated lattice has exactly its nominal size).
    pub lattice_constant_error: [f64; 2],
    /// Each fitted model parameter against the simulated value.
    pub parameters: Vec<ParameterCheck>,
}

/// One fitted model parameter and the simulator's value.
#[derive(Debug, Clone, Serialize)]
pub struct ParameterCheck {
    /// Parameter name as the model reports it.
    pub name: String,
    /// Fitted value (SI units, see `unit`).
    pub value: f64,
    /// Its 1σ uncertainty.
    pub sigma: f64,
    /// Simulated value.
    pub truth: f64,
    /// Unit of `value`, `sigma` and `truth`.
    pub unit: String,
}

/// The simulated value of each model parameter the DHCT model fits (drift, acceleration,
/// creep, creep time constant, power-law hysteresis), from the truth's effect records.
fn true_parameters(truth: &GroundTruth) -> Vec<(&'static str, f64)> {
    let get = |effect: &str, name: &str| {
        truth
            .effects
            .iter()
            .filter(|e| e.name == effect)
            .flat_map(|e| e.parameter_names.iter().zip(&e.parameters))
            .find(|(n, _)| n.as_str() == name)
            .map(|(_, v)| *v)
    };
    let pairs = [
        ("v_x", get("thermal-drift", "velocity_x_m_per_s")),
        ("a_x", get("thermal-drift", "acceleration_x_m_per_s2")),
        ("C_x", get("creep", "coefficient_x_m")),
        ("v_y", get("thermal-drift", "velocity_y_m_per_s")),
        ("a_y", get("thermal-drift", "acceleration_y_m_per_s2")),
        ("C_y", get("creep", "coefficient_y_m")),
        ("t0", get("creep", "t0_s")),
        ("k", get("fast-hysteresis", "k")),
        ("n", get("fast-hysteresis", "n")),
    ];
    pairs
        .into_iter()
        .filter_map(|(n, v)| v.map(|v| (n, v)))
        .collect()
}

/// Found feature matched to its truth: found and true controller positions (px), the
/// corrected position and the true sample position (m).
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Match {
    /// Trace or retrace.
    pub pass: ScanPass,
    /// Found position, pixels.
    pub found_px: [f64; 2],
    /// Fit uncertainty, pixels.
    pub sigma_px: [f64; 2],
    /// True controller position, pixels.
    pub truth_px: [f64; 2],
    /// DHCT-corrected position, metres.
    pub corrected_m: [f64; 2],
    /// True sample position, metres.
    pub sample_m: [f64; 2],
}

/// Every found feature away from the border matched to its truth, and the number of true
/// features and found features away from the border.
pub fn match_features(
    analysis: &Analysis,
    truth: &GroundTruth,
    geometry: &ScanGeometry,
    lattice: &dyn Lattice,
) -> (Vec<Match>, usize, usize) {
    let (px, py) = (geometry.pitch_x(), geometry.pitch_y());
    let nn = lattice.nearest_neighbour_distance();
    let margin = [EDGE_MARGIN_NN * nn / px, EDGE_MARGIN_NN * nn / py];
    let (w, h) = (geometry.columns() as f64, geometry.rows() as f64);
    let inside = |p: [f64; 2]| {
        p[0] >= margin[0] - 0.5
            && p[1] >= margin[1] - 0.5
            && p[0] <= w - 0.5 - margin[0]
            && p[1] <= h - 0.5 - margin[1]
    };
    let mut matches = Vec::new();
    let (mut truth_count, mut found_count) = (0, 0);
    for output in &analysis.passes {
        let acquisitions: Vec<([f64; 2], [f64; 2])> = truth
            .features
            .iter()
            .map(|t| {
                let a = match output.pass {
                    ScanPass::Trace => &t.trace,
                    ScanPass::Retrace => &t.retrace,
                };
                (a, t.sample_position_m)
            })
            .filter(|(a, _)| a.in_image && inside(a.controller_position_px))
            .map(|(a, s)| (a.controller_position_px, s))
            .collect();
        truth_count += acquisitions.len();
        if acquisitions.is_empty() {
            continue;
        }
        let points: Vec<[f64; 2]> = acquisitions.iter().map(|a| a.0).collect();
        let tree: ImmutableKdTree<f64, 2> =
            ImmutableKdTree::new_from_slice(&points).expect("a non-empty truth indexes");
        let radius_px = MATCH_RADIUS_NN * nn / px.max(py);
        let mut used = vec![false; points.len()];
        for (f, c) in output.features.features.iter().zip(&output.corrected) {
            if !inside([f.x_px, f.y_px]) {
                continue;
            }
            found_count += 1;
            let hit = tree
                .query(&[f.x_px, f.y_px])
                .nearest_one::<SquaredEuclidean<f64>>()
                .execute();
            let k = hit.item as usize;
            if hit.distance.sqrt() > radius_px || used[k] {
                continue;
            }
            used[k] = true;
            matches.push(Match {
                pass: output.pass,
                found_px: [f.x_px, f.y_px],
                sigma_px: [f.x_sigma_px, f.y_sigma_px],
                truth_px: acquisitions[k].0,
                corrected_m: [c.x_m, c.y_m],
                sample_m: acquisitions[k].1,
            });
        }
    }
    (matches, truth_count, found_count)
}

/// Accuracy of `analysis` against `truth`.
pub fn accuracy(
    analysis: &Analysis,
    truth: &GroundTruth,
    geometry: &ScanGeometry,
    lattice: &dyn Lattice,
) -> Accuracy {
    let (px, py) = (geometry.pitch_x(), geometry.pitch_y());
    let (matches, truth_count, found) = match_features(analysis, truth, geometry, lattice);
    let n = matches.len().max(1) as f64;
    let sq = |v: [f64; 2]| v[0] * v[0] + v[1] * v[1];
    let feature_rms_px = (matches
        .iter()
        .map(|m| sq([m.found_px[0] - m.truth_px[0], m.found_px[1] - m.truth_px[1]]))
        .sum::<f64>()
        / (2.0 * n))
        .sqrt();
    let axis_rms = |k: usize| {
        (matches
            .iter()
            .map(|m| (m.found_px[k] - m.truth_px[k]).powi(2))
            .sum::<f64>()
            / n)
            .sqrt()
    };
    let crlb_px = (matches.iter().map(|m| sq(m.sigma_px)).sum::<f64>() / (2.0 * n)).sqrt();
    let noise_floor_m = (matches
        .iter()
        .map(|m| {
            sq([
                (m.found_px[0] - m.truth_px[0]) * px,
                (m.found_px[1] - m.truth_px[1]) * py,
            ])
        })
        .sum::<f64>()
        / n)
        .sqrt();
    let uncorrected: Vec<[f64; 2]> = matches
        .iter()
        .map(|m| {
            [
                m.found_px[0] * px - m.sample_m[0],
                m.found_px[1] * py - m.sample_m[1],
            ]
        })
        .collect();
    let corrected: Vec<[f64; 2]> = matches
        .iter()
        .filter(|m| m.corrected_m.iter().all(|v| v.is_finite()))
        .map(|m| {
            [
                m.corrected_m[0] - m.sample_m[0],
                m.corrected_m[1] - m.sample_m[1],
            ]
        })
        .collect();
    let corrected_rms_m = rms_about_mean(&corrected);
    let crlb_white_px = white_noise_crlb_px(truth, geometry, lattice);
    let all: usize = analysis
        .passes
        .iter()
        .map(|p| p.features.features.len())
        .sum();
    let indexed: usize = analysis
        .passes
        .iter()
        .map(|p| p.indices.iter().filter(|i| i.is_some()).count())
        .sum();
    let lattice_constant_error = analysis
        .regions
        .first()
        .map(|r| [r.fit.scale[0] - 1.0, r.fit.scale[1] - 1.0])
        .unwrap_or([f64::NAN, f64::NAN]);
    let parameters = true_parameters(truth)
        .into_iter()
        .filter_map(|(name, t)| {
            analysis
                .dhct
                .model
                .parameters
                .iter()
                .find(|p| p.name == name)
                .map(|p| ParameterCheck {
                    name: name.to_string(),
                    value: p.value,
                    sigma: p.sigma,
                    truth: t,
                    unit: p.unit.clone(),
                })
        })
        .collect();
    Accuracy {
        found,
        matched: matches.len(),
        truth_in_image: truth_count,
        recall: matches.len() as f64 / truth_count.max(1) as f64,
        feature_rms_px,
        feature_rms_xy_px: [axis_rms(0), axis_rms(1)],
        crlb_px,
        feature_rms_over_crlb: feature_rms_px / crlb_px,
        crlb_white_px,
        feature_rms_over_crlb_white: feature_rms_px / crlb_white_px,
        noise_floor_m,
        uncorrected_rms_m: rms_about_mean(&uncorrected),
        corrected_rms_m,
        corrected_over_floor: corrected_rms_m / noise_floor_m,
        indexed_fraction: indexed as f64 / all.max(1) as f64,
        lattice_constant_error,
        parameters,
    }
}

/// The white-noise CRLB of the simulated feature shape (round Gaussians only), pixels.
fn white_noise_crlb_px(truth: &GroundTruth, geometry: &ScanGeometry, lattice: &dyn Lattice) -> f64 {
    let config = &truth.config;
    let shape = &config.surface.feature;
    let tip = config.tip.sigma_m;
    let noise = config.noise.white_sigma_m;
    if !shape.lobes.is_empty() || shape.sigma_m[0] != shape.sigma_m[1] || noise <= 0.0 {
        return f64::NAN;
    }
    // Tip broadening keeps the volume: σ² → σ² + σ_tip², peak × σ² / (σ² + σ_tip²).
    let sigma2 = shape.sigma_m[0].powi(2) + tip * tip;
    let amplitude = shape.height_m.abs() * shape.sigma_m[0].powi(2) / sigma2;
    let pitch = geometry.pitch_x();
    let radius_px =
        dhct_features::FeatureOptions::for_neighbour_distance(lattice.nearest_neighbour_distance())
            .fit_radius_fraction
            * lattice.nearest_neighbour_distance()
            / pitch;
    crate::crlb::position_crlb_px(sigma2.sqrt() / pitch, amplitude, noise, radius_px)
        .unwrap_or(f64::NAN)
}
