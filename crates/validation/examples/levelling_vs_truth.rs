//! The feature finder's centres against the simulator's truth, pass by pass, on an
//! effect-free scan of a validation set: how far the line levelling moves them across the
//! lines. The line offsets are known exactly (the scan is rendered a second time without
//! them), so the lines can also be levelled by the truth to see what levelling costs.
//!
//! ```text
//! cargo run --release -p dhct-validation --example levelling_vs_truth -- 112007 [tilted] [options]
//! ```
//! Options, any of: `keep=hdc` (the base effects kept: h hysteresis, d drift, c creep; all
//! by default), `offsets=PM` (the line offsets' rms in pm), `no-pink`, `no-white`, `flat`
//! (no tilted plane), `true-levels` (the true offsets subtracted before the features are
//! found), `levelling=lattice|median|none` (lattice by default), `levels-from-fits` (the
//! lines' levels fitted jointly with the features afterwards: `line_levels_from_fits`).

use dhct_features::{FeatureOptions, FeatureSet, LineCorrection, find_features_in_pair};
use dhct_scan::{ImageChannel, ScanPair};
use dhct_simulate::{EffectConfig, Simulation, SimulationConfig, SimulationOutput};
use dhct_validation::{ValidationCase, ValidationSet};

type Failure = Box<dyn std::error::Error>;

fn main() -> Result<(), Failure> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let seed: u64 = args.first().ok_or("a seed is needed")?.parse()?;
    let option = |key: &str| args.iter().find_map(|a| a.strip_prefix(key));
    let flag = |name: &str| args.iter().any(|a| a == name);
    let set = args
        .iter()
        .skip(1)
        .find_map(|a| ValidationSet::named(a).ok())
        .map_or_else(|| ValidationSet::named("tilted"), Ok)?;
    let mut config = ValidationCase::effect_free(seed, &set).config;
    let keep = option("keep=").unwrap_or("hdc");
    config.effects.retain(|e| match e {
        EffectConfig::FastHysteresis(_) => keep.contains('h'),
        EffectConfig::ThermalDrift(_) => keep.contains('d'),
        EffectConfig::Creep(_) => keep.contains('c'),
        _ => true,
    });
    if let Some(pm) = option("offsets=") {
        config.noise.line_offset_sigma_m = pm.parse::<f64>()? * 1e-12;
    }
    if flag("no-pink") {
        config.noise.pink_sigma_m = 0.0;
    }
    if flag("no-white") {
        config.noise.white_sigma_m = 0.0;
    }
    if flag("flat") {
        config.surface.plane_slope = [0.0, 0.0];
    }
    let levelling = match option("levelling=") {
        None => LineCorrection::Lattice,
        Some(name) => [
            LineCorrection::None,
            LineCorrection::Median,
            LineCorrection::Tapered,
            LineCorrection::Lattice,
            LineCorrection::Linear,
        ]
        .into_iter()
        .find(|l| l.name() == name)
        .ok_or_else(|| format!("no line levelling is called {name:?}"))?,
    };
    println!(
        "{} #{seed}: effects kept {keep:?}, line offsets {:.2} pm, lattice rows at {:.4} rad",
        set.name,
        config.noise.line_offset_sigma_m * 1e12,
        config.surface.angle_rad
    );
    let mut output = Simulation::from_config(&config)?.run()?;
    if flag("true-levels") {
        output.pair = without_true_offsets(&output, &config)?;
    }
    let lattice = config.surface.lattice.build()?;
    let options = FeatureOptions {
        line_correction: levelling,
        line_levels_from_fits: flag("levels-from-fits"),
        ..FeatureOptions::for_neighbour_distance(lattice.nearest_neighbour_distance())
    };
    for set in find_features_in_pair(&output.pair, &options)? {
        report_pass(&set, &output);
    }
    Ok(())
}

/// `output`'s pair less each line's true offset: the same scan rendered without line
/// offsets differs from it by exactly those.
fn without_true_offsets(
    output: &SimulationOutput,
    config: &SimulationConfig,
) -> Result<ScanPair, Failure> {
    let mut clean = config.clone();
    clean.noise.line_offset_sigma_m = 0.0;
    let without = Simulation::from_config(&clean)?.run()?;
    let levelled = |with: Option<&ImageChannel>, without: Option<&ImageChannel>| {
        let (with, without) = (with.ok_or("a pass")?, without.ok_or("a pass")?);
        let mut image = with.clone();
        for ((r, _), v) in image.z.indexed_iter_mut() {
            *v -= with.z[[r, 0]] - without.z[[r, 0]];
        }
        Ok::<ImageChannel, Failure>(image)
    };
    let trace = levelled(output.pair.trace(), without.pair.trace())?;
    let retrace = levelled(output.pair.retrace(), without.pair.retrace())?;
    Ok(ScanPair::new(
        output.pair.geometry().clone(),
        trace,
        Some(retrace),
    )?)
}

/// Prints the centres of `set` (one pass) against the truth across the lines (pm): mean,
/// rms, and the mean in each quarter along the lines (a shear shows as a trend).
fn report_pass(set: &FeatureSet, output: &SimulationOutput) {
    let geometry = &output.truth.geometry;
    let (columns, pitch_pm) = (geometry.columns() as f64, geometry.pitch_y() * 1e12);
    let errors: Vec<(f64, f64)> = set
        .features
        .iter()
        .filter_map(|f| {
            let truth = output
                .truth
                .features
                .iter()
                .map(|t| t.acquisition(set.pass).controller_position_px);
            let distance2 = |p: &[f64; 2]| (p[0] - f.x_px).powi(2) + (p[1] - f.y_px).powi(2);
            let nearest = truth.min_by(|a, b| distance2(a).total_cmp(&distance2(b)))?;
            (distance2(&nearest) < 4.0).then(|| (f.x_px, (f.y_px - nearest[1]) * pitch_pm))
        })
        .collect();
    let mean = |e: &[(f64, f64)]| e.iter().map(|e| e.1).sum::<f64>() / e.len() as f64;
    let all_mean = mean(&errors);
    let rms =
        (errors.iter().map(|e| (e.1 - all_mean).powi(2)).sum::<f64>() / errors.len() as f64).sqrt();
    let quarters: Vec<String> = (0..4)
        .map(|q| {
            let part: Vec<(f64, f64)> = errors
                .iter()
                .copied()
                .filter(|e| ((e.0 / columns * 4.0) as usize).min(3) == q)
                .collect();
            format!("{:.2}", mean(&part))
        })
        .collect();
    println!(
        "{}: {} of {} matched; across the lines mean {all_mean:.2} pm, rms {rms:.2} pm; \
         by quarter along the lines {quarters:?} pm\n  {}",
        set.pass,
        errors.len(),
        set.features.len(),
        set.line_levelling
    );
}
