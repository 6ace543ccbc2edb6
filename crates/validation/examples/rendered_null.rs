//! Renders effect-free scans with a base model that differs from dhct's (the `foreign-dev`
//! validation set: other fast-scan hysteresis laws, slow-scan hysteresis), adds image noise,
//! finds the features with a chosen line levelling and diagnoses each scan: a false-alarm
//! check on the image path (`docs/diagnose.md`, "Not done"). Also prints how far the
//! found centres scatter about the simulated truth against what their fits report, and
//! the floor's estimates.
//!
//! ```text
//! cargo run --release -p dhct-validation --example rendered_null -- LEVELLING WHITE_PM OFFSETS_PM PINK_PM [first=51001] [n=16]
//! ```
//! (`LEVELLING`: `none`, `median`, `tapered`, `linear` or `lattice`; the noise RMS values in
//! picometres: white per pixel, one offset per scan line, 1/f over the acquisition; with
//! `look=1` the `rendered-dev` set's scans with their own noise and atom shapes instead,
//! `effect=NAME` adds that effect to them, `coupling=0` keeps a height coupling's step
//! edge but not its lateral shift, `vibration_mhz=N` sets a vibration's frequency, and
//! `summary=1` prints the verdict in words). With a
//! step edge, the centres' y error is also shown by distance from it.

use dhct_diagnose::{Candidate, DiagnoseOptions, diagnose, sub_feature_view_of_pair};
use dhct_features::{FeatureOptions, LineCorrection, find_features_in_pair};
use dhct_scan::ScanPass;
use dhct_simulate::Simulation;
use dhct_validation::{
    PositionNoise, SimulatedScan, ValidationCase, ValidationSet, simulate_positions_with,
};

fn levelling(name: &str) -> Option<LineCorrection> {
    Some(match name {
        "none" => LineCorrection::None,
        "median" => LineCorrection::Median,
        "tapered" => LineCorrection::Tapered,
        "linear" => LineCorrection::Linear,
        "lattice" => LineCorrection::Lattice,
        _ => return None,
    })
}

/// The value of `key=…` among `args`, or `default`.
/// The image-path set named by `set=NAME` (default `rendered-dev`).
fn image_set(args: &[String]) -> ValidationSet {
    args.iter()
        .find_map(|a| a.strip_prefix("set="))
        .and_then(|name| ValidationSet::named(name).ok())
        .unwrap_or_else(|| ValidationSet::named("rendered-dev").expect("a shipped set"))
}

fn keyed(args: &[String], key: &str, default: u64) -> u64 {
    args.iter()
        .find_map(|s| s.strip_prefix(key)?.strip_prefix('=')?.parse().ok())
        .unwrap_or(default)
}

/// The found centres' scatter about the noise-free simulated positions (metres per axis,
/// the mean offset removed; matched within 3 px) and the RMS of their fits' 1σ.
fn scatter_against_truth(
    case: &ValidationCase,
    scan: &SimulatedScan,
) -> Result<([f64; 2], [f64; 2]), Box<dyn std::error::Error>> {
    let exact = simulate_positions_with(&case.config, &PositionNoise::white(0.0), 0)?;
    let pitch = [scan.geometry.pitch_x(), scan.geometry.pitch_y()];
    let (mut errors, mut reported) = (Vec::new(), [0.0; 2]);
    let mut errors_at = Vec::new();
    for (found, truth) in [(&scan.trace, &exact.trace), (&scan.retrace, &exact.retrace)] {
        for f in found {
            let distance2 =
                |t: &dhct_features::Feature| (t.x_px - f.x_px).powi(2) + (t.y_px - f.y_px).powi(2);
            let nearest = truth
                .iter()
                .min_by(|a, b| distance2(a).total_cmp(&distance2(b)));
            if let Some(t) = nearest.filter(|t| distance2(t) < 9.0) {
                errors.push([(f.x_px - t.x_px) * pitch[0], (f.y_px - t.y_px) * pitch[1]]);
                errors_at.push(([t.x_px, t.y_px], *errors.last().unwrap()));
                reported[0] += (f.x_sigma_px * pitch[0]).powi(2);
                reported[1] += (f.y_sigma_px * pitch[1]).powi(2);
            }
        }
    }
    let n = errors.len().max(1) as f64;
    let spread = |a: usize| {
        let mean = errors.iter().map(|e| e[a]).sum::<f64>() / n;
        (errors.iter().map(|e| (e[a] - mean).powi(2)).sum::<f64>() / n).sqrt()
    };
    step_profile(case, scan, &errors_at);
    Ok(([spread(0), spread(1)], reported.map(|r| (r / n).sqrt())))
}

