//! Miscalibrated files: the lattice is the standard. Graphite, a square lattice and a
//! Si(111)-7×7-like cell (dim corner holes and 12 bright adatoms per cell, tracked by the
//! corner holes) are simulated with drift, creep and hysteresis, and written with a pixel
//! size that is off by up to ±30 % per axis and an x drift that shears the frame by up to
//! 10°. The corrected lattice, measured by a Fourier transform of the *corrected image*
//! (not by dhct's own lattice fit), must be within 1 % and 0.5° of the truth.

mod common;

use common::das_like;
use dhct_calibrate::measure_lattice;
use dhct_lattice::{Hexagonal, Lattice, Square};
use dhct_pipeline::{PipelineOptions, run};
use dhct_scan::{ScanPair, ScanPass};
use dhct_simulate::config::{FeatureShape, LatticeConfig, NoiseConfig};
use dhct_simulate::effects::EffectConfig;
use dhct_simulate::{Simulation, SimulationConfig, presets};

struct Case {
    name: &'static str,
    surface: LatticeConfig,
    lattice: Box<dyn Lattice>,
    width_m: f64,
    feature_sigma_m: f64,
    height_m: f64,
}

fn cases() -> Vec<Case> {
    vec![
        Case {
            name: "graphite",
            surface: LatticeConfig::Graphite,
            lattice: Box::new(Hexagonal::graphite()),
            width_m: 5e-9,
            feature_sigma_m: 0.6e-10,
            height_m: 40e-12,
        },
        Case {
            name: "square",
            surface: LatticeConfig::Square { a_m: 3.6e-10 },
            lattice: Box::new(Square::new(3.6e-10).expect("valid")),
            width_m: 7e-9,
            feature_sigma_m: 0.8e-10,
            height_m: 40e-12,
        },
        Case {
            name: "7x7-like",
            surface: LatticeConfig::User(das_like()),
            lattice: Box::new(Hexagonal::si111_7x7()),
            width_m: 40e-9,
            feature_sigma_m: 2.5e-10,
            height_m: 60e-12,
        },
    ]
}

/// `case` simulated with drift, creep and hysteresis plus an x drift shearing the frame by
/// `shear_deg`, then written with its pixel size multiplied by `error` per axis.
fn miscalibrated(case: &Case, error: [f64; 2], shear_deg: f64) -> ScanPair {
    let mut config: SimulationConfig = presets::ci_small();
    config.scan.width_m = case.width_m;
    config.scan.height_m = case.width_m;
    config.surface.lattice = case.surface.clone();
    config.surface.angle_rad = 0.21;
    config.surface.feature = FeatureShape {
        height_m: case.height_m,
        sigma_m: [case.feature_sigma_m; 2],
        angle_rad: 0.0,
        lobes: Vec::new(),
    };
    config.noise = NoiseConfig {
        white_sigma_m: 2e-12,
        ..NoiseConfig::default()
    };
    let geometry = Simulation::from_config(&config)
        .expect("valid config")
        .run()
        .expect("runs")
        .pair
        .geometry()
        .clone();
    let shear_velocity = shear_deg.to_radians().tan() * geometry.slow_speed();
    for effect in &mut config.effects {
        if let EffectConfig::ThermalDrift(drift) = effect {
            // The tip lags the sample: d.x grows with y, so features appear sheared.
            drift.velocity_m_per_s[0] += shear_velocity;
        }
    }
    let pair = Simulation::from_config(&config)
        .expect("valid config")
        .run()
        .expect("runs")
        .pair;
    let file_geometry = pair
        .geometry()
        .clone()
        .with_pitch(geometry.pitch_x() * error[0], geometry.pitch_y() * error[1])
        .expect("positive");
    ScanPair::new(
        file_geometry,
        pair.trace().expect("trace").clone(),
        pair.image(ScanPass::Retrace).cloned(),
    )
    .expect("same shape")
}

