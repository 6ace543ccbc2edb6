//! DHCT on the paper's headline case: graphite, 2048 × 2048 px trace + retrace over 25 nm
//! (simulated with drift, creep, hysteresis and noise). Times each stage — features,
//! neighbours + local distortion + model fit, correction of both images — and reports the
//! corrected-position error against the simulator's truth.
//!
//! `cargo bench -p dhct-distortion --bench distortion`

use std::time::Instant;

use dhct_distortion::{
    DhctOptions, PassInput, analyse, correct_features, correct_image, pixel_sample_positions,
};
use dhct_features::{FeatureOptions, LineCorrection, find_features_in_pair};
use dhct_scan::ScanPass;
use dhct_simulate::{Simulation, presets};

fn main() {
    let config = presets::headline_2048();
    let output = Simulation::from_config(&config)
        .expect("valid preset")
        .run()
        .expect("simulation");
    let geometry = output.pair.geometry();
    let lattice = config.surface.lattice.build().expect("lattice");

    let start = Instant::now();
    let options = FeatureOptions {
        line_correction: LineCorrection::Median,
        ..FeatureOptions::for_neighbour_distance(lattice.nearest_neighbour_distance())
    };
    let sets = find_features_in_pair(&output.pair, &options).expect("features");
    let features_s = start.elapsed().as_secs_f64();

    let start = Instant::now();
    let inputs: Vec<PassInput> = sets
        .iter()
        .map(|s| PassInput {
            features: &s.features,
            mask: None,
        })
        .collect();
    let result =
        analyse(&inputs, geometry, lattice.as_ref(), &DhctOptions::default()).expect("model fit");
    let model_s = start.elapsed().as_secs_f64();

    let start = Instant::now();
    let (trace, retrace) = rayon::join(
        || {
            correct_image(
                &result.model,
                geometry,
                ScanPass::Trace,
                &output.pair.trace().expect("trace").z,
            )
        },
        || {
            correct_image(
                &result.model,
                geometry,
                ScanPass::Retrace,
                &output.pair.retrace().expect("retrace").z,
            )
        },
    );
    let (_trace, _retrace) = (
        trace.expect("trace correction"),
        retrace.expect("retrace correction"),
    );
    let correction_s = start.elapsed().as_secs_f64();

    // Of which computing every pixel's sample-frame position (the resampling computes each
    // twice: once for the rows' extent, once where a band uses it).
    let start = Instant::now();
    rayon::join(
        || pixel_sample_positions(&result.model, geometry, ScanPass::Trace),
        || pixel_sample_positions(&result.model, geometry, ScanPass::Retrace),
    );
    let positions_s = start.elapsed().as_secs_f64();

    let count: usize = sets.iter().map(|s| s.features.len()).sum();
    println!("features:          {features_s:.3} s ({count} in trace + retrace)");
    println!("NN + local + fit:  {model_s:.3} s");
    println!("correction (2 images): {correction_s:.3} s");
    println!("  pixel positions once (2 images): {positions_s:.3} s");
    println!(
        "total:             {:.3} s on {} threads",
        features_s + model_s + correction_s,
        rayon::current_num_threads()
    );

    // Corrected features vs truth, after removing one global translation.
    let trace_set = &sets[0];
    let corrected = correct_features(&result.model, geometry, &trace_set.features);
    let mut pairs = Vec::new();
    for (f, c) in trace_set.features.iter().zip(&corrected) {
        let nearest = output.truth.features.iter().min_by(|a, b| {
            let d = |t: &dhct_simulate::FeatureTruth| {
                let p = t.trace.controller_position_px;
                (p[0] - f.x_px).hypot(p[1] - f.y_px)
            };
            d(a).total_cmp(&d(b))
        });
        if let Some(t) = nearest {
            pairs.push(([c.x_m, c.y_m], t.sample_position_m));
        }
    }
    let n = pairs.len() as f64;
    let shift = pairs.iter().fold([0.0, 0.0], |s, (c, t)| {
        [s[0] + (c[0] - t[0]) / n, s[1] + (c[1] - t[1]) / n]
    });
    let rms = (pairs
        .iter()
        .map(|(c, t)| (c[0] - t[0] - shift[0]).powi(2) + (c[1] - t[1] - shift[1]).powi(2))
        .sum::<f64>()
        / n)
        .sqrt();
    println!(
        "corrected trace features vs truth: rms {:.2} pm over {} features",
        rms * 1e12,
        pairs.len()
    );
}
