//! Simulates a graphite scan with one effect the base DHCT model does not know about,
//! diagnoses it, and prints the report.
//!
//! ```text
//! cargo run --release -p dhct-validation --example diagnose_simulated -- tip-change 1 [images] [dev-2]
//! ```
//! (effect: any candidate name, or `none`; seed; `images` = render and find features; the
//! validation set whose physics is drawn, by its name in `sets.toml` (default `tuned`);
//! `law=cubic|quartic|exponential|power`: the base model's fast-scan hysteresis law).

use dhct_diagnose::{Candidate, DiagnoseOptions, diagnose};
use dhct_simulate::EffectConfig;
use dhct_validation::{
    BaseLaw, ValidationCase, ValidationSet, simulate_images, simulate_positions,
};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let effect = args.get(1).map_or("tip-change", |s| s.as_str());
    let seed: u64 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(1);
    let rest = args.get(3..).unwrap_or_default();
    let images = rest.iter().any(|s| s == "images");
    let set = rest
        .iter()
        .find_map(|s| ValidationSet::named(s).ok())
        .unwrap_or_else(|| ValidationSet::named("tuned").expect("a shipped set"));
    let mut case = match Candidate::ALL.iter().find(|c| c.name() == effect) {
        Some(&c) => ValidationCase::single(c, seed, &set),
        None => ValidationCase::effect_free(seed, &set),
    };
    let law = rest.iter().find_map(|s| match s.strip_prefix("law=")? {
        "cubic" => Some(BaseLaw::Cubic),
        "quartic" => Some(BaseLaw::Quartic),
        "exponential" => Some(BaseLaw::Exponential),
        "power" => Some(BaseLaw::Power),
        _ => None,
    });
    if let Some(law) = law {
        let line_s = case.config.scan.width_m / case.config.scan.fast_speed_m_per_s;
        for e in &mut case.config.effects {
            if let EffectConfig::FastHysteresis(h) = e {
                h.law = law.draw(seed, line_s);
            }
        }
    }
    println!(
        "case {}: {:?}\n{:?}",
        case.name, case.truth, case.config.effects
    );
    let start = std::time::Instant::now();
    let scan = if images {
        simulate_images(&case.config)?
    } else {
        simulate_positions(&case.config, 2e-12, seed)?
    };
    let lattice = case.config.surface.lattice.build()?;
    println!(
        "{} + {} features, simulated in {:.2} s",
        scan.trace.len(),
        scan.retrace.len(),
        start.elapsed().as_secs_f64()
    );
    let start = std::time::Instant::now();
    let report = diagnose(
        &scan.inputs(),
        &scan.geometry,
        lattice.as_ref(),
        &DiagnoseOptions::default(),
    )?;
    println!("{report}");
    println!("diagnosed in {:.2} s", start.elapsed().as_secs_f64());
    Ok(())
}
