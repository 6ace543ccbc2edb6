//! `summary.csv`: one row per file (status, error, lattice constant, model parameters with
//! their uncertainties, warnings), and `dhct summarize`, which merges the tables of shards.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use dhct_sm4_io::{WriteError, write_atomically};
use serde::Serialize;

use crate::correct::RunSummary;

/// What became of one file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Status {
    /// Corrected.
    Ok,
    /// Could not be corrected (the error says why).
    Failed,
    /// Not a scan file (the note says why).
    Skipped,
}

impl Status {
    fn name(self) -> &'static str {
        match self {
            Status::Ok => "ok",
            Status::Failed => "failed",
            Status::Skipped => "skipped",
        }
    }
}

/// One model parameter of one file.
#[derive(Debug, Clone, Serialize)]
pub struct ParameterCell {
    pub name: String,
    pub unit: String,
    pub value: f64,
    /// 1σ, `None` when the data do not determine it.
    pub sigma: Option<f64>,
}

/// One file's row of `summary.csv` (lengths in metres, angles in degrees, times in
/// seconds; the first lattice region's fit).
#[derive(Debug, Clone, Serialize)]
pub struct Row {
    /// The input file's path.
    pub input: String,
    /// Its output folder, relative to OUTDIR (empty unless corrected).
    pub output: String,
    /// What became of the file.
    pub status: Status,
    /// The error (failed) or why the file was skipped; empty when ok.
    pub error: String,
    /// The lattice's name.
    pub lattice: String,
    /// The lattice's nearest-neighbour distance, metres.
    pub nearest_neighbour_distance_m: Option<f64>,
    /// Features found, trace and retrace together.
    pub features: Option<usize>,
    /// Features indexed to a lattice site, trace and retrace together.
    pub indexed: Option<usize>,
    /// The fitted lattice constant along x (nominal × scale), metres.
    pub lattice_constant_x_m: Option<f64>,
    /// The fitted lattice constant along y (nominal × scale), metres.
    pub lattice_constant_y_m: Option<f64>,
    /// The fitted lattice rotation from +x towards +y, degrees.
    pub angle_deg: Option<f64>,
    /// RMS deviation of the fitted features from their sites, metres.
    pub rms_deviation_m: Option<f64>,
    /// Semi-axis of the 1σ confidence ellipse along its major axis, metres.
    pub ellipse_major_m: Option<f64>,
    /// Semi-axis of the 1σ confidence ellipse along its minor axis, metres.
    pub ellipse_minor_m: Option<f64>,
    /// `drift-model` or `affine`.
    pub correction: String,
    /// The warning codes, separated by "; ".
    pub warnings: String,
    /// Wall time spent on the file, seconds.
    pub seconds: f64,
    /// The model parameters, each with unit and 1σ.
    pub parameters: Vec<ParameterCell>,
}

impl Row {
    fn empty(input: &Path, status: Status, error: String, seconds: f64) -> Row {
        Row {
            input: input.display().to_string(),
            output: String::new(),
            status,
            error,
            lattice: String::new(),
            nearest_neighbour_distance_m: None,
            features: None,
            indexed: None,
            lattice_constant_x_m: None,
            lattice_constant_y_m: None,
            angle_deg: None,
            rms_deviation_m: None,
            ellipse_major_m: None,
            ellipse_minor_m: None,
            correction: String::new(),
            warnings: String::new(),
            seconds,
            parameters: Vec::new(),
        }
    }

    /// A corrected file written into `output` (relative to OUTDIR).
    pub fn ok(input: &Path, output: &Path, s: &RunSummary, seconds: f64) -> Row {
        let region = s.regions.first();
        let correction = serde_json::to_value(s.correction)
            .ok()
            .and_then(|v| v.as_str().map(str::to_owned))
            .unwrap_or_default();
        Row {
            output: output.display().to_string(),
            lattice: if s.lattice_assumed {
                format!("{} (assumed: no lattice named)", s.lattice)
            } else {
                s.lattice.clone()
            },
            nearest_neighbour_distance_m: Some(s.nearest_neighbour_distance_m),
            features: Some(s.passes.iter().map(|p| p.features).sum()),
            indexed: Some(s.passes.iter().map(|p| p.indexed).sum()),
            lattice_constant_x_m: region.map(|r| r.lattice_constant_m[0]),
            lattice_constant_y_m: region.map(|r| r.lattice_constant_m[1]),
            angle_deg: region.map(|r| r.angle_deg),
            rms_deviation_m: region.map(|r| r.rms_deviation_m),
            ellipse_major_m: region.map(|r| r.whole_ellipse.sigma_major_m),
            ellipse_minor_m: region.map(|r| r.whole_ellipse.sigma_minor_m),
            correction,
            warnings: s
                .warnings
                .iter()
                .map(|w| w.code.name())
                .collect::<Vec<_>>()
                .join("; "),
            parameters: s
                .parameters
                .iter()
                .map(|p| ParameterCell {
                    name: p.name.clone(),
                    unit: p.unit.clone(),
                    value: p.value,
                    sigma: p.is_determined().then_some(p.sigma),
                })
                .collect(),
            ..Row::empty(input, Status::Ok, String::new(), seconds)
        }
    }

