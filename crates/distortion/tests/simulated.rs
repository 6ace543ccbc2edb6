//! Acceptance against the simulator's ground truth: drift + creep + hysteresis at the
//! `ci-small` preset's magnitudes (graphite, 50 nm/s, drift (5, −8) pm/s, creep
//! C = (0.1, 0.2) nm, t0 = 20 s, S = 0.95·τ^−0.03, 2 pm white noise) on 512² px / 8 nm.

mod common;

use dhct_distortion::local::{LocalSettings, estimate_lattice_angle, local_distortions};
use dhct_distortion::{DhctOptions, DistortionError, FitOptions, fit_model};
use dhct_lattice::LocalDistortionMethod;
use dhct_simulate::{LatticeConfig, SimulationConfig, presets};

fn config_512(lattice: LatticeConfig) -> SimulationConfig {
    let mut config = presets::ci_small();
    config.scan.columns = 512;
    config.scan.rows = 512;
    config.scan.width_m = 8e-9;
    config.scan.height_m = 8e-9;
    config.surface.lattice = lattice;
    config
}

fn report(name: &str, run: &common::Run) -> common::Residuals {
    for p in &run.result.passes {
        eprintln!(
            "{name} {:?}: {} selected, {} measured, excluded {:?}, RDF a = {:.4} Å",
            p.pass,
            p.selection.selected.len(),
            p.local.len(),
            p.selection.exclusions,
            p.selection.rdf_fit.nn_distance_m * 1e10
        );
    }
    let r = common::residuals(run, 20.0);
    let nn = run.lattice.nearest_neighbour_distance();
    eprintln!(
        "{name}: {} features; rms (pm): noise floor {:.3}, uncorrected {:.1}, affine-only {:.2}, \
         DHCT {:.3} (= {:.2} x floor); affine/DHCT = {:.1}; corrected NN {:.5} Å ({:+.4} %)",
        r.count,
        r.noise_floor * 1e12,
        r.uncorrected * 1e12,
        r.affine * 1e12,
        r.dhct * 1e12,
        r.dhct / r.noise_floor,
        r.affine / r.dhct,
        r.corrected_nn_m * 1e10,
        (r.corrected_nn_m / nn - 1.0) * 100.0
    );
    r
}

#[test]
fn graphite_drift_creep_hysteresis_matches_truth() {
    let run = common::run(
        &config_512(LatticeConfig::Graphite),
        &DhctOptions::default(),
    );
    let r = report("graphite", &run);
    for (name, value, sigma, truth) in common::drift_parameter_errors(&run) {
        let z = (value - truth) / sigma;
        eprintln!("  {name}: {value:.5e} ± {sigma:.2e} (truth {truth:.5e}): {z:+.2} σ");
        assert!(z.abs() <= 3.0, "{name} is {z:.2} σ from the truth");
    }
    assert!(r.count > 1000);
    assert!(
        r.dhct <= 1.5 * r.noise_floor,
        "DHCT rms {} vs floor {}",
        r.dhct,
        r.noise_floor
    );
    assert!(
        r.affine >= 10.0 * r.dhct,
        "affine {} vs DHCT {}",
        r.affine,
        r.dhct
    );
    assert!((r.corrected_nn_m / 2.46e-10 - 1.0).abs() < 1e-3);
}

#[test]
fn square_lattice() {
    let run = common::run(
        &config_512(LatticeConfig::Square { a_m: 3.0e-10 }),
        &DhctOptions::default(),
    );
    let r = report("square", &run);
    assert!(
        r.dhct <= 1.5 * r.noise_floor,
        "DHCT rms {} vs floor {}",
        r.dhct,
        r.noise_floor
    );
    assert!(r.affine >= 10.0 * r.dhct);
    assert!((r.corrected_nn_m / 3.0e-10 - 1.0).abs() < 1e-3);
}

#[test]
fn honeycomb_lattice() {
    let mut config = config_512(LatticeConfig::Graphene);
    config.surface.feature.sigma_m = [0.4e-10, 0.4e-10];
    let run = common::run(&config, &DhctOptions::default());
    let r = report("honeycomb", &run);
    assert!(
        r.dhct <= 1.5 * r.noise_floor,
        "DHCT rms {} vs floor {}",
        r.dhct,
        r.noise_floor
    );
    assert!(r.affine >= 10.0 * r.dhct);
    assert!((r.corrected_nn_m / run.lattice.nearest_neighbour_distance() - 1.0).abs() < 1e-3);
}

