//! `dhct.simulate`: the forward simulator of STM acquisition, returning the scan and its
//! ground truth.

use std::path::PathBuf;

use dhct_simulate::{Simulation, SimulationConfig, presets as preset_table};
use pyo3::prelude::*;

use crate::errors::SimulationError;
use crate::scan::Scan;

/// The config named by `preset`, read from `path`, or parsed from `config_json`
/// (exactly one), validated.
fn load(
    preset: Option<&str>,
    path: Option<PathBuf>,
    config_json: Option<&str>,
) -> PyResult<SimulationConfig> {
    let error = |e: dhct_simulate::SimulationError| SimulationError::new_err(e.to_string());
    let config = match (preset, path, config_json) {
        (Some(name), None, None) => preset_table::by_name(name).map_err(error)?,
        (None, Some(path), None) => SimulationConfig::from_path(&path).map_err(error)?,
        (None, None, Some(text)) => SimulationConfig::from_json_str(text).map_err(error)?,
        _ => {
            return Err(SimulationError::new_err(
                "give one of a preset name, a config path or a config",
            ));
        }
    };
    config.validate().map_err(error)?;
    Ok(config)
}

/// Simulates one acquisition; returns the scan (trace and retrace, metres), the ground
/// truth as JSON text (what `ground_truth.json` holds) and the config as TOML text.
#[pyfunction]
#[pyo3(signature = (preset=None, path=None, config_json=None, seed=None))]
pub fn simulate(
    py: Python<'_>,
    preset: Option<&str>,
    path: Option<PathBuf>,
    config_json: Option<&str>,
    seed: Option<u64>,
) -> PyResult<(Scan, String, String)> {
    let mut config = load(preset, path, config_json)?;
    if let Some(seed) = seed {
        config.seed = seed;
    }
    let toml = config
        .to_toml_string()
        .map_err(|e| SimulationError::new_err(e.to_string()))?;
    let output = py
        .detach(|| Simulation::from_config(&config).and_then(|s| s.run()))
        .map_err(|e| SimulationError::new_err(format!("simulation failed: {e}")))?;
    let truth = serde_json::to_string(&output.truth)
        .map_err(|e| SimulationError::new_err(format!("cannot serialise the truth: {e}")))?;
    let scan = Scan {
        pair: output.pair,
        metadata: Default::default(),
        path: None,
        format: Some("simulation".into()),
    };
    Ok((scan, truth, toml))
}

/// The built-in presets: (name, one-line summary).
#[pyfunction]
pub fn presets() -> Vec<(&'static str, &'static str)> {
    preset_table::ALL
        .iter()
        .map(|p| (p.name, p.summary))
        .collect()
}

/// The lattice catalogue: (name, aliases, one-line summary, whether its constant is known),
/// the names `correct(lattice=...)` and a simulation's `surface.lattice` take.
#[pyfunction]
pub fn lattices() -> Vec<(&'static str, Vec<&'static str>, &'static str, bool)> {
    dhct_lattice::CATALOGUE
        .iter()
        .map(|e| (e.name, e.aliases.to_vec(), e.summary, e.known_constant))
        .collect()
}
