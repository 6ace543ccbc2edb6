//! What broke the calibration on real images from other labs, simulated class by class, on
//! graphite, a square lattice and a Si(111)-7×7-like cell, three seeds each:
//!
//! * **satellites**: a superstructure modulation (period doubling, (√3×√3)R30°, an
//!   incommensurate one) at 5–10 % of the main reflections' power;
//! * **anisotropic tip**: features 2.5× longer along one direction, so equivalent
//!   reflections differ strongly in power;
//! * **line jumps**: per-line height offsets as large as half the corrugation;
//! * **few cells**: frames only 6–8 large cells (10–12 atomic ones) across;
//! * **strong drift**: a slow-axis drift that stretches or squeezes the raw lattice 1.5×.
//!
//! Each but the strong drift is also written with a pixel size off by up to 20 %. The corrected lattice, measured
//! by fitting the named lattice to the Fourier peaks of the *corrected image*, must be
//! within 1 % in both scales and 0.5° in shear. Outside the bounds (a 3× stretch, an image
//! with no lattice) the run must stop with an error.

mod common;

use common::{Surface, corrected_lattice, simulate_miscalibrated, surfaces};
use dhct_lattice::Lattice;
use dhct_pipeline::{PipelineError, PipelineOptions, run};
use dhct_scan::ScanPair;
use dhct_simulate::SimulationConfig;
use dhct_simulate::config::Modulation;
use dhct_simulate::effects::EffectConfig;

/// The classes of the sweep.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Class {
    Satellites,
    AnisotropicTip,
    LineJumps,
    FewCells,
    StrongDrift,
}

const CLASSES: [Class; 5] = [
    Class::Satellites,
    Class::AnisotropicTip,
    Class::LineJumps,
    Class::FewCells,
    Class::StrongDrift,
];

/// The simulation of `surface` with `class` for `seed` (0, 1, 2), and the pixel-size
/// error it is written with.
fn config(surface: &Surface, class: Class, seed: u64) -> (SimulationConfig, [f64; 2]) {
    let mut config = surface.simulation(0.21 + 0.17 * seed as f64);
    config.seed = 100 + seed;
    let error = [[1.2, 0.9], [0.85, 1.1], [1.0, 1.15]][seed as usize];
    match class {
        Class::Satellites => {
            // One feature's cosine amplitude at the first reflection is about
            // 2·h·2πσ²/A·exp(−2π²σ²g²); the satellite's power is 5–10 % of it.
            let index = [[0.5, 0.0], [1.0 / 3.0, 1.0 / 3.0], [0.37, 0.11]][seed as usize];
            let fraction = [0.05, 0.08, 0.1][seed as usize];
            config.surface.modulations = vec![Modulation {
                index,
                amplitude_m: fraction_of_first_order(surface, fraction),
            }];
        }
        Class::AnisotropicTip => {
            // Longer along one axis, so that the first reflections along it are 30× weaker
            // in power than those across it (real tips: 10–60×).
            let g = first_order_frequency(surface);
            let extra = (30f64.ln() / (4.0 * std::f64::consts::PI.powi(2) * g * g)).sqrt();
            let sigma = surface.feature_sigma_m;
            config.surface.feature.sigma_m = [sigma, sigma.hypot(extra)];
            config.surface.feature.angle_rad = 0.4 * seed as f64;
        }
        Class::LineJumps => {
            config.noise.line_offset_sigma_m = 0.5 * surface.height_m;
        }
        Class::FewCells => {
            // The large cell as few times across as on the real 7×7 frames that were
            // refused; an atomic lattice 10–12 times (below that the Fourier judge itself
            // is uncertain by ~1 % on a perfect image).
            let cells = if surface.name == "7x7-like" {
                [6.0, 7.0, 8.0][seed as usize]
            } else {
                [10.0, 11.0, 12.0][seed as usize]
            };
            config.scan.width_m = cells * surface.cell_m;
            config.scan.height_m = cells * surface.cell_m;
        }
        // The drift alone (the file's pixel size right): the raw lattice 1.5× longer or
        // shorter along the slow axis.
        Class::StrongDrift => return (config, [1.0, 1.0]),
    }
    (config, error)
}

/// The first reflection's frequency of a one-feature-per-cell lattice of `surface`,
/// cycles per metre.
fn first_order_frequency(surface: &Surface) -> f64 {
    if surface.name == "square" {
        1.0 / surface.cell_m
    } else {
        2.0 / (3f64.sqrt() * surface.cell_m)
    }
}

/// The amplitude (metres) of a cosine whose power is `fraction` of one first-order
/// reflection of a one-feature-per-cell lattice of `surface`.
fn fraction_of_first_order(surface: &Surface, fraction: f64) -> f64 {
    let cell_area = surface.cell_m.powi(2) * if surface.name == "square" { 1.0 } else { 0.866 };
    let g = first_order_frequency(surface);
    let sigma = surface.feature_sigma_m;
    let first = 2.0 * surface.height_m * 2.0 * std::f64::consts::PI * sigma * sigma / cell_area
        * (-2.0 * std::f64::consts::PI.powi(2) * sigma * sigma * g * g).exp();
    first * fraction.sqrt()
}

