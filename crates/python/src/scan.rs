//! `dhct.Scan`: one channel's trace and retrace with its geometry, read from a file or
//! built from numpy arrays.

use std::collections::BTreeMap;
use std::path::PathBuf;

use dhct_scan::{ImageChannel, ScanDirection, ScanGeometry, ScanPair, ScanPass};
use dhct_sm4_io::GeometryOverrides;
use numpy::{PyArray2, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::errors::{OptionError, ReadError};

/// One channel of a scan: trace and/or retrace images (2-D, rows × columns, display
/// orientation) sharing one geometry.
#[pyclass(frozen, module = "dhct")]
pub struct Scan {
    pub pair: ScanPair,
    pub metadata: BTreeMap<String, String>,
    /// The file it was read from, if any.
    pub path: Option<PathBuf>,
    /// The file format's name, if read from a file.
    pub format: Option<String>,
}

fn array<'py>(
    py: Python<'py>,
    pair: &ScanPair,
    pass: ScanPass,
) -> Option<Bound<'py, PyArray2<f64>>> {
    pair.image(pass).map(|c| PyArray2::from_array(py, &c.z))
}

fn direction(text: &str, what: &str) -> PyResult<ScanDirection> {
    ScanDirection::parse(text).ok_or_else(|| {
        OptionError::new_err(format!(
            "{what} = '{text}' is not a scan direction (use right, left, up or down)"
        ))
    })
}

/// The geometry as a dict: lengths in metres, times in seconds.
pub fn geometry_dict<'py>(py: Python<'py>, g: &ScanGeometry) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("columns", g.columns())?;
    d.set_item("rows", g.rows())?;
    d.set_item("pitch_m", (g.pitch_x(), g.pitch_y()))?;
    d.set_item("pitch_x_m", g.pitch_x())?;
    d.set_item("pitch_y_m", g.pitch_y())?;
    d.set_item("width_m", g.width())?;
    d.set_item("height_m", g.height())?;
    d.set_item("pixel_period_s", g.pixel_period())?;
    d.set_item("line_time_s", g.line_scan_time())?;
    d.set_item("line_period_s", g.line_period())?;
    d.set_item("turnaround_s", g.turnaround_time())?;
    d.set_item("frame_duration_s", g.frame_duration())?;
    d.set_item("fast", direction_name(g.trace_fast()))?;
    d.set_item("slow", direction_name(g.slow_direction()))?;
    d.set_item("scan_angle_rad", g.scan_angle())?;
    d.set_item("offset_m", g.offset())?;
    d.set_item("scale_source", source(g.scale_source()))?;
    d.set_item("timing_source", source(g.timing_source()))?;
    d.set_item("frame", g.frame())?;
    Ok(d)
}

fn direction_name(d: ScanDirection) -> &'static str {
    match d {
        ScanDirection::Right => "right",
        ScanDirection::Left => "left",
        ScanDirection::Up => "up",
        ScanDirection::Down => "down",
    }
}

fn source(s: dhct_scan::ValueSource) -> &'static str {
    match s {
        dhct_scan::ValueSource::Stated => "stated",
        dhct_scan::ValueSource::Assumed => "assumed",
    }
}

/// Reads `path` (any supported format, detected from content) with `overrides` applied.
pub fn read_scan(
    py: Python<'_>,
    path: PathBuf,
    channel: Option<String>,
    overrides: GeometryOverrides,
) -> PyResult<Scan> {
    let read = py.detach(|| dhct_sm4_io::read_path_with(&path, &overrides));
    let file =
        read.map_err(|e| ReadError::new_err(format!("cannot read {}: {e}", path.display())))?;
    let pair = file
        .channel_or_topography(channel.as_deref())
        .map_err(|e| ReadError::new_err(format!("{}: {e}", path.display())))?
        .clone();
    Ok(Scan {
        pair,
        format: Some(file.format.name().to_string()),
        metadata: file.metadata,
        path: Some(path),
    })
}

impl Scan {
    /// The geometry for `from_arrays`: the pixel period from `pixel_period_s` or
    /// `line_time_s` (exactly one), pitch `(x, y)` metres.
    fn build_geometry(
        shape: (usize, usize),
        pitch: (f64, f64),
        pixel_period_s: Option<f64>,
        line_time_s: Option<f64>,
        directions: (ScanDirection, ScanDirection),
        turnaround_s: f64,
    ) -> PyResult<ScanGeometry> {
        let (rows, columns) = shape;
        let (fast, slow) = directions;
        let geometry = match (pixel_period_s, line_time_s) {
            (Some(p), None) => ScanGeometry::new(columns, rows, pitch.0, pitch.1, p, fast, slow),
            (None, Some(t)) => {
                ScanGeometry::from_line_time(columns, rows, pitch.0, pitch.1, t, fast, slow)
            }
            _ => {
                return Err(OptionError::new_err(
                    "give exactly one of pixel_period_s and line_time_s",
                ));
            }
        };
        geometry
            .and_then(|g| g.with_turnaround(turnaround_s))
            .map_err(|e| OptionError::new_err(format!("geometry: {e}")))
    }
}