/// The centres' y error RMS by distance from the first step edge (controller frame,
/// neighbour distances), when the scan has one.
fn step_profile(case: &ValidationCase, scan: &SimulatedScan, errors_at: &[([f64; 2], [f64; 2])]) {
    let Some(step) = case.config.surface.steps.first() else {
        return;
    };
    let dhct_simulate::Region::HalfPlane { point_m, normal } = step.region else {
        return;
    };
    let nn = case
        .config
        .surface
        .lattice
        .build()
        .map(|l| l.nearest_neighbour_distance())
        .unwrap_or(1.0);
    let norm = normal[0].hypot(normal[1]);
    let pitch = [scan.geometry.pitch_x(), scan.geometry.pitch_y()];
    let edges = [0.0, 0.5, 1.0, 1.5, 2.0, 3.0, 5.0, f64::INFINITY];
    let mut line = String::from("    y error by distance from the step (nn):");
    for w in edges.windows(2) {
        let e: Vec<f64> = errors_at
            .iter()
            .filter(|(at, _)| {
                let d = ((at[0] * pitch[0] - point_m[0]) * normal[0]
                    + (at[1] * pitch[1] - point_m[1]) * normal[1])
                    .abs()
                    / norm
                    / nn;
                d >= w[0] && d < w[1]
            })
            .map(|(_, e)| e[1])
            .collect();
        let rms = (e.iter().map(|v| v * v).sum::<f64>() / e.len().max(1) as f64).sqrt();
        line += &format!(" <{}: {:.1} pm ({})", w[1], rms * 1e12, e.len());
    }
    println!("{line}");
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let usage = "usage: rendered_null LEVELLING WHITE_PM OFFSETS_PM PINK_PM [first=N] [n=N]";
    let line_correction = args.get(1).and_then(|s| levelling(s)).ok_or(usage)?;
    let picometres = |i: usize| -> Result<f64, Box<dyn std::error::Error>> {
        Ok(args.get(i).ok_or(usage)?.parse::<f64>()? * 1e-12)
    };
    let (white, offsets, pink) = (picometres(2)?, picometres(3)?, picometres(4)?);
    let first = keyed(&args, "first", 51001);
    for seed in first..first + keyed(&args, "n", 16) {
        // `look=1`: the image-path development set's scans, their own noise and atoms.
        let case = if keyed(&args, "look", 0) == 1 {
            let effect = args.iter().find_map(|a| a.strip_prefix("effect="));
            let effects: Vec<Candidate> = Candidate::ALL
                .into_iter()
                .filter(|c| effect == Some(c.name()))
                .collect();
            let mut case = ValidationCase::with_effects(&effects, seed, &image_set(&args));
            let vibration_mhz = keyed(&args, "vibration_mhz", 0);
            for e in &mut case.config.effects {
                if let (dhct_simulate::EffectConfig::Vibration(v), true) = (e, vibration_mhz > 0) {
                    v.frequency_hz = vibration_mhz as f64 * 1e-3;
                }
            }
            if keyed(&args, "coupling", 1) == 0 {
                for e in &mut case.config.effects {
                    if let dhct_simulate::EffectConfig::HeightCoupling(c) = e {
                        c.lateral_per_height = [0.0; 2];
                    }
                }
            }
            case
        } else {
            let mut case = ValidationCase::effect_free(
                seed,
                &ValidationSet::named("foreign-dev").expect("a shipped set"),
            );
            case.config.noise.white_sigma_m = white;
            case.config.noise.line_offset_sigma_m = offsets;
            case.config.noise.pink_sigma_m = pink;
            case
        };
        let output = Simulation::from_config(&case.config)?.run()?;
        let lattice = case.config.surface.lattice.build()?;
        let options = FeatureOptions {
            line_correction,
            ..FeatureOptions::for_neighbour_distance(lattice.nearest_neighbour_distance())
        };
        let mut scan = SimulatedScan {
            geometry: output.pair.geometry().clone(),
            trace: Vec::new(),
            retrace: Vec::new(),
        };
        let sets = find_features_in_pair(&output.pair, &options)?;
        let view = sub_feature_view_of_pair(
            &output.pair,
            &sets.iter().collect::<Vec<_>>(),
            &options,
            None,
        );
        for set in sets {
            println!(
                "    {:?}: correlated-noise factor {:.2} × {:.2}",
                set.pass, set.correlated_noise_factor[0], set.correlated_noise_factor[1]
            );
            match set.pass {
                ScanPass::Trace => scan.trace = set.features,
                ScanPass::Retrace => scan.retrace = set.features,
            }
        }
        let options = DiagnoseOptions::default();
        match diagnose(&scan.inputs(), &scan.geometry, lattice.as_ref(), &options) {
            Ok(report) => {
                let report = match view {
                    Some(view) => report.with_sub_feature_view(view),
                    None => report,
                };
                let v = &report.verdict_details;
                let named: Vec<&str> = v.effects.iter().map(|c| c.name()).collect();
                println!(
                    "seed {seed}: {:?}, gap {:.2} -> {:.2}, named {named:?}",
                    report.verdict, v.gap_before, v.gap_after
                );
                if keyed(&args, "summary", 0) == 1 {
                    println!("    {}", v.summary);
                }
                if let Some(view) = &report.sub_feature {
                    println!("    {}", view.describe());
                }
                let n = &report.noise;
                println!(
                    "    floor {:.2} × {:.2} pm from {}",
                    n.sigma_m[0] * 1e12,
                    n.sigma_m[1] * 1e12,
                    n.source.describe()
                );
                let rms = report.base.gap.rms_m;
                println!(
                    "    base model's residual {:.2} × {:.2} pm ({:.2} × {:.2} floors)",
                    rms[0] * 1e12,
                    rms[1] * 1e12,
                    rms[0] / n.sigma_m[0],
                    rms[1] / n.sigma_m[1]
                );
                println!(
                    "    localisation {}, successive {}, trace/retrace {}",
                    n.localisation.describe(),
                    n.successive_differences.describe(),
                    n.trace_retrace.describe()
                );
            }
            Err(e) => println!("seed {seed}: {e}"),
        }
        let (truth, reported) = scatter_against_truth(&case, &scan)?;
        println!(
            "    centres vs truth: scatter {:.2} × {:.2} pm, fits' 1σ {:.2} × {:.2} pm",
            truth[0] * 1e12,
            truth[1] * 1e12,
            reported[0] * 1e12,
            reported[1] * 1e12
        );
    }
    Ok(())
}
