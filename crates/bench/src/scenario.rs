//! The simulated scans the benchmarks run on, and the pipeline options they use.

use dhct_lattice::Lattice;
use dhct_pipeline::PipelineOptions;
use dhct_simulate::{SimulationConfig, presets};

/// Pixels along each side of the paper's headline image.
pub const HEADLINE_PIXELS: usize = 2048;

/// How the tip speed follows the image size in [`headline_at`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SpeedScaling {
    /// The headline's 100 nm/s at every size: the line time grows with the pixels, so
    /// drift distorts a larger image more (an 8192² frame would take 4.5 h and be stretched
    /// four times as much as the headline).
    SameSpeed,
    /// The headline's line time (0.25 s) at every size: the speed grows with the pixels,
    /// the frame time with the pixels, and drift distorts every size by the same fraction.
    SameLineTime,
}

/// The headline case (`presets::headline_2048`: graphite, 25 nm over 2048 px, 100 nm/s,
/// drift + creep + hysteresis + noise) at `pixels` × `pixels` with the same pixel pitch
/// (12.2 pm), so the number of features grows with the number of pixels; the tip speed as
/// `speed` says.
pub fn headline_at(pixels: usize, speed: SpeedScaling) -> SimulationConfig {
    let mut config = presets::headline_2048();
    let pitch_m = config.scan.width_m / config.scan.columns as f64;
    if speed == SpeedScaling::SameLineTime {
        config.scan.fast_speed_m_per_s *= pixels as f64 / config.scan.columns as f64;
    }
    config.name = format!("headline-{pixels}");
    config.scan.columns = pixels;
    config.scan.rows = pixels;
    config.scan.width_m = pitch_m * pixels as f64;
    config.scan.height_m = pitch_m * pixels as f64;
    // Above the simulator's default 2 GiB (about 5120² px), allow what the image needs.
    let needed_gib = (pixels * pixels) as f64 * dhct_simulate::config::BYTES_PER_PIXEL as f64
        / (1u64 << 30) as f64;
    if needed_gib > 2.0 {
        config.scan.memory_limit_gib = Some(needed_gib.ceil());
    }
    config
}

/// Options of every benchmark run: the pipeline's recommended defaults for the lattice
/// (`PipelineOptions::for_lattice`, what `dhct correct` uses: median line levelling,
/// affine local distortion), so the numbers describe the shipped behaviour.
pub fn pipeline_options(lattice: &dyn Lattice) -> PipelineOptions {
    PipelineOptions::for_lattice(lattice)
}