#[pymethods]
impl Scan {
    /// A scan from numpy arrays (rows × columns, display orientation, z in `unit`) and its
    /// geometry: `pitch_m` (one value, or (x, y)), metres; `pixel_period_s` or
    /// `line_time_s` (one line in one direction, without turnaround), seconds; `fast` the
    /// trace's fast direction and `slow` the slow direction (right, left, up, down);
    /// `turnaround_s` the dead time at each end of a line, seconds.
    #[staticmethod]
    #[pyo3(signature = (trace, retrace=None, *, pitch_m, pixel_period_s=None, line_time_s=None,
        fast="right", slow="down", turnaround_s=0.0, unit="m", name="topography"))]
    #[allow(clippy::too_many_arguments)]
    fn from_arrays(
        trace: PyReadonlyArray2<'_, f64>,
        retrace: Option<PyReadonlyArray2<'_, f64>>,
        pitch_m: &Bound<'_, PyAny>,
        pixel_period_s: Option<f64>,
        line_time_s: Option<f64>,
        fast: &str,
        slow: &str,
        turnaround_s: f64,
        unit: &str,
        name: &str,
    ) -> PyResult<Scan> {
        let pitch = match pitch_m.extract::<f64>() {
            Ok(p) => (p, p),
            Err(_) => pitch_m.extract::<(f64, f64)>().map_err(|_| {
                OptionError::new_err("pitch_m must be a number or a pair (x, y), metres")
            })?,
        };
        let directions = (direction(fast, "fast")?, direction(slow, "slow")?);
        let z = trace.as_array().to_owned();
        let geometry = Scan::build_geometry(
            z.dim(),
            pitch,
            pixel_period_s,
            line_time_s,
            directions,
            turnaround_s,
        )?;
        let trace = ImageChannel::new(name, unit, z);
        let retrace = retrace.map(|r| ImageChannel::new(name, unit, r.as_array().to_owned()));
        let pair = ScanPair::new(geometry, trace, retrace)
            .map_err(|e| OptionError::new_err(format!("{e}")))?;
        Ok(Scan {
            pair,
            metadata: BTreeMap::new(),
            path: None,
            format: None,
        })
    }

    /// The trace image (float64, rows × columns, in `unit`), or None.
    #[getter]
    fn trace<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray2<f64>>> {
        array(py, &self.pair, ScanPass::Trace)
    }

    /// The retrace image (float64, rows × columns, in `unit`), or None.
    #[getter]
    fn retrace<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray2<f64>>> {
        array(py, &self.pair, ScanPass::Retrace)
    }

    /// The unit of the image values ("m" for topography).
    #[getter]
    fn unit(&self) -> String {
        self.pair
            .images()
            .next()
            .map(|(_, c)| c.unit.clone())
            .unwrap_or_default()
    }

    /// The channel's name.
    #[getter]
    fn channel(&self) -> String {
        self.pair.name().to_string()
    }

    /// (rows, columns).
    #[getter]
    fn shape(&self) -> (usize, usize) {
        (self.pair.geometry().rows(), self.pair.geometry().columns())
    }

    /// Where the image lies and how it was scanned: lengths in metres, times in seconds.
    #[getter]
    fn geometry<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        geometry_dict(py, self.pair.geometry())
    }

    /// Header fields of the file (free-form key → value), with `format` and `path`.
    #[getter]
    fn metadata<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for (k, v) in &self.metadata {
            d.set_item(k, v)?;
        }
        if let Some(format) = &self.format {
            d.set_item("format", format)?;
        }
        if let Some(path) = &self.path {
            d.set_item("path", path.display().to_string())?;
        }
        Ok(d)
    }

    fn __repr__(&self) -> String {
        let g = self.pair.geometry();
        let passes: Vec<String> = self.pair.images().map(|(p, _)| p.to_string()).collect();
        format!(
            "Scan('{}', {} x {} px, {:.3} x {:.3} nm, {}, pixel period {:.4e} s)",
            self.pair.name(),
            g.columns(),
            g.rows(),
            g.width() * 1e9,
            g.height() * 1e9,
            passes.join(" + "),
            g.pixel_period()
        )
    }
}
