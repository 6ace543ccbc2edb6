//! Shared by the feature tests against simulator ground truth.

use dhct_simulate::{SimulationConfig, presets};

/// The headline preset cut to 512 × 512 px at the same pixel pitch (12.2 pm).
pub fn headline_512() -> SimulationConfig {
    let mut config = presets::headline_2048();
    config.scan.columns = 512;
    config.scan.rows = 512;
    config.scan.width_m = 25e-9 / 4.0;
    config.scan.height_m = 25e-9 / 4.0;
    config
}
