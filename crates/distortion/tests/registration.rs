//! The global registration (every indexed feature's position against the ideal lattice)
//! against the simulator's ground truth: from the local route's model, and from no model
//! at all (the identity: the lattice alone indexes the raw positions) on a scan whose drift
//! stretches the raw lattice past the neighbour window of the local route.

mod common;

use dhct_distortion::registration::{StartQuality, register_from};
use dhct_distortion::{
    DhctOptions, DistortionModel, FitOptions, HysteresisChoice, HysteresisLaw, SeedMap, analyse,
    analyse_seeded,
};
use dhct_simulate::effects::{EffectConfig, ThermalDrift};
use dhct_simulate::{LatticeConfig, SimulationConfig, presets};

fn graphite_512() -> SimulationConfig {
    let mut config = presets::ci_small();
    config.scan.columns = 512;
    config.scan.rows = 512;
    config.scan.width_m = 8e-9;
    config.scan.height_m = 8e-9;
    config.surface.lattice = LatticeConfig::Graphite;
    config
}

/// Registers `run`'s features from `start` and checks the model against the truth: the
/// corrected positions at the localisation floor, every drift/creep/hysteresis parameter
/// within 3σ.
fn registered_matches_truth(run: &mut common::Run, start: DistortionModel, quality: StartQuality) {
    registered_with_matches_truth(run, start, quality, &FitOptions::default());
}

/// [`registered_matches_truth`] under the fit `options`.
fn registered_with_matches_truth(
    run: &mut common::Run,
    start: DistortionModel,
    quality: StartQuality,
    options: &FitOptions,
) {
    let geometry = run.output.pair.geometry().clone();
    let inputs = common::pass_inputs(&run.sets);
    let local = common::residuals(run, 20.0);
    let (registration, features) = register_from(
        &inputs,
        &geometry,
        run.lattice.as_ref(),
        &start,
        quality,
        options,
    )
    .expect("registers");
    let found: usize = run.sets.iter().map(|s| s.features.len()).sum();
    run.result.model = registration.model;
    let r = common::residuals(run, 20.0);
    eprintln!(
        "{quality:?} start: {} of {found} features registered, rms deviation {:.2} pm; \
         rms vs truth {:.3} pm (local route {:.3}, floor {:.3})",
        features.len(),
        registration.rms_deviation_m * 1e12,
        r.dhct * 1e12,
        local.dhct * 1e12,
        r.noise_floor * 1e12
    );
    assert!(features.len() as f64 > 0.9 * found as f64, "{quality:?}");
    assert!(
        r.dhct <= 1.5 * r.noise_floor,
        "{quality:?}: {} vs floor {}",
        r.dhct,
        r.noise_floor
    );
    // A parameter at a bound of its range (t0 of a scan without creep) is not compared.
    let diagnostics = &run.result.model.diagnostics;
    let at_bound = |name: &str| diagnostics.at_bounds.iter().any(|b| b.parameter == name);
    for (name, value, sigma, truth) in common::drift_parameter_errors(run) {
        let z = (value - truth) / sigma;
        eprintln!("  {name}: {value:.4e} ± {sigma:.1e} (truth {truth:.4e}): {z:+.2} σ");
        if !at_bound(&name) {
            assert!(
                z.abs() <= 3.0,
                "{quality:?}: {name} is {z:.2} σ from the truth"
            );
        }
    }
    eprintln!("  at a bound: {:?}", diagnostics.at_bounds);
}

#[test]
fn registration_from_the_local_model_matches_the_truth() {
    let mut run = common::run(&graphite_512(), &DhctOptions::default());
    let start = run.result.model.clone();
    registered_matches_truth(&mut run, start, StartQuality::Fitted);
}

/// A scan without hysteresis registered without a hysteresis law (no law parameters in
/// the fit: a case that once indexed an empty gradient) matches the truth.
#[test]
fn registration_without_a_hysteresis_law_matches_a_scan_without_hysteresis() {
    let mut config = graphite_512();
    config.effects.retain(|e| {
        !matches!(
            e,
            EffectConfig::FastHysteresis(_) | EffectConfig::AsymmetricHysteresis(_)
        )
    });
    let mut run = common::run(&config, &DhctOptions::default());
    let mut start = run.result.model.clone();
    start.hysteresis = HysteresisLaw::none();
    let options = FitOptions {
        hysteresis: HysteresisChoice::None,
        ..FitOptions::default()
    };
    registered_with_matches_truth(&mut run, start, StartQuality::Fitted, &options);
    assert_eq!(run.result.model.hysteresis, HysteresisLaw::none());
}

