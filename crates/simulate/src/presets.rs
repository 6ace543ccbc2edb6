//! Ready-made simulations. Each is a TOML file under `crates/simulate/presets/` (the only
//! place a preset's numbers are written), embedded in the library, so a user can copy one,
//! edit it and pass it to `dhct simulate --config`.
//!
//! * `fig3-*`: the DHCT paper's Fig. 3 situation — a hexagonal lattice with 1 nm spacing,
//!   512 × 512 px over 20 nm, 50 nm/s fast scan, no noise — without drift and with 10 pm/s
//!   of drift along the fast axis, along the slow scan and against it. (The paper's exact
//!   panel list is not available here; these are the cases its text discusses.) The slow
//!   speed is 50 nm/s / 1024 = 48.8 pm/s, so 10 pm/s changes the slow scale by 20.5 %.
//! * `headline-2048`: the paper's Fig. 4 headline acquisition — graphite (a = 2.46 Å),
//!   2048 × 2048 px over 25 nm, 100 nm/s, trace and retrace — with drift, acceleration,
//!   creep, power-law hysteresis and noise of typical room-temperature magnitude.
//! * `ci-small`: the same physics on 256 × 256 px over 4 nm of graphite; runs in well
//!   under a second.
//! * `graphite-sequence`: an image sequence ([`crate::sequence`]) of 12 such frames, 3 s
//!   apart, with drift continuous over the session (a slow oscillation, initial creep, a
//!   move with its own creep before frame 6).

use crate::SimulationConfig;
use crate::SimulationError;

/// One named preset.
#[derive(Debug, Clone, Copy)]
pub struct Preset {
    /// Name for `dhct simulate --preset`, also the TOML file's stem.
    pub name: &'static str,
    /// One line on what it shows.
    pub summary: &'static str,
    /// The shipped TOML file's text.
    pub toml: &'static str,
}

impl Preset {
    /// The preset's config, parsed from its TOML.
    pub fn config(&self) -> Result<SimulationConfig, SimulationError> {
        SimulationConfig::from_toml_str(self.toml)
    }
}

/// Every preset.
pub const ALL: [Preset; 7] = [
    Preset {
        name: "fig3a-no-drift",
        summary: "Fig. 3 lattice (1 nm, 512², 50 nm/s) without drift",
        toml: include_str!("../presets/fig3a-no-drift.toml"),
    },
    Preset {
        name: "fig3b-drift-fast",
        summary: "Fig. 3 lattice with 10 pm/s drift along +x (the fast axis)",
        toml: include_str!("../presets/fig3b-drift-fast.toml"),
    },
    Preset {
        name: "fig3c-drift-along-slow",
        summary: "Fig. 3 lattice with 10 pm/s drift along +y (with the slow scan)",
        toml: include_str!("../presets/fig3c-drift-along-slow.toml"),
    },
    Preset {
        name: "fig3d-drift-against-slow",
        summary: "Fig. 3 lattice with 10 pm/s drift along −y (against the slow scan)",
        toml: include_str!("../presets/fig3d-drift-against-slow.toml"),
    },
    Preset {
        name: "headline-2048",
        summary: "Fig. 4 headline: graphite, 2048², 25 nm, 100 nm/s, drift+creep+hysteresis+noise",
        toml: include_str!("../presets/headline-2048.toml"),
    },
    Preset {
        name: "ci-small",
        summary: "CI-sized graphite, 256², 4 nm, drift+creep+hysteresis+noise",
        toml: include_str!("../presets/ci-small.toml"),
    },
    Preset {
        name: "graphite-sequence",
        summary: "12-frame sequence of ci-small-like graphite frames, drift+oscillation+creep, a move",
        toml: include_str!("../presets/graphite-sequence.toml"),
    },
];

/// The preset called `name`.
pub fn by_name(name: &str) -> Result<SimulationConfig, SimulationError> {
    ALL.iter()
        .find(|p| p.name == name)
        .ok_or_else(|| SimulationError::UnknownPreset {
            name: name.to_string(),
            known: ALL.map(|p| p.name).join(", "),
        })?
        .config()
}

/// A shipped preset by name, for the shorthands below.
///
/// # Panics
/// Only if a shipped file does not parse, which `tests/presets.rs` rules out.
fn shipped(name: &str) -> SimulationConfig {
    by_name(name).unwrap_or_else(|e| panic!("shipped preset {name}: {e}"))
}

/// Fig. 3: hexagonal lattice, a = 1 nm, 512², 20 nm, 50 nm/s, no drift.
pub fn fig3_no_drift() -> SimulationConfig {
    shipped("fig3a-no-drift")
}

/// Fig. 3 with 10 pm/s tip drift along +x: lines shear, the trace is stretched by
/// 1 + 10 pm/s / 50 nm/s along x and the retrace compressed by the same amount.
pub fn fig3_drift_fast() -> SimulationConfig {
    shipped("fig3b-drift-fast")
}

/// Fig. 3 with 10 pm/s tip drift along +y, with the downward slow scan: the slow scale is
/// stretched by 1 + 10/48.83, so the lattice looks compressed along y.
pub fn fig3_drift_along_slow() -> SimulationConfig {
    shipped("fig3c-drift-along-slow")
}

/// Fig. 3 with 10 pm/s tip drift along −y, against the slow scan: the slow scale shrinks
/// by 1 − 10/48.83, so the lattice looks stretched along y.
pub fn fig3_drift_against_slow() -> SimulationConfig {
    shipped("fig3d-drift-against-slow")
}

/// The paper's Fig. 4 headline acquisition: graphite, 2048 × 2048 px over 25 nm, 100 nm/s
/// (pixel period 122 µs, line 0.25 s, frame 1024 s, slow speed 24.4 pm/s), trace and
/// retrace, with drift (3, −2) pm/s, acceleration (−1, 0.5) fm/s², creep C = (0.2, 0.5) nm
/// with t0 = 60 s, the power-law hysteresis S = 0.93·τ^−0.035 (S ≈ 1.16 at 2 ms, 0.98 at
/// the line end) and 3 pm white, 2 pm 1/f, 5 pm line-offset noise and rare 50 pm spikes.
pub fn headline_2048() -> SimulationConfig {
    shipped("headline-2048")
}

/// A CI-sized version: graphite, 256 × 256 px over 4 nm, 50 nm/s (line 80 ms, frame 41 s,
/// slow speed 97.7 pm/s), drift (5, −8) pm/s, creep C = (0.1, 0.2) nm with t0 = 20 s,
/// hysteresis S = 0.95·τ^−0.03, 2 pm white noise.
pub fn ci_small() -> SimulationConfig {
    shipped("ci-small")
}

/// An image sequence ([`crate::SequenceSimulation`]): 12 frames of graphite, 256 × 256 px
/// over 4 nm at 50 nm/s (frame 40.96 s), one every 44 s (3 s pause, rounded up); session
/// drift (3, −2) pm/s with acceleration (1, 0) fm/s² and a (0.2, 0.1) nm oscillation of
/// period 260 s, initial creep C = (0.1, 0.05) nm with t0 = 20 s, a move to (1, −0.5) nm before
/// frame 6 with creep C = (0.2, −0.1) nm, t0 = 5 s; hysteresis S = 0.95·τ^−0.03 and 2 pm white
/// noise as in [`ci_small`].
pub fn graphite_sequence() -> SimulationConfig {
    shipped("graphite-sequence")
}
