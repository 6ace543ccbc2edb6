//! `dhct.correct_series` and `dhct.simulate_sequence`: frames of one area fitted with one
//! model and registered into one sample frame, as `dhct series` does; and simulated
//! sequences with their truth, written frame by frame.

use std::path::PathBuf;

use dhct_app::series::{SeriesRequest, by_image, run};
use dhct_simulate::{SequenceSimulation, SimulationConfig, presets as preset_table};
use pyo3::prelude::*;

use crate::correct::build_config;
use crate::errors::{AnalysisError, SimulationError, to_py};

/// Runs `dhct series` on `inputs` (files, folders, glob patterns) into `output`; returns
/// `series.json`'s content.
#[pyfunction]
#[pyo3(signature = (inputs, output, options_json, config_path=None, knots=None, by_image=false))]
pub fn correct_series(
    py: Python<'_>,
    inputs: Vec<String>,
    output: PathBuf,
    options_json: &str,
    config_path: Option<PathBuf>,
    knots: Option<usize>,
    by_image: bool,
) -> PyResult<String> {
    let config = build_config(options_json, config_path)?;
    let request = SeriesRequest {
        inputs: &inputs,
        output: &output,
        config,
        knots,
    };
    let text = py
        .detach(|| {
            if by_image {
                by_image::run(&request).and_then(|s| Ok(serde_json::to_string(&s)?))
            } else {
                run(&request).and_then(|s| Ok(serde_json::to_string(&s)?))
            }
        })
        .map_err(|e| to_py::<AnalysisError>(&e))?;
    Ok(text)
}

/// Simulates the sequence of a preset or config file (with a `[sequence]` table) into
/// `output`, one frame at a time; returns the paths written.
#[pyfunction]
#[pyo3(signature = (output, preset=None, path=None, seed=None))]
pub fn simulate_sequence(
    py: Python<'_>,
    output: PathBuf,
    preset: Option<&str>,
    path: Option<PathBuf>,
    seed: Option<u64>,
) -> PyResult<Vec<String>> {
    let error = |e: dhct_simulate::SimulationError| SimulationError::new_err(e.to_string());
    let mut config = match (preset, path) {
        (Some(name), None) => preset_table::by_name(name).map_err(error)?,
        (None, Some(path)) => SimulationConfig::from_path(&path).map_err(error)?,
        _ => {
            return Err(SimulationError::new_err(
                "give one of a preset name or a config path",
            ));
        }
    };
    if let Some(seed) = seed {
        config.seed = seed;
    }
    let written = py
        .detach(|| {
            SequenceSimulation::from_config(&config).and_then(|s| s.write(&output, |_, _| {}))
        })
        .map_err(error)?;
    Ok(written.iter().map(|p| p.display().to_string()).collect())
}
