//! `dhct.correct`: the whole chain on a scan or file, resolved exactly as `dhct correct`
//! resolves its flags, with every result kept in memory until `write`.

use std::path::PathBuf;
use std::sync::Mutex;
use std::time::Instant;

use dhct_app::correct as cli;
use dhct_app::correct::feature_table::feature_row;
use dhct_app::correct::{AnalyseRequest, CorrectConfig, CorrectError, Corrected};
use dhct_app::hints::Spelling;
use dhct_features::{Cell, FeatureRow};
use dhct_pipeline::Stage;
use dhct_scan::{ScanPair, ScanPass};
use numpy::{PyArray1, PyArray2, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::errors::{AnalysisError, InputMismatchError, OptionError, ReadError, WriteError, to_py};
use crate::scan::Scan;

/// The config: `config_path`'s file (if any) overridden by the options given as JSON (the
/// fields of `CorrectConfig`, as a TOML config names them).
pub(crate) fn build_config(
    options_json: &str,
    config_path: Option<PathBuf>,
) -> PyResult<CorrectConfig> {
    let given: CorrectConfig = serde_json::from_str(options_json)
        .map_err(|e| OptionError::new_err(format!("invalid option: {e}")))?;
    given.check().map_err(|e| to_py::<OptionError>(&e))?;
    let base = match config_path {
        Some(path) => CorrectConfig::read(&path).map_err(|e| to_py::<OptionError>(&e))?,
        None => CorrectConfig::default(),
    };
    Ok(base.overridden_by(given))
}

/// A `Scan` with the config's geometry overrides applied.
fn scan_pair(scan: &Scan, config: &CorrectConfig) -> PyResult<ScanPair> {
    if config.geometry.is_empty() {
        return Ok(scan.pair.clone());
    }
    let geometry = config
        .geometry
        .apply(scan.pair.geometry())
        .map_err(|e| OptionError::new_err(format!("geometry: {e}")))?;
    let (_, trace, retrace) = scan.pair.clone().into_parts();
    ScanPair::from_parts(geometry, trace, retrace)
        .map_err(|e| OptionError::new_err(format!("geometry: {e}")))
}

/// The pair to analyse and its label in the summary: a `Scan`, or a file read as `dhct
/// correct` reads it (with an optional retrace file).
/// The pair to analyse, its labels, the reading time, and the files it came from (when it
/// did: `channels="all"` reads the other channels from them).
type InputPair = (
    ScanPair,
    String,
    Option<String>,
    f64,
    Option<(PathBuf, Option<PathBuf>)>,
);

fn input_pair(
    py: Python<'_>,
    source: &Bound<'_, PyAny>,
    retrace: Option<PathBuf>,
    config: &CorrectConfig,
) -> PyResult<InputPair> {
    if let Ok(scan) = source.cast::<Scan>() {
        let scan = scan.get();
        if retrace.is_some() {
            return Err(OptionError::new_err(
                "retrace= is a file to read with the input file; build the Scan with both \
                 images instead (Scan.from_arrays(trace, retrace, ...))",
            ));
        }
        let label = scan
            .path
            .as_ref()
            .map_or_else(|| "<arrays>".to_string(), |p| p.display().to_string());
        let files = scan.path.clone().map(|p| (p, None));
        return Ok((scan_pair(scan, config)?, label, None, 0.0, files));
    }
    let path: PathBuf = source.extract().map_err(|_| {
        OptionError::new_err("the input must be a dhct.Scan or a path (str or os.PathLike)")
    })?;
    let start = Instant::now();
    let pair = py
        .detach(|| {
            cli::read_pair(
                &path,
                retrace.as_deref(),
                &config.geometry,
                config.channel.as_deref(),
            )
        })
        .map_err(|e| to_py::<ReadError>(&e))?;
    let label = path.display().to_string();
    let retrace_label = retrace.as_ref().map(|p| p.display().to_string());
    let read_s = start.elapsed().as_secs_f64();
    Ok((pair, label, retrace_label, read_s, Some((path, retrace))))
}

/// Runs the analysis without the GIL; `progress` (a callable taking the stage's
/// description) is called with the GIL at each stage; its first exception is raised after.
fn run_detached(
    py: Python<'_>,
    request: AnalyseRequest,
    progress: Option<Py<PyAny>>,
) -> PyResult<Corrected> {
    let failed: Mutex<Option<PyErr>> = Mutex::new(None);
    let on_stage = |stage: Stage| {
        if let Some(callback) = &progress {
            Python::attach(|py| {
                if let Err(e) = callback.call1(py, (stage.describe(),))
                    && let Ok(mut slot) = failed.lock()
                {
                    slot.get_or_insert(e);
                }
            });
        }
    };
    let result = py.detach(|| cli::analyse(request, &on_stage));
    if let Some(error) = failed.into_inner().ok().flatten() {
        return Err(error);
    }
    // Hints name the keyword arguments of `dhct.correct`, not the command line's flags.
    result.map_err(|e| match &e {
        CorrectError::Options(_) => OptionError::new_err(e.render(Spelling::Python)),
        CorrectError::InputMismatch { .. } => {
            InputMismatchError::new_err(e.render(Spelling::Python))
        }
        CorrectError::Analysis(_) => AnalysisError::new_err(e.render(Spelling::Python)),
    })
}

/// Corrects `source` (a `Scan` or a path) with the options given as a JSON object of
/// `dhct correct`'s config keys; see `dhct.correct` for the Python signature.
#[pyfunction]
#[pyo3(signature = (source, options_json, config_path=None, retrace=None, mask=None, progress=None))]
pub fn correct(
    py: Python<'_>,
    source: &Bound<'_, PyAny>,
    options_json: &str,
    config_path: Option<PathBuf>,
    retrace: Option<PathBuf>,
    mask: Option<PyReadonlyArray2<'_, bool>>,
    progress: Option<Py<PyAny>>,
) -> PyResult<Correction> {
    let config = build_config(options_json, config_path)?;
    let (pair, input, retrace, read_s, files) = input_pair(py, source, retrace, &config)?;
    let mask = mask.map(|m| m.as_array().to_owned());
    let shape = (pair.geometry().rows(), pair.geometry().columns());
    if let Some(m) = &mask
        && m.dim() != shape
    {
        return Err(OptionError::new_err(format!(
            "the mask is {} x {} (rows x columns) but the scan is {} x {}",
            m.nrows(),
            m.ncols(),
            shape.0,
            shape.1
        )));
    }
    let request = AnalyseRequest {
        pair,
        config,
        mask,
        input,
        retrace,
        read_s,
    };
    Ok(Correction {
        inner: Corrected {
            source: files,
            ..run_detached(py, request, progress)?
        },
    })
}

/// The result of `dhct.correct` as computed (wrapped by the Python class `dhct.Result`).
#[pyclass(frozen, module = "dhct")]
pub struct Correction {
    inner: Corrected,
}

/// One feature column.
enum Column {
    Float(Vec<f64>),
    Int(Vec<i64>),
    Bool(Vec<bool>),
    Text(Vec<String>),
}

/// Feature columns in `features.csv`'s order, then `indexed`.
#[derive(Default)]
struct Columns(Vec<(&'static str, Column)>);

impl Columns {
    /// The column `name`, made by `new` when it does not exist yet.
    fn column(&mut self, name: &'static str, new: impl FnOnce() -> Column) -> &mut Column {
        let at = match self.0.iter().position(|(n, _)| *n == name) {
            Some(at) => at,
            None => {
                self.0.push((name, new()));
                self.0.len() - 1
            }
        };
        &mut self.0[at].1
    }

    /// Appends one row; an empty cell is −1 in an integer column and NaN in a float one.
    fn push(&mut self, row: &FeatureRow) {
        for (name, cell) in row.cells() {
            match (cell, self.column(name, || new_column(cell))) {
                (Cell::Int(v), Column::Int(c)) => c.push(v.unwrap_or(-1)),
                (Cell::Float(v), Column::Float(c)) => c.push(v.unwrap_or(f64::NAN)),
                (Cell::Text(v), Column::Text(c)) => c.push(v.to_owned()),
                _ => unreachable!("a FeatureRow column keeps its type"),
            }
        }
        let indexed = row.placement.and_then(|p| p.index).is_some();
        if let Column::Bool(c) = self.column("indexed", || Column::Bool(Vec::new())) {
            c.push(indexed);
        }
    }
}

/// An empty column of `cell`'s type.
fn new_column(cell: Cell) -> Column {
    match cell {
        Cell::Int(_) => Column::Int(Vec::new()),
        Cell::Float(_) => Column::Float(Vec::new()),
        Cell::Text(_) => Column::Text(Vec::new()),
    }
}

#[pymethods]
impl Correction {
    /// The corrected image of `pass` ("trace" or "retrace"), float64 rows × columns on the
    /// sample-frame grid (NaN where there is no data), or None.
    fn corrected<'py>(&self, py: Python<'py>, pass: &str) -> Option<Bound<'py, PyArray2<f64>>> {
        let pass = ScanPass::from_name(pass)?;
        self.inner
            .analysis
            .passes
            .iter()
            .find(|p| p.pass == pass)
            .map(|p| PyArray2::from_array(py, &p.corrected_image))
    }

    /// Every feature of every pass as columns (the columns of `features.csv`): name →
    /// numpy array (float64, int64 or bool) or list of str (`pass`, `status`).
    fn feature_columns<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let mut c = Columns::default();
        for pass in &self.inner.analysis.passes {
            for k in 0..pass.features.features.len() {
                c.push(&feature_row(pass, k));
            }
        }
        let d = PyDict::new(py);
        for (name, column) in c.0 {
            match column {
                Column::Float(v) => d.set_item(name, PyArray1::from_vec(py, v))?,
                Column::Int(v) => d.set_item(name, PyArray1::from_vec(py, v))?,
                Column::Bool(v) => d.set_item(name, PyArray1::from_vec(py, v))?,
                Column::Text(v) => d.set_item(name, v)?,
            }
        }
        Ok(d)
    }

    /// The content of `model.json` (before writing: `outputs` empty, `write_s` 0).
    fn model_json(&self) -> PyResult<String> {
        serde_json::to_string(&self.inner.summary)
            .map_err(|e| OptionError::new_err(format!("cannot serialise the model: {e}")))
    }

    /// The lattice given: name, nearest-neighbour distance (metres), primitive vectors
    /// (2 × 2, metres, rows a1 and a2), plane group.
    fn lattice_given<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let lattice = self.inner.lattice.as_ref();
        let [a1, a2] = lattice.primitive_vectors();
        let vectors = ndarray::arr2(&[[a1.x, a1.y], [a2.x, a2.y]]);
        let d = PyDict::new(py);
        d.set_item("name", &self.inner.lattice_name)?;
        d.set_item(
            "nearest_neighbour_distance_m",
            lattice.nearest_neighbour_distance(),
        )?;
        d.set_item("primitive_vectors_m", PyArray2::from_array(py, &vectors))?;
        d.set_item("plane_group", lattice.plane_group().to_string())?;
        Ok(d)
    }

    /// The averaged and symmetry-averaged unit cell (float64 arrays on the fractional grid,
    /// `values[i, j]` at u = j/R, v = i/R), the group and the cell counts; None when no cell
    /// was averaged.
    fn unit_cell<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let Some(cell) = &self.inner.analysis.unit_cell else {
            return Ok(None);
        };
        let d = PyDict::new(py);
        d.set_item("averaged", PyArray2::from_array(py, &cell.averaged.values))?;
        d.set_item(
            "symmetrized",
            PyArray2::from_array(py, &cell.symmetrized.values),
        )?;
        d.set_item("group", cell.group.to_string())?;
        d.set_item("cells_available", cell.cells_available)?;
        d.set_item("cells_selected", cell.cells_selected)?;
        Ok(Some(d))
    }

    /// The scan that was analysed (with any geometry options applied).
    fn scan(&self) -> Scan {
        Scan {
            pair: self.inner.pair.clone(),
            metadata: Default::default(),
            path: None,
            format: None,
        }
    }

    /// The sim-to-real gap diagnosis of the features found (what `dhct correct --diagnose`
    /// writes as diagnosis.json), as JSON text.
    fn diagnose_json(&self, py: Python<'_>) -> PyResult<String> {
        let c = &self.inner;
        let report = py.detach(|| dhct_app::diagnose::diagnosis_of(c));
        report
            .map(|(r, _)| r.to_json())
            .map_err(|e| to_py::<AnalysisError>(&e))
    }

    /// Writes every output `dhct correct` writes into `outdir` (through a staging folder;
    /// an earlier run is replaced only with `overwrite`); returns `model.json`'s text.
    #[pyo3(signature = (outdir, overwrite=false, diagnose=false))]
    fn write(
        &self,
        py: Python<'_>,
        outdir: PathBuf,
        overwrite: bool,
        diagnose: bool,
    ) -> PyResult<String> {
        let summary = py
            .detach(|| cli::write(&self.inner, &outdir, overwrite, diagnose))
            .map_err(|e| to_py::<WriteError>(&e))?;
        serde_json::to_string(&summary)
            .map_err(|e| WriteError::new_err(format!("cannot serialise the model: {e}")))
    }
}
