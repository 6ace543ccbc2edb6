//! Runs the diagnosis validation on one set only (its cases, summary and confusion
//! matrix), e.g. the image-path development set:
//!
//! ```text
//! cargo run --release -p dhct-diagnose --example validate_set -- rendered-dev
//! ```
//! (set names as printed by the full sweep: `tuned`, `held-out`, `foreign-2`,
//! `rendered-dev`, `rendered`, `rendered-2`, `rendered-3`, …).

use dhct_diagnose::synth::ValidationSet;
use dhct_diagnose::{
    ValidationOptions, rendered_held_out, second_rendered_held_out, third_rendered_held_out,
    validate,
};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let name = std::env::args().nth(1).ok_or("usage: validate_set SET")?;
    let set = ValidationSet::ALL
        .into_iter()
        .find(|s| s.name() == name)
        .ok_or_else(|| format!("no validation set named {name:?}"))?;
    let mut options = ValidationOptions::default();
    options.sets.retain(|s| s.set == set);
    // The image-path held-out sets are fixed but not in the default sweep: each is run
    // once, when the method is final.
    if set == ValidationSet::Rendered {
        options.sets = vec![rendered_held_out()];
    }
    if set == ValidationSet::SecondRendered {
        options.sets = vec![second_rendered_held_out()];
    }
    if set == ValidationSet::ThirdRendered {
        options.sets = vec![third_rendered_held_out()];
    }
    let report = validate(&options);
    println!("{report}");
    println!("floors (pm):");
    for c in &report.cases {
        let [x, y] = c.noise_floor_m.map(|v| v * 1e12);
        println!("{:<44} {x:.2} × {y:.2}", c.name);
    }
    Ok(())
}
