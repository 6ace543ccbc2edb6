//! Shared helpers of the acceptance tests: simulate, find features, run DHCT, and compare
//! with the simulator's ground truth.
#![allow(dead_code)]

use dhct_distortion::{
    DhctOptions, DhctResult, DistortionModel, PassInput, analyse, correct_features, nn_angle_stats,
    select_features,
};
use dhct_features::{FeatureOptions, FeatureSet, find_features_in_pair};
use dhct_lattice::Lattice;
use dhct_numerics::moments::rms_about_mean;
use dhct_scan::{ScanGeometry, ScanPass};
use dhct_simulate::{Simulation, SimulationConfig, SimulationOutput};
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::{DMatrix, DVector};

pub struct Run {
    pub output: SimulationOutput,
    pub lattice: Box<dyn Lattice>,
    pub sets: Vec<FeatureSet>,
    pub result: DhctResult,
}

pub fn run(config: &SimulationConfig, options: &DhctOptions) -> Run {
    let mut run = simulate_and_find(config);
    let result = analyse(
        &pass_inputs(&run.sets),
        run.output.pair.geometry(),
        run.lattice.as_ref(),
        options,
    )
    .expect("DHCT analysis succeeds");
    run.result = result;
    run
}

/// Every pass's features, without a mask.
pub fn pass_inputs(sets: &[FeatureSet]) -> Vec<PassInput<'_>> {
    sets.iter()
        .map(|s| PassInput {
            features: &s.features,
            mask: None,
        })
        .collect()
}

/// Simulates `config` and finds its features; the result holds the identity model (no
/// analysis run).
pub fn simulate_and_find(config: &SimulationConfig) -> Run {
    let simulation = Simulation::from_config(config).expect("valid config");
    let output = simulation.run().expect("simulation runs");
    let lattice = config.surface.lattice.build().expect("lattice");
    let nn = lattice.nearest_neighbour_distance();
    let sets = find_features_in_pair(&output.pair, &FeatureOptions::for_neighbour_distance(nn))
        .expect("features found");
    Run {
        output,
        lattice,
        sets,
        result: DhctResult::of_model(DistortionModel::identity()),
    }
}

/// Residual statistics of one run (metres).
#[derive(Debug, Clone, Copy)]
pub struct Residuals {
    /// Matched features (both passes).
    pub count: usize,
    /// RMS localisation error of the found features in the controller frame.
    pub noise_floor: f64,
    /// RMS of controller position − true sample position (after one translation).
    pub uncorrected: f64,
    /// RMS after the best global affine map per pass (fitted to the truth).
    pub affine: f64,
    /// RMS of DHCT-corrected − true sample position (after one global translation).
    pub dhct: f64,
    /// Mean corrected NN distance, metres.
    pub corrected_nn_m: f64,
    /// Mean uncorrected NN distance, metres.
    pub uncorrected_nn_m: f64,
}

fn affine_rms(from: &[[f64; 2]], to: &[[f64; 2]]) -> f64 {
    let n = from.len();
    let design = DMatrix::from_fn(n, 3, |i, j| match j {
        0 => 1.0,
        1 => from[i][0],
        _ => from[i][1],
    });
    let mut sse = 0.0;
    for axis in 0..2 {
        let y = DVector::from_iterator(n, to.iter().map(|p| p[axis]));
        let jtj = design.transpose() * &design;
        let coef = jtj
            .lu()
            .solve(&(design.transpose() * &y))
            .expect("affine solvable");
        let r = &design * coef - y;
        sse += r.norm_squared();
    }
    (sse / n.max(1) as f64).sqrt()
}

