//! Wall time of the `ci-small` and `headline-2048` presets (trace + retrace + ground truth),
//! and the process's peak memory.
//!
//! `cargo bench -p dhct-simulate` (release build; uses all cores rayon sees, set
//! `RAYON_NUM_THREADS` to change). Prints one line per preset; not a timed test.

use std::time::Instant;

use dhct_simulate::{Simulation, SimulationConfig, presets};

/// Peak resident memory from /proc/self/status (`VmHWM`), if available.
fn peak_memory() -> String {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|status| {
            status
                .lines()
                .find(|line| line.starts_with("VmHWM:"))
                .map(|line| line.trim_start_matches("VmHWM:").trim().to_string())
        })
        .unwrap_or_else(|| "unknown".into())
}

fn time(config: &SimulationConfig, repeats: usize) -> Result<(), Box<dyn std::error::Error>> {
    let simulation = Simulation::from_config(config)?;
    let mut best = f64::INFINITY;
    let mut features = 0;
    for _ in 0..repeats {
        let started = Instant::now();
        let output = simulation.run()?;
        best = best.min(started.elapsed().as_secs_f64());
        features = output.truth.features.len();
    }
    let g = simulation.geometry();
    println!(
        "{:14} {:5} x {:5} px pair, {:6} features: best of {repeats}: {:8.3} s  ({:.1} ns/px incl. truth)  peak RSS so far {}",
        config.name,
        g.columns(),
        g.rows(),
        features,
        best,
        best * 1e9 / (2.0 * g.columns() as f64 * g.rows() as f64),
        peak_memory(),
    );
    Ok(())
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    // `cargo bench` passes `--bench`; ignore arguments.
    println!("rayon threads: {}", rayon::current_num_threads());
    time(&presets::ci_small(), 10)?;
    time(&presets::headline_2048(), 3)?;
    Ok(())
}
