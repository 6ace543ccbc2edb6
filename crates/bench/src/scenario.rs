//! The simulated scans the benchmarks run on, and the pipeline options they use.

use dhct_lattice::Lattice;
use dhct_pipeline::PipelineOptions;
use dhct_simulate::{SimulationConfig, presets};

/// Pixels along each side of the paper's headline image.
pub const HEADLINE_PIXELS: usize = 2048;

/// The headline case (`presets::headline_2048`: graphite, 25 nm over 2048 px, 100 nm/s,
/// drift + creep + hysteresis + noise) at `pixels` × `pixels` with the same pixel pitch
/// (12.2 pm) and tip speed, so the number of features grows with the number of pixels and
/// the frame time with its square (the line time grows with `pixels`).
pub fn headline_at(pixels: usize) -> SimulationConfig {
    let mut config = presets::headline_2048();
    let pitch_m = config.scan.width_m / config.scan.columns as f64;
    config.name = format!("headline-{pixels}");
    config.scan.columns = pixels;
    config.scan.rows = pixels;
    config.scan.width_m = pitch_m * pixels as f64;
    config.scan.height_m = pitch_m * pixels as f64;
    config
}

/// Options of every benchmark run: the pipeline's recommended defaults for the lattice
/// (`PipelineOptions::for_lattice`, what `dhct correct` uses: median line levelling,
/// affine local distortion), so the numbers describe the shipped behaviour.
pub fn pipeline_options(lattice: &dyn Lattice) -> PipelineOptions {
    PipelineOptions::for_lattice(lattice)
}