    /// A file that could not be corrected.
    pub fn failed(input: &Path, error: String, seconds: f64) -> Row {
        Row::empty(input, Status::Failed, error, seconds)
    }

    /// A file that is not a scan.
    pub fn skipped(skipped: &super::Skipped) -> Row {
        Row::empty(&skipped.path, Status::Skipped, skipped.note.clone(), 0.0)
    }

    /// One line for the terminal.
    pub fn line(&self) -> String {
        let error = self.error.replace('\n', " ");
        match (
            self.status,
            self.lattice_constant_x_m,
            self.lattice_constant_y_m,
        ) {
            (Status::Failed, _, _) => format!("FAILED  {}: {error}", self.input),
            (Status::Skipped, _, _) => format!("skipped {}: {error}", self.input),
            (Status::Ok, Some(ax), Some(ay)) => format!(
                "ok      {}: {} features, a = {:.4} x {:.4} Å, {}, {:.2} s",
                self.input,
                self.features.unwrap_or(0),
                ax * 1e10,
                ay * 1e10,
                self.lattice,
                self.seconds
            ),
            (Status::Ok, _, _) => format!(
                "ok      {}: {} features",
                self.input,
                self.features.unwrap_or(0)
            ),
        }
    }

    /// The fixed columns' cells, in [`FIXED_COLUMNS`] order.
    fn fixed_cells(&self) -> Vec<String> {
        let f = |v: Option<f64>| v.map(|v| format!("{v:e}")).unwrap_or_default();
        let n = |v: Option<usize>| v.map(|v| v.to_string()).unwrap_or_default();
        vec![
            self.input.clone(),
            self.output.clone(),
            self.status.name().into(),
            // One line per row, for line-based tools (grep, wc -l) too.
            self.error.replace('\n', " "),
            self.lattice.clone(),
            f(self.nearest_neighbour_distance_m),
            n(self.features),
            n(self.indexed),
            f(self.lattice_constant_x_m),
            f(self.lattice_constant_y_m),
            f(self.angle_deg),
            f(self.rms_deviation_m),
            f(self.ellipse_major_m),
            f(self.ellipse_minor_m),
            self.correction.clone(),
            self.warnings.clone(),
            format!("{:.3}", self.seconds),
        ]
    }
}

/// The columns every table starts with; each model parameter follows as `NAME [UNIT]` and
/// `NAME sigma [UNIT]`.
pub const FIXED_COLUMNS: [&str; 17] = [
    "input",
    "output",
    "status",
    "error",
    "lattice",
    "nearest_neighbour_distance_m",
    "features",
    "indexed",
    "lattice_constant_x_m",
    "lattice_constant_y_m",
    "angle_deg",
    "rms_deviation_m",
    "ellipse_major_m",
    "ellipse_minor_m",
    "correction",
    "warnings",
    "seconds",
];

fn value_column(p: &ParameterCell) -> String {
    format!("{} [{}]", p.name, p.unit)
}

fn sigma_column(p: &ParameterCell) -> String {
    format!("{} sigma [{}]", p.name, p.unit)
}

/// Writes `rows` as CSV to `path` (atomically): the fixed columns, then every parameter
/// any row has (value and sigma, in first-seen order; empty where a row lacks it).
pub fn write_table(path: &Path, rows: &[Row]) -> Result<()> {
    let mut header: Vec<String> = FIXED_COLUMNS.iter().map(|c| c.to_string()).collect();
    for p in rows.iter().flat_map(|r| &r.parameters) {
        let column = value_column(p);
        if !header.contains(&column) {
            header.push(column);
            header.push(sigma_column(p));
        }
    }
    let records: Vec<Vec<String>> = rows
        .iter()
        .map(|r| {
            let mut cells = r.fixed_cells();
            cells.resize(header.len(), String::new());
            for p in &r.parameters {
                let at = |name: String| header.iter().position(|h| *h == name);
                if let (Some(v), Some(s)) = (at(value_column(p)), at(sigma_column(p))) {
                    cells[v] = format!("{:e}", p.value);
                    cells[s] = p.sigma.map(|s| format!("{s:e}")).unwrap_or_default();
                }
            }
            cells
        })
        .collect();
    write_csv(path, &header, &records)
}

