//! Detection against simulator ground truth: ≥ 99.5 % of atoms found and ≤ 0.2 % false
//! features on 512² images with the noise and distortions of the paper's Fig. 4 headline
//! acquisition (3 pm white, 2 pm 1/f, 5 pm line-offset noise and spikes on 40 pm atoms;
//! drift, creep and hysteresis), for graphite, a square lattice and dark features.

use dhct_features::{
    Background, FeatureOptions, FeatureSet, LineCorrection, Polarity, find_features_in_pair,
};
use dhct_scan::ScanPass;
use dhct_simulate::{GroundTruth, LatticeConfig, Simulation, SimulationConfig};

mod common;
use common::headline_512;

struct Score {
    expected: usize,
    found: usize,
    false_features: usize,
}

/// Matches features to the true controller positions of `pass`; only atoms farther than
/// `margin_px` from the border are expected (closer ones are edge-cut by design).
fn score(set: &FeatureSet, truth: &GroundTruth, margin_px: f64, match_px: f64) -> Score {
    let geometry = &truth.geometry;
    let (w, h) = (
        geometry.columns() as f64 - 1.0,
        geometry.rows() as f64 - 1.0,
    );
    let positions: Vec<[f64; 2]> = truth
        .features
        .iter()
        .map(|f| match set.pass {
            ScanPass::Trace => f.trace.controller_position_px,
            ScanPass::Retrace => f.retrace.controller_position_px,
        })
        .collect();
    let inside = |p: &[f64; 2], m: f64| p[0] >= m && p[1] >= m && p[0] <= w - m && p[1] <= h - m;
    let near = |p: &[f64; 2], x: f64, y: f64| (p[0] - x).hypot(p[1] - y) < match_px;
    let expected: Vec<&[f64; 2]> = positions.iter().filter(|p| inside(p, margin_px)).collect();
    let found = expected
        .iter()
        .filter(|p| set.features.iter().any(|f| near(p, f.x_px, f.y_px)))
        .count();
    // A feature is false if no true atom (anywhere, even just outside the margin) is near it.
    let false_features = set
        .features
        .iter()
        .filter(|f| !positions.iter().any(|p| near(p, f.x_px, f.y_px)))
        .count();
    Score {
        expected: expected.len(),
        found,
        false_features,
    }
}

fn check(name: &str, config: SimulationConfig, options: &FeatureOptions) {
    let output = Simulation::from_config(&config).unwrap().run().unwrap();
    let sets = find_features_in_pair(&output.pair, options).unwrap();
    assert_eq!(sets.len(), 2, "{name}: trace and retrace");
    let pitch = output.truth.geometry.pitch_x();
    let nn_px = options.neighbour_distance / pitch;
    // Edge margin used by the finder is the kernel radius, round(nn/2); allow one more px.
    let margin = (nn_px / 2.0).round() + 1.0;
    for set in &sets {
        let s = score(set, &output.truth, margin, 0.25 * nn_px);
        let found = s.found as f64 / s.expected as f64;
        let false_rate = s.false_features as f64 / set.features.len() as f64;
        println!(
            "{name} {:?}: {} expected, {} found ({:.3} %), {} false ({:.3} %), rejected: {}",
            set.pass,
            s.expected,
            s.found,
            100.0 * found,
            s.false_features,
            100.0 * false_rate,
            set.rejection_counts()
        );
        assert!(
            s.expected > 300,
            "{name}: the test image must hold many atoms"
        );
        assert!(
            found >= 0.995,
            "{name} {:?}: found only {:.3} %",
            set.pass,
            100.0 * found
        );
        assert!(
            false_rate <= 0.002,
            "{name} {:?}: {:.3} % false",
            set.pass,
            100.0 * false_rate
        );
    }
}

fn options(nn: f64) -> FeatureOptions {
    FeatureOptions {
        background: Background::Plane,
        line_correction: LineCorrection::Median,
        ..FeatureOptions::for_neighbour_distance(nn)
    }
}

#[test]
fn graphite_at_headline_noise() {
    check("graphite", headline_512(), &options(2.46e-10));
}

#[test]
fn square_lattice_at_headline_noise() {
    let mut config = headline_512();
    config.surface.lattice = LatticeConfig::Square { a_m: 3.0e-10 };
    config.surface.feature.sigma_m = [0.7e-10, 0.7e-10];
    check("square", config, &options(3.0e-10));
}

#[test]
fn dark_features_at_headline_noise() {
    let mut config = headline_512();
    config.surface.feature.height_m = -40e-12;
    let options = FeatureOptions {
        polarity: Polarity::Dark,
        ..options(2.46e-10)
    };
    check("dark graphite", config, &options);
}
