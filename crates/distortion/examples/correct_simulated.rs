//! Simulates the CI-sized graphite scan (drift, creep, hysteresis, noise), finds the atoms,
//! fits the DHCT model to trace and retrace, and prints the parameters and how far the
//! corrected features are from the truth.
//!
//! ```text
//! cargo run --release -p dhct-distortion --example correct_simulated
//! ```

use dhct_distortion::{DhctOptions, PassInput, analyse, correct_features, correct_image};
use dhct_features::{FeatureOptions, find_features_in_pair};
use dhct_scan::ScanPass;
use dhct_simulate::{Simulation, presets};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let config = presets::ci_small();
    let output = Simulation::from_config(&config)?.run()?;
    let geometry = output.pair.geometry();
    let lattice = config.surface.lattice.build()?;
    let options = FeatureOptions::for_neighbour_distance(lattice.nearest_neighbour_distance());
    let sets = find_features_in_pair(&output.pair, &options)?;
    let inputs: Vec<PassInput> = sets
        .iter()
        .map(|s| PassInput {
            features: &s.features,
            mask: None,
        })
        .collect();
    let result = analyse(&inputs, geometry, lattice.as_ref(), &DhctOptions::default())?;
    for pass in &result.passes {
        println!(
            "{:?}: {} features, {} with 6 neighbours, excluded {:?}",
            pass.pass,
            inputs
                .iter()
                .find(|i| i.features[0].pass == pass.pass)
                .map_or(0, |i| i.features.len()),
            pass.selection.selected.len(),
            pass.selection.exclusions
        );
    }
    println!("fitted model:");
    for p in &result.model.parameters {
        println!(
            "  {:>4} = {:+.4e} ± {:.1e} {}",
            p.name, p.value, p.sigma, p.unit
        );
    }
    println!(
        "truth: v = (5e-12, -8e-12) m/s, C = (1e-10, 2e-10) m, t0 = 20 s, k = 0.95, n = -0.03"
    );

    // Corrected features vs the truth's sample positions (nearest truth feature).
    let (px, py) = (geometry.pitch_x(), geometry.pitch_y());
    for set in &sets {
        let corrected = correct_features(&result.model, geometry, &set.features);
        let mut sum = 0.0;
        let mut count = 0;
        for (f, c) in set.features.iter().zip(&corrected) {
            let nearest = output.truth.features.iter().min_by(|a, b| {
                let pos = |t: &dhct_simulate::FeatureTruth| match set.pass {
                    ScanPass::Trace => t.trace.controller_position_px,
                    ScanPass::Retrace => t.retrace.controller_position_px,
                };
                let d = |p: [f64; 2]| (p[0] - f.x_px).hypot(p[1] - f.y_px);
                d(pos(a)).total_cmp(&d(pos(b)))
            });
            if let Some(t) = nearest {
                sum += (c.x_m - t.sample_position_m[0]).powi(2)
                    + (c.y_m - t.sample_position_m[1]).powi(2);
                count += 1;
            }
        }
        println!(
            "{:?}: rms corrected - true position {:.2} pm over {count} features ({:.3} px)",
            set.pass,
            (sum / count.max(1) as f64).sqrt() * 1e12,
            (sum / count.max(1) as f64).sqrt() / px.min(py)
        );
        if let Some(image) = output.pair.image(set.pass) {
            let corrected = correct_image(&result.model, geometry, set.pass, &image.z)?;
            let empty = corrected.iter().filter(|v| v.is_nan()).count();
            println!(
                "  corrected image: {} of {} pixels have no data (NaN)",
                empty,
                corrected.len()
            );
        }
    }
    Ok(())
}