/// Matches found features to the truth, and compares positions. Only features at least
/// `margin_px` from the border are used.
pub fn residuals(run: &Run, margin_px: f64) -> Residuals {
    let geometry: &ScanGeometry = run.output.pair.geometry();
    let (px, py) = (geometry.pitch_x(), geometry.pitch_y());
    let model = &run.result.model;
    let nn = run.lattice.nearest_neighbour_distance();
    let (mut noise, mut unc, mut dh) = (Vec::new(), Vec::new(), Vec::new());
    let mut affine_sse = 0.0;
    let mut total = 0usize;
    let mut nn_corr = Vec::new();
    let mut nn_unc = Vec::new();
    for set in &run.sets {
        let pass = set.pass;
        let truth: Vec<([f64; 2], [f64; 2])> = run
            .output
            .truth
            .features
            .iter()
            .map(|t| {
                let a = match pass {
                    ScanPass::Trace => t.trace,
                    ScanPass::Retrace => t.retrace,
                };
                (a.controller_position_px, t.sample_position_m)
            })
            .collect();
        let points: Vec<[f64; 2]> = truth.iter().map(|t| t.0).collect();
        let tree: ImmutableKdTree<f64, 2> = ImmutableKdTree::new_from_slice(&points).expect("tree");
        let corrected = correct_features(model, geometry, &set.features);
        let (mut from, mut to) = (Vec::new(), Vec::new());
        for (f, c) in set.features.iter().zip(&corrected) {
            let (w, h) = (geometry.columns() as f64, geometry.rows() as f64);
            if f.x_px < margin_px
                || f.y_px < margin_px
                || f.x_px > w - margin_px
                || f.y_px > h - margin_px
            {
                continue;
            }
            let hit = tree
                .query(&[f.x_px, f.y_px])
                .nearest_one::<SquaredEuclidean<f64>>()
                .execute();
            if hit.distance.sqrt() * px > 0.3 * nn {
                continue;
            }
            let (ctrl, sample) = truth[hit.item as usize];
            noise.push([(f.x_px - ctrl[0]) * px, (f.y_px - ctrl[1]) * py]);
            unc.push([f.x_px * px - sample[0], f.y_px * py - sample[1]]);
            dh.push([c.x_m - sample[0], c.y_m - sample[1]]);
            from.push([f.x_px * px, f.y_px * py]);
            to.push(sample);
        }
        affine_sse += affine_rms(&from, &to).powi(2) * from.len() as f64;
        total += from.len();
        // NN distances among features selected in the corrected frame, corrected and not.
        let points_px: Vec<[f64; 2]> = corrected.iter().map(|c| [c.x_px, c.y_px]).collect();
        let selection = select_features(
            &points_px,
            geometry,
            None,
            run.lattice.as_ref(),
            &Default::default(),
        )
        .expect("selection");
        for s in &selection.selected {
            for &j in &s.neighbours {
                let (a, b) = (&corrected[s.index], &corrected[j]);
                nn_corr.push((a.x_m - b.x_m).hypot(a.y_m - b.y_m));
                let (a, b) = (&set.features[s.index], &set.features[j]);
                nn_unc.push(((a.x_px - b.x_px) * px).hypot((a.y_px - b.y_px) * py));
            }
        }
        let _ = nn_angle_stats;
    }
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    Residuals {
        count: total,
        noise_floor: {
            let n = noise.len().max(1) as f64;
            (noise.iter().map(|v| v[0] * v[0] + v[1] * v[1]).sum::<f64>() / n).sqrt()
        },
        uncorrected: rms_about_mean(&unc),
        affine: (affine_sse / total.max(1) as f64).sqrt(),
        dhct: rms_about_mean(&dh),
        corrected_nn_m: mean(&nn_corr),
        uncorrected_nn_m: mean(&nn_unc),
    }
}

/// `(name, fitted, sigma, truth)` for the drift/creep parameters of the simulator's
/// thermal-drift + creep effects.
pub fn drift_parameter_errors(run: &Run) -> Vec<(String, f64, f64, f64)> {
    let mut truth = std::collections::HashMap::new();
    for e in &run.output.truth.effects {
        for (n, v) in e.parameter_names.iter().zip(&e.parameters) {
            truth.insert(format!("{}:{}", e.name, n), *v);
        }
    }
    let get = |k: &str| truth.get(k).copied().unwrap_or(0.0);
    let expected = [
        ("v_x", get("thermal-drift:velocity_x_m_per_s")),
        ("a_x", get("thermal-drift:acceleration_x_m_per_s2")),
        ("C_x", get("creep:coefficient_x_m")),
        ("v_y", get("thermal-drift:velocity_y_m_per_s")),
        ("a_y", get("thermal-drift:acceleration_y_m_per_s2")),
        ("C_y", get("creep:coefficient_y_m")),
        ("t0", get("creep:t0_s")),
        ("k", get("fast-hysteresis:k")),
        ("n", get("fast-hysteresis:n")),
    ];
    expected
        .iter()
        .filter_map(|(name, t)| {
            run.result
                .model
                .parameters
                .iter()
                .find(|p| p.name == *name)
                .map(|p| (name.to_string(), p.value, p.sigma, *t))
        })
        .collect()
}