/// Runs the simulation and writes it with the pixel size multiplied by `error`. For
/// [`Class::StrongDrift`] a slow-axis drift stretches the raw lattice 1.5× along the slow
/// axis (seeds 0, 1: with the tip; 2: against it, 1.5× shorter).
fn simulate(mut config: SimulationConfig, class: Class, error: [f64; 2]) -> ScanPair {
    if class == Class::StrongDrift {
        let geometry = config.scan.geometry().expect("a valid scan");
        // Features appear 1/(1 + v/v_slow) as long along the slow axis.
        let ratio = if config.seed % 3 == 2 {
            0.5
        } else {
            -1.0 / 3.0
        };
        for effect in &mut config.effects {
            if let EffectConfig::ThermalDrift(drift) = effect {
                drift.velocity_m_per_s[1] = ratio * geometry.slow_speed();
            }
        }
    }
    simulate_miscalibrated(&config, error)
}

fn options(lattice: &dyn Lattice) -> PipelineOptions {
    let mut options = PipelineOptions::for_lattice(lattice);
    options.calibration.check.pitch_tolerance = 0.5;
    options
}

#[test]
fn every_class_inside_the_bounds_is_corrected_to_within_1_percent() {
    let mut failures = Vec::new();
    for surface in surfaces() {
        for class in CLASSES {
            for seed in 0..3 {
                let (config, error) = config(&surface, class, seed);
                let pair = simulate(config, class, error);
                let lattice = surface.lattice.as_ref();
                let label = format!(
                    "{} {class:?} seed {seed} (pixel size ×{error:?})",
                    surface.name
                );
                let analysis = match run(&pair, lattice, None, &options(lattice), &|_| {}) {
                    Ok(analysis) => analysis,
                    Err(e) => {
                        failures.push(format!("{label}: refused: {e}"));
                        continue;
                    }
                };
                let [kx, ky, shear] =
                    corrected_lattice(&pair, &analysis.passes[0].corrected_image, lattice);
                let compared = analysis
                    .affine
                    .first()
                    .map(|c| (c.model_rms_m * 1e12, c.affine_rms_m * 1e12, c.model_scale));
                println!(
                    "{label}: {:?} (rms model/affine {compared:.1?} pm), corrected x {kx:.4}, \
                     y {ky:.4}, shear {shear:.2}°",
                    analysis.correction
                );
                if (kx - 1.0).abs() > 0.01 || (ky - 1.0).abs() > 0.01 || shear.abs() > 0.5 {
                    failures.push(format!(
                        "{label}: corrected x {kx:.4}, y {ky:.4}, shear {shear:.2}°"
                    ));
                }
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn a_threefold_stretch_and_an_image_without_a_lattice_are_refused() {
    let surface = surfaces().remove(0);
    let lattice = surface.lattice.as_ref();
    let (config, _) = config(&surface, Class::LineJumps, 0);
    let stretched = simulate(config.clone(), Class::LineJumps, [1.0, 3.0]);
    match run(&stretched, lattice, None, &options(lattice), &|_| {}) {
        Err(PipelineError::Calibration(_)) => {}
        other => panic!("a 3× stretch: {:?}", other.map(|a| a.correction)),
    }
    let mut flat = config;
    flat.surface.feature.height_m = 0.0;
    flat.noise.white_sigma_m = 5e-12;
    let noise = simulate(flat, Class::LineJumps, [1.0, 1.0]);
    let result = run(&noise, lattice, None, &options(lattice), &|_| {});
    assert!(result.is_err(), "an image without a lattice ran to the end");
}

/// A commensurate (√7×√7)R19.1° superstructure six times as powerful as the atoms' first
/// reflections (FeBr₂ on Au(111) shows one), with the pixel-size search as wide as
/// `--calibrate` makes it: the atoms' lattice is the one calibrated (the reading that needs
/// no pixel-size correction first), the superstructure's reflections are left over and
/// reported, never the cell.
#[test]
fn a_superstructure_stronger_than_the_atoms_is_left_over_not_made_the_lattice() {
    let surface = surfaces().remove(0);
    let lattice = surface.lattice.as_ref();
    let mut config = surface.simulation(0.3);
    config.seed = 107;
    let amplitude_m = fraction_of_first_order(&surface, 6.0);
    // The three first reflections of the superstructure, |g| = |g₁|/√7.
    config.surface.modulations = [[3.0, 1.0], [-1.0, 2.0], [-2.0, -3.0]]
        .into_iter()
        .map(|[h, k]| Modulation {
            index: [h / 7.0, k / 7.0],
            amplitude_m,
        })
        .collect();
    let pair = simulate_miscalibrated(&config, [1.0, 1.0]);
    let mut options = options(lattice);
    options.calibration.check.pitch_tolerance = 9.0;
    let analysis = run(&pair, lattice, None, &options, &|_| {}).expect("corrected");
    let calibration = analysis.calibration.as_ref().expect("measured");
    let matched = &calibration.passes[0].matched;
    assert!(
        (calibration.calibration.mean_scale - 1.0).abs() < 0.2,
        "the superstructure was made the lattice: {:?}",
        calibration.calibration
    );
    let long: Vec<_> = matched
        .unexplained
        .iter()
        .filter(|p| (p.period_m / (3f64.sqrt() / 2.0 * surface.cell_m) - 7f64.sqrt()).abs() < 0.2)
        .collect();
    assert!(!long.is_empty(), "{:?}", matched.unexplained);
    let [kx, ky, shear] = corrected_lattice(&pair, &analysis.passes[0].corrected_image, lattice);
    assert!(
        (kx - 1.0).abs() <= 0.01 && (ky - 1.0).abs() <= 0.01 && shear.abs() <= 0.5,
        "corrected x {kx:.4}, y {ky:.4}, shear {shear:.2}°"
    );
}