fn check(case: &Case, error: [f64; 2], shear_deg: f64) {
    let pair = miscalibrated(case, error, shear_deg);
    let mut options = PipelineOptions::for_lattice(case.lattice.as_ref());
    options.features.line_correction = dhct_features::LineCorrection::None;
    options.calibration.check.pitch_tolerance = 0.5;
    let analysis = run(&pair, case.lattice.as_ref(), None, &options, &|_| {})
        .unwrap_or_else(|e| panic!("{} {error:?} {shear_deg}°: {e}", case.name));
    // The corrected image lies on the raw pixel grid with the file's pixel size, in sample
    // units: the model maps the file's (wrong) metres onto the lattice's true ones.
    let corrected = &analysis.passes[0].corrected_image;
    let measured = measure_lattice(corrected.view(), pair.geometry(), None)
        .unwrap_or_else(|e| panic!("{} {error:?}: corrected image: {e}", case.name));
    let [a1, a2] = case.lattice.primitive_vectors();
    let (a, angle) = (a1.norm(), a1.angle(&a2).to_degrees());
    let found = &measured.lattice;
    let ideal_angle = if angle > 90.0 { 180.0 - angle } else { angle };
    println!(
        "{:9} error {error:?} shear {shear_deg:5.1}°: {} features, {} indexed; corrected {} / {} = {:.4}, {:.4}, angle {:.2}° ({:?}, file calibration {:?})",
        case.name,
        analysis.passes[0].features.features.len(),
        analysis.passes[0].indices.iter().flatten().count(),
        dhct_calibrate::length(found.lengths_m[0]),
        dhct_calibrate::length(a),
        found.lengths_m[0] / a,
        found.lengths_m[1] / a,
        found.angle_deg,
        analysis.correction,
        analysis.calibration.as_ref().map(|c| c.calibration.scale)
    );
    for length in found.lengths_m {
        assert!(
            (length / a - 1.0).abs() < 0.01,
            "{} {error:?} {shear_deg}°: corrected lattice {} (truth a = {a:e}), calibration {:?}",
            case.name,
            found.describe(),
            analysis.calibration.as_ref().map(|c| c.calibration)
        );
    }
    assert!(
        (found.angle_deg - ideal_angle).abs() < 0.5,
        "{} {error:?} {shear_deg}°: corrected lattice {} (truth {ideal_angle}°)",
        case.name,
        found.describe()
    );
}

#[test]
fn scale_errors_up_to_30_percent_and_shear_up_to_10_degrees_are_calibrated_away() {
    let settings: [([f64; 2], f64); 5] = [
        ([1.3, 1.0], 0.0),
        ([1.0, 0.7], 5.0),
        ([0.7, 0.85], 10.0),
        ([1.3, 1.15], -10.0),
        ([0.8, 0.8], 0.0),
    ];
    for case in cases() {
        for (error, shear) in settings {
            check(&case, error, shear);
        }
    }
}

#[test]
fn a_large_cell_on_a_small_frame_falls_back_to_the_affine_correction() {
    // 5 cells across: too few corner holes keep a full neighbour shell for the drift model.
    let mut case = cases().pop().expect("the 7x7-like case");
    case.width_m = 13e-9;
    let pair = miscalibrated(&case, [1.2, 0.9], 3.0);
    let mut options = PipelineOptions::for_lattice(case.lattice.as_ref());
    options.features.line_correction = dhct_features::LineCorrection::None;
    options.calibration.check.pitch_tolerance = 0.5;
    let analysis = run(&pair, case.lattice.as_ref(), None, &options, &|_| {})
        .unwrap_or_else(|e| panic!("small 7x7-like frame: {e}"));
    assert_eq!(analysis.correction, dhct_pipeline::CorrectionSource::Affine);
    assert!(
        analysis
            .warnings
            .iter()
            .any(|w| w.code == dhct_pipeline::WarningCode::ModelNotFitted)
    );
    // The corrected image's Fourier peaks, fitted with the lattice (all of them: five cells
    // give few, broad peaks, and the coarsest cell alone is uncertain by ~1 %).
    let measured = measure_lattice(
        analysis.passes[0].corrected_image.view(),
        pair.geometry(),
        None,
    )
    .expect("a lattice in the corrected image");
    let bounds = dhct_calibrate::CheckOptions::default().bounds(pair.geometry().fast_axis());
    let matched = dhct_calibrate::match_lattice(&measured, case.lattice.as_ref(), &bounds)
        .expect("the lattice fits the corrected image");
    for scale in matched.calibration.scale {
        assert!(
            (scale - 1.0).abs() < 0.015,
            "corrected {} (scales {:?})",
            measured.lattice.describe(),
            matched.calibration.scale
        );
    }
}
