//! `dhct.map_points`: points of a fitted frame moved into the sample frame with their 1σ.

use dhct_app::apply::SavedModel;
use dhct_app::points::inside_frame;
use dhct_distortion::map_point;
use dhct_scan::ScanPass;
use numpy::{PyArray1, PyReadonlyArray1};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::errors::OptionError;

/// Moves points `(x, y)` (pixels, or metres with `metres`) of the frame `model_json` (a
/// model.json's text) was fitted on into its sample frame; `t` (seconds since the frame
/// start, NaN = when the pixel under the point was recorded) and `pass_name` (`trace` or
/// `retrace`) say when and along which lines the tip reached them. Returns numpy arrays:
/// `corrected_x_m`, `corrected_y_m`, `sigma_x_m`, `sigma_y_m`, `time_s`.
#[pyfunction]
#[pyo3(signature = (model_json, x, y, t=None, pass_name="trace", metres=false))]
pub fn map_points<'py>(
    py: Python<'py>,
    model_json: &str,
    x: PyReadonlyArray1<'py, f64>,
    y: PyReadonlyArray1<'py, f64>,
    t: Option<PyReadonlyArray1<'py, f64>>,
    pass_name: &str,
    metres: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let saved: SavedModel = serde_json::from_str(model_json)
        .map_err(|e| OptionError::new_err(format!("not a model.json written by dhct: {e}")))?;
    let pass = ScanPass::from_name(pass_name).ok_or_else(|| {
        OptionError::new_err(format!("pass_={pass_name:?}: use \"trace\" or \"retrace\""))
    })?;
    let (x, y) = (x.as_slice()?, y.as_slice()?);
    let t = t.as_ref().map(|t| t.as_slice()).transpose()?;
    if x.len() != y.len() || t.is_some_and(|t| t.len() != x.len()) {
        return Err(OptionError::new_err(format!(
            "x, y and t must have one length: {}, {} and {}",
            x.len(),
            y.len(),
            t.map_or("none".into(), |t| t.len().to_string())
        )));
    }
    let g = &saved.geometry;
    let mut columns: [Vec<f64>; 5] = Default::default();
    for k in 0..x.len() {
        let xy = if metres {
            [x[k] / g.pitch_x(), y[k] / g.pitch_y()]
        } else {
            [x[k], y[k]]
        };
        if !inside_frame(g, xy) {
            return Err(OptionError::new_err(format!(
                "point {k} at ({:.2}, {:.2}) px lies outside the {} x {} px frame the model \
                 was fitted on",
                xy[0],
                xy[1],
                g.columns(),
                g.rows()
            )));
        }
        let time = t.map(|t| t[k]).filter(|v| !v.is_nan());
        let mapped = map_point(&saved.model, g, pass, xy, time);
        let values = [
            mapped.position_m[0],
            mapped.position_m[1],
            mapped.sigma_m[0],
            mapped.sigma_m[1],
            mapped.time_s,
        ];
        for (column, value) in columns.iter_mut().zip(values) {
            column.push(value);
        }
    }
    let names = [
        "corrected_x_m",
        "corrected_y_m",
        "sigma_x_m",
        "sigma_y_m",
        "time_s",
    ];
    let out = PyDict::new(py);
    for (name, column) in names.into_iter().zip(columns) {
        out.set_item(name, PyArray1::from_vec(py, column))?;
    }
    Ok(out)
}
