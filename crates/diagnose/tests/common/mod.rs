//! The scan the image-level tests share.

use dhct_simulate::SimulationConfig;

/// Graphite 512² over 6 nm at 100 nm/s (120 ms per line pair), drift, creep, power-law
/// hysteresis, 3 pm white + 2 pm pink noise and 5 pm line offsets; `extra` (more effects) is
/// appended as is.
pub fn graphite_512(name: &str, seed: u64, extra: &str) -> SimulationConfig {
    let text = format!(
        r#"
name = "{name}"
seed = {seed}
[scan]
columns = 512
rows = 512
width_m = 6e-9
height_m = 6e-9
fast_speed_m_per_s = 1e-7
turnaround_s = 0.0
trace_fast = "right"
slow = "down"
[surface.lattice]
kind = "graphite"
[surface.feature]
height_m = 4e-11
sigma_m = [6e-11, 6e-11]
[noise]
white_sigma_m = 3e-12
pink_sigma_m = 2e-12
line_offset_sigma_m = 5e-12
[output]
formats = []
[[effects]]
kind = "thermal-drift"
velocity_m_per_s = [3e-12, -2e-12]
acceleration_m_per_s2 = [-1e-15, 5e-16]
[[effects]]
kind = "creep"
coefficient_m = [2e-10, 5e-10]
t0_s = 60.0
[[effects]]
kind = "fast-hysteresis"
[effects.law]
kind = "power"
k = 0.93
n = -0.035
{extra}
"#
    );
    toml::from_str(&text).expect("the test config parses")
}