fn write_csv(path: &Path, header: &[String], records: &[Vec<String>]) -> Result<()> {
    write_atomically(path, |w| {
        let mut writer = csv::Writer::from_writer(w);
        let mut write = || -> csv::Result<()> {
            writer.write_record(header)?;
            for record in records {
                writer.write_record(record)?;
            }
            writer.flush()?;
            Ok(())
        };
        write().map_err(|e| WriteError::from(std::io::Error::other(e)))
    })
    .with_context(|| format!("cannot write {}", path.display()))
}

/// The table of `input`: the file, or `summary.csv` in the folder.
fn table_path(input: &Path) -> PathBuf {
    if input.is_dir() {
        input.join(super::SUMMARY_FILE)
    } else {
        input.to_path_buf()
    }
}

/// `dhct summarize`: merges the `summary.csv` tables of `inputs` (files, or folders holding
/// one, e.g. each shard's OUTDIR) into `output`: the union of the columns (in first-seen
/// order), every row once per table. Returns a one-line count by status.
pub fn summarize(inputs: &[PathBuf], output: &Path) -> Result<String> {
    let mut header: Vec<String> = Vec::new();
    let mut rows: Vec<Vec<(String, String)>> = Vec::new();
    for input in inputs {
        let path = table_path(input);
        let text = dhct_sm4_io::read_regular_text(&path, 1 << 30)
            .with_context(|| format!("cannot read {}", path.display()))?;
        let mut reader = csv::Reader::from_reader(text.as_bytes());
        let columns: Vec<String> = reader
            .headers()
            .with_context(|| format!("{} is not a CSV table", path.display()))?
            .iter()
            .map(str::to_owned)
            .collect();
        if !columns.iter().any(|c| c == "status") || !columns.iter().any(|c| c == "input") {
            bail!(
                "{} is not a dhct summary table (no input and status columns)",
                path.display()
            );
        }
        for column in &columns {
            if !header.contains(column) {
                header.push(column.clone());
            }
        }
        for record in reader.records() {
            let record = record.with_context(|| format!("{} is malformed", path.display()))?;
            rows.push(
                columns
                    .iter()
                    .cloned()
                    .zip(record.iter().map(str::to_owned))
                    .collect(),
            );
        }
    }
    let records: Vec<Vec<String>> = rows
        .iter()
        .map(|row| {
            header
                .iter()
                .map(|h| {
                    row.iter()
                        .find(|(c, _)| c == h)
                        .map(|(_, v)| v.clone())
                        .unwrap_or_default()
                })
                .collect()
        })
        .collect();
    write_csv(output, &header, &records)?;
    let count = |status: &str| {
        rows.iter()
            .filter(|r| r.iter().any(|(c, v)| c == "status" && v == status))
            .count()
    };
    Ok(format!(
        "{} files: {} ok, {} failed, {} skipped; merged into {}\n",
        rows.len(),
        count("ok"),
        count("failed"),
        count("skipped"),
        output.display()
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(input: &str, parameters: &[(&str, f64, Option<f64>)]) -> Row {
        let mut r = Row::failed(Path::new(input), "boom, \"quoted\"\nline".into(), 1.0);
        r.status = Status::Ok;
        r.parameters = parameters
            .iter()
            .map(|&(name, value, sigma)| ParameterCell {
                name: name.into(),
                unit: "m/s".into(),
                value,
                sigma,
            })
            .collect();
        r
    }

    #[test]
    fn tables_hold_every_parameter_and_merge_by_column_name() {
        let dir = tempfile::tempdir().unwrap();
        let a = dir.path().join("a.csv");
        let b = dir.path().join("b.csv");
        write_table(&a, &[row("x.sm4", &[("v_x", 1.5, Some(0.1))])]).unwrap();
        write_table(
            &b,
            &[row("y.sm4", &[("v_y", 2.0, None), ("v_x", 3.0, Some(0.2))])],
        )
        .unwrap();
        let merged = dir.path().join("all.csv");
        let text = summarize(&[a, b], &merged).unwrap();
        assert!(text.starts_with("2 files: 2 ok, 0 failed"), "{text}");
        let mut reader = csv::Reader::from_path(&merged).unwrap();
        let header: Vec<String> = reader.headers().unwrap().iter().map(String::from).collect();
        let records: Vec<csv::StringRecord> = reader.records().map(Result::unwrap).collect();
        let cell =
            |r: usize, c: &str| records[r][header.iter().position(|h| h == c).unwrap()].to_string();
        assert_eq!(cell(0, "v_x [m/s]"), "1.5e0");
        assert_eq!(cell(1, "v_x [m/s]"), "3e0");
        assert_eq!(cell(0, "v_y [m/s]"), "");
        assert_eq!(cell(1, "v_y sigma [m/s]"), "");
        assert_eq!(cell(1, "error"), "boom, \"quoted\" line");
        assert!(summarize(&[dir.path().join("missing.csv")], &merged).is_err());
    }
}
