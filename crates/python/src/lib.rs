//! The Python extension `dhct._dhct`: reading, correcting and simulating STM scans with
//! numpy arrays in and out. The pure-Python package `dhct` (python/dhct) wraps it.

mod correct;
mod errors;
mod points;
mod scan;
mod series;
mod simulate;

use std::path::PathBuf;

use dhct_sm4_io::GeometryOverrides;
use pyo3::prelude::*;

/// Reads `path` (RHK SM4, Nanonis SXM, ISO 28600, GSF, NPY, TIFF, ...; detected from
/// content): the topography, or the channel named `channel`. `overrides_json` holds
/// geometry values replacing the file's (`pitch_x`, `pixel_period`, ..., SI units).
#[pyfunction]
#[pyo3(signature = (path, channel=None, overrides_json=None))]
fn read(
    py: Python<'_>,
    path: PathBuf,
    channel: Option<String>,
    overrides_json: Option<&str>,
) -> PyResult<scan::Scan> {
    let overrides: GeometryOverrides = match overrides_json {
        Some(text) => serde_json::from_str(text)
            .map_err(|e| errors::OptionError::new_err(format!("invalid geometry: {e}")))?,
        None => GeometryOverrides::default(),
    };
    overrides
        .validate()
        .map_err(|e| errors::OptionError::new_err(format!("geometry.{e}")))?;
    scan::read_scan(py, path, channel, overrides)
}

#[pymodule]
fn _dhct(module: &Bound<'_, PyModule>) -> PyResult<()> {
    errors::register(module)?;
    module.add_class::<scan::Scan>()?;
    module.add_class::<correct::Correction>()?;
    module.add_function(wrap_pyfunction!(read, module)?)?;
    module.add_function(wrap_pyfunction!(correct::correct, module)?)?;
    module.add_function(wrap_pyfunction!(points::map_points, module)?)?;
    module.add_function(wrap_pyfunction!(simulate::simulate, module)?)?;
    module.add_function(wrap_pyfunction!(series::correct_series, module)?)?;
    module.add_function(wrap_pyfunction!(series::simulate_sequence, module)?)?;
    module.add_function(wrap_pyfunction!(simulate::presets, module)?)?;
    module.add_function(wrap_pyfunction!(simulate::lattices, module)?)?;
    module.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