#[test]
fn ellipse_and_affine_agree_on_trigonal_data() {
    let mut config = presets::ci_small();
    config.scan.columns = 384;
    config.scan.rows = 384;
    config.scan.width_m = 6e-9;
    config.scan.height_m = 6e-9;
    let run = common::run(&config, &DhctOptions::default());
    let geometry = run.output.pair.geometry();
    for (set, pass) in run.sets.iter().zip(&run.result.passes) {
        let points_m: Vec<[f64; 2]> = set
            .features
            .iter()
            .map(|f| [f.x_px * geometry.pitch_x(), f.y_px * geometry.pitch_y()])
            .collect();
        let angle =
            estimate_lattice_angle(&points_m, &pass.selection.selected, run.lattice.as_ref());
        let settings = |method| LocalSettings {
            geometry,
            lattice: run.lattice.as_ref(),
            method,
            lattice_angle_rad: angle,
        };
        let ellipse = local_distortions(
            &set.features,
            &pass.selection.selected,
            &settings(LocalDistortionMethod::Ellipse),
        );
        let affine = local_distortions(
            &set.features,
            &pass.selection.selected,
            &settings(LocalDistortionMethod::Affine),
        );
        assert_eq!(ellipse.len(), affine.len());
        let n = ellipse.len() as f64;
        let (mut ds, mut dd, mut spread_s, mut spread_d) = (0.0, 0.0, 0.0, 0.0);
        let mean_s = ellipse.iter().map(|e| e.scale).sum::<f64>() / n;
        let mean_d = ellipse.iter().map(|e| e.drift_m_per_s[1]).sum::<f64>() / n;
        for (e, a) in ellipse.iter().zip(&affine) {
            ds += (e.scale - a.scale).powi(2);
            dd += (e.drift_m_per_s[1] - a.drift_m_per_s[1]).powi(2);
            spread_s += (e.scale - mean_s).powi(2);
            spread_d += (e.drift_m_per_s[1] - mean_d).powi(2);
        }
        let (ds, dd) = ((ds / n).sqrt(), (dd / n).sqrt());
        let (spread_s, spread_d) = ((spread_s / n).sqrt(), (spread_d / n).sqrt());
        eprintln!(
            "{:?}: ellipse vs affine rms difference: S {ds:.2e} (spread {spread_s:.2e}), \
             D_y {dd:.2e} m/s (spread {spread_d:.2e})",
            pass.pass
        );
        // Both see the same neighbours; with 6 exact points they are identical, with noise
        // they differ far less than the signal varies.
        assert!(ds < 0.1 * spread_s && dd < 0.1 * spread_d);
    }
}

#[test]
fn too_few_features_is_a_clear_error() {
    let err = fit_model(&[], 10.0, 0.1, &FitOptions::default()).expect_err("no data");
    assert!(matches!(
        err,
        DistortionError::TooFewFeatures { found: 0, .. }
    ));
    let message = err.to_string();
    assert!(
        message.contains("0 usable") && message.contains("check"),
        "{message}"
    );
}

/// Drift against the slow scan at 30 % and 40 % of the slow-scan speed (the raw slow scale
/// is that much off). In the raw positions most features (at 40 %: all) lose part of their
/// NN shell in the window, and those that keep it are the less distorted ones. A first
/// model (at 40 %: from the k nearest neighbours) corrects the positions, the neighbours
/// are found again in the corrected frame, and the fit must then match the truth. (Before
/// that, at 30 % only ~20 % of the features were measured and the corrected slow scale
/// came out 0.8 % off, silently; at 35 % and more the analysis stopped with an error.)
#[test]
fn drift_of_thirty_and_forty_percent_of_the_slow_speed_is_recovered() {
    use dhct_distortion::NeighbourSource;
    use dhct_simulate::effects::{EffectConfig, ThermalDrift};
    for fraction in [0.3, 0.4] {
        let mut config = config_512(LatticeConfig::Graphite);
        let scan = &config.scan;
        let line_s = scan.width_m / scan.fast_speed_m_per_s + scan.turnaround_s;
        let slow_speed = (scan.height_m / scan.rows as f64) / (2.0 * line_s);
        let v = fraction * slow_speed;
        for effect in &mut config.effects {
            if let EffectConfig::ThermalDrift(ThermalDrift {
                velocity_m_per_s,
                acceleration_m_per_s2,
            }) = effect
            {
                *velocity_m_per_s = [0.625 * v, -v];
                *acceleration_m_per_s2 = [0.0, 0.0];
            }
        }
        let run = common::run(&config, &DhctOptions::default());
        let r = report(&format!("graphite, {fraction} × slow-speed drift"), &run);
        for p in &run.result.passes {
            assert_eq!(p.neighbour_source, NeighbourSource::CorrectedFrame);
            let refined = p.refined_selection.as_ref().expect("refined neighbours");
            assert!(
                refined.selected.len() > 2 * p.selection.selected.len(),
                "{:?}: {} raw vs {} refined",
                p.pass,
                p.selection.selected.len(),
                refined.selected.len()
            );
        }
        for (name, value, sigma, truth) in common::drift_parameter_errors(&run) {
            let z = (value - truth) / sigma;
            eprintln!("  {name}: {value:.5e} ± {sigma:.2e} (truth {truth:.5e}): {z:+.2} σ");
            assert!(
                z.abs() <= 3.0,
                "{fraction}: {name} is {z:.2} σ from the truth"
            );
        }
        assert!(
            r.dhct <= 1.5 * r.noise_floor,
            "DHCT rms {} vs floor {}",
            r.dhct,
            r.noise_floor
        );
        assert!((r.corrected_nn_m / 2.46e-10 - 1.0).abs() < 1e-3);
    }
}