/// The upper-triangular `K` (file per sample metres) of the best linear map from the true
/// sample positions to the raw controller positions (`A = K·Q`, `Q` a rotation): what the
/// pipeline measures from the image's Fourier peaks.
fn measured_map(run: &common::Run) -> [[f64; 2]; 2] {
    let geometry = run.output.pair.geometry();
    let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
    let (mut rx, mut ry) = ([0.0; 2], [0.0; 2]);
    let truth = &run.output.truth.features;
    let n = truth.len() as f64;
    let mean = |f: &dyn Fn(usize) -> f64| (0..truth.len()).map(f).sum::<f64>() / n;
    let ms = [
        mean(&|i| truth[i].sample_position_m[0]),
        mean(&|i| truth[i].sample_position_m[1]),
    ];
    let raw = |i: usize| {
        let p = truth[i].trace.controller_position_px;
        [p[0] * geometry.pitch_x(), p[1] * geometry.pitch_y()]
    };
    let mr = [mean(&|i| raw(i)[0]), mean(&|i| raw(i)[1])];
    for (i, t) in truth.iter().enumerate() {
        let (x, y) = (
            t.sample_position_m[0] - ms[0],
            t.sample_position_m[1] - ms[1],
        );
        let r = raw(i);
        let (u, v) = (r[0] - mr[0], r[1] - mr[1]);
        sxx += x * x;
        sxy += x * y;
        syy += y * y;
        rx[0] += u * x;
        rx[1] += u * y;
        ry[0] += v * x;
        ry[1] += v * y;
    }
    let det = sxx * syy - sxy * sxy;
    let solve = |r: [f64; 2]| {
        [
            (r[0] * syy - r[1] * sxy) / det,
            (r[1] * sxx - r[0] * sxy) / det,
        ]
    };
    let ([a, b], [c, d]) = (solve(rx), solve(ry));
    let k3 = c.hypot(d);
    let q2 = [c / k3, d / k3];
    let q1 = [q2[1], -q2[0]];
    [[a * q1[0] + b * q1[1], a * q2[0] + b * q2[1]], [0.0, k3]]
}

/// A drift of 40 % of the slow-scan speed stretches the raw lattice by 40 % along the slow
/// axis and shears it by 23°: among the raw positions the local route finds too few
/// neighbour shells to fit a model. Seeded with the measured affine map, (a) the local
/// route finds its shells among the positions with the map undone, and (b) the global
/// registration started from the map alone (what the analysis falls back to when the local
/// route still fails) matches the truth too.
#[test]
fn strong_drift_is_analysed_from_the_measured_map() {
    let mut config = graphite_512();
    let scan = &config.scan;
    let line_s = scan.width_m / scan.fast_speed_m_per_s + scan.turnaround_s;
    let slow_speed = (scan.height_m / scan.rows as f64) / (2.0 * line_s);
    config
        .effects
        .retain(|e| !matches!(e, EffectConfig::Creep(_)));
    for effect in &mut config.effects {
        if let EffectConfig::ThermalDrift(ThermalDrift {
            velocity_m_per_s, ..
        }) = effect
        {
            *velocity_m_per_s = [0.25 * slow_speed, -0.4 * slow_speed];
        }
    }
    let mut run = common::simulate_and_find(&config);
    let inputs = common::pass_inputs(&run.sets);
    let geometry = run.output.pair.geometry();
    let seed = SeedMap::new(measured_map(&run)).expect("regular map");
    eprintln!("measured map {:?}", seed.file_per_sample);
    let lattice = run.lattice.as_ref();
    let options = DhctOptions::default();
    let local = analyse(&inputs, geometry, lattice, &options);
    assert!(
        local.is_err(),
        "without the map the local route fits: {:?}",
        local.map(|r| r.model)
    );
    let result =
        analyse_seeded(&inputs, geometry, lattice, &options, Some(&seed)).expect("analyses");
    let routes = result.routes.clone().expect("routes compared");
    eprintln!(
        "seeded: {:?} chosen; held-out rms local {:.2} pm, global {:.2} pm",
        routes.chosen,
        routes.local_held_out_rms_m * 1e12,
        routes.global_held_out_rms_m * 1e12
    );
    assert!(result.passes.iter().all(|p| p.local.len() > 300));
    run.result.model = result.model;
    let r = common::residuals(&run, 20.0);
    assert!(
        r.dhct <= 1.5 * r.noise_floor,
        "seeded: {} vs floor {}",
        r.dhct,
        r.noise_floor
    );
    let rough = seed.as_model(geometry).expect("a horizontal fast axis");
    registered_matches_truth(&mut run, rough, StartQuality::Rough);
}
