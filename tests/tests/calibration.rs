//! Miscalibrated files: the lattice is the standard. Graphite, a square lattice and a
//! Si(111)-7×7-like cell (dim corner holes and 12 bright adatoms per cell, tracked by the
//! corner holes) are simulated with drift, creep and hysteresis, and written with a pixel
//! size that is off by up to ±30 % per axis and an x drift that shears the frame by up to
//! 10°. The corrected lattice, measured by a Fourier transform of the *corrected image*
//! (the lattice fitted to its peaks, not dhct's own lattice fit of the features), must be
//! within 1 % and 0.5° of the truth.

mod common;

use common::{Surface, corrected_lattice, simulate_miscalibrated, surfaces};

use dhct_pipeline::{PipelineOptions, run};
use dhct_scan::ScanPair;
use dhct_simulate::effects::EffectConfig;

/// `case` simulated with drift, creep and hysteresis plus an x drift shearing the frame by
/// `shear_deg`, then written with its pixel size multiplied by `error` per axis.
fn miscalibrated(case: &Surface, error: [f64; 2], shear_deg: f64) -> ScanPair {
    let mut config = case.simulation(0.21);
    let geometry = config.scan.geometry().expect("a valid scan");
    let shear_velocity = shear_deg.to_radians().tan() * geometry.slow_speed();
    for effect in &mut config.effects {
        if let EffectConfig::ThermalDrift(drift) = effect {
            // The tip lags the sample: d.x grows with y, so features appear sheared.
            drift.velocity_m_per_s[0] += shear_velocity;
        }
    }
    simulate_miscalibrated(&config, error)
}

fn check(case: &Surface, error: [f64; 2], shear_deg: f64) {
    let pair = miscalibrated(case, error, shear_deg);
    let mut options = PipelineOptions::for_lattice(case.lattice.as_ref());
    options.features.line_correction = dhct_features::LineCorrection::None;
    options.calibration.check.pitch_tolerance = 0.5;
    let analysis = run(&pair, case.lattice.as_ref(), None, &options, &|_| {})
        .unwrap_or_else(|e| panic!("{} {error:?} {shear_deg}°: {e}", case.name));
    // The corrected image lies on the raw pixel grid with the file's pixel size, in sample
    // units: the model maps the file's (wrong) metres onto the lattice's true ones. Its
    // Fourier peaks are fitted with the lattice (the coarsest cell indexing them is no
    // judge: one stray weak peak makes it a supercell).
    let [kx, ky, shear] = corrected_lattice(
        &pair,
        &analysis.passes[0].corrected_image,
        case.lattice.as_ref(),
    );
    println!(
        "{:9} error {error:?} shear {shear_deg:5.1}°: {} features, {} indexed; corrected x {kx:.4}, y {ky:.4}, shear {shear:.2}° ({:?}, file calibration {:?})",
        case.name,
        analysis.passes[0].features.features.len(),
        analysis.passes[0].indices.iter().flatten().count(),
        analysis.correction,
        analysis.calibration.as_ref().map(|c| c.calibration.scale)
    );
    assert!(
        (kx - 1.0).abs() < 0.01 && (ky - 1.0).abs() < 0.01 && shear.abs() < 0.5,
        "{} {error:?} {shear_deg}°: corrected x {kx:.4}, y {ky:.4}, shear {shear:.2}°",
        case.name
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
    for case in surfaces() {
        for (error, shear) in settings {
            check(&case, error, shear);
        }
    }
}

#[test]
fn a_large_cell_on_a_small_frame_is_corrected_or_stops_clearly() {
    // 6 cells across: corrected, by the drift model where enough corner holes keep a full
    // neighbour shell, else by the affine map with a warning that says so.
    let mut case = surfaces().pop().expect("the 7x7-like case");
    case.width_m = 16e-9;
    let pair = miscalibrated(&case, [1.2, 0.9], 3.0);
    let mut options = PipelineOptions::for_lattice(case.lattice.as_ref());
    options.features.line_correction = dhct_features::LineCorrection::None;
    options.calibration.check.pitch_tolerance = 0.5;
    let analysis = run(&pair, case.lattice.as_ref(), None, &options, &|_| {})
        .unwrap_or_else(|e| panic!("small 7x7-like frame: {e}"));
    if analysis.correction == dhct_pipeline::CorrectionSource::Affine {
        assert!(
            analysis
                .warnings
                .iter()
                .any(|w| w.code == dhct_pipeline::WarningCode::ModelNotFitted)
        );
    }
    // The corrected image's Fourier peaks, fitted with the lattice.
    let [kx, ky, shear] = corrected_lattice(
        &pair,
        &analysis.passes[0].corrected_image,
        case.lattice.as_ref(),
    );
    assert!(
        (kx - 1.0).abs() < 0.015 && (ky - 1.0).abs() < 0.015 && shear.abs() < 0.5,
        "corrected x {kx:.4}, y {ky:.4}, shear {shear:.2}° ({:?})",
        analysis.correction
    );
    // 5 cells across: too few corner holes inside the frame for a lattice fit; the run
    // stops and says how many it found.
    case.width_m = 13e-9;
    let pair = miscalibrated(&case, [1.2, 0.9], 3.0);
    match run(&pair, case.lattice.as_ref(), None, &options, &|_| {}) {
        Err(e @ dhct_pipeline::PipelineError::TooFewFeatures { .. }) => {
            assert!(e.to_string().contains("needed"), "{e}")
        }
        other => panic!("5 cells: {:?}", other.map(|a| a.correction)),
    }
}
