//! `dhct apply MODEL.json --points POINTS.csv`: points given in the coordinates of the file
//! the model was fitted on (spectroscopy positions, a CITS grid's points, marks), moved into
//! the sample frame with the 1σ the model's uncertainty gives them.
//!
//! The input is a CSV file with a header. A point's place is `x_px, y_px` (pixels, display
//! orientation, 0 at the first pixel's centre) or `x_m, y_m` (metres from the same origin:
//! `features.csv`'s controller frame); `t_s` (seconds since the frame start) when it was
//! recorded, else (no column, or an empty cell) as the pixel under it was; `pass` (`trace` or `retrace`, default
//! `trace`). Every input column is kept; the mapped columns follow.

use std::path::{Path, PathBuf};

use dhct_distortion::{DistortionModel, MappedPoint, map_point};
use dhct_scan::{ScanGeometry, ScanPass};
use dhct_sm4_io::{WriteError, write_atomically};

/// The file the mapped points are written to, in the output folder.
pub const POINTS_CSV: &str = "points_corrected.csv";

/// Columns appended to every input row.
const MAPPED_COLUMNS: [&str; 7] = [
    "time_s",
    "corrected_x_m",
    "corrected_y_m",
    "sigma_x_m",
    "sigma_y_m",
    "corrected_x_px",
    "corrected_y_px",
];

/// Half a pixel of slack around the frame: a point on the edge pixels is inside.
const EDGE_PX: f64 = 0.5;

/// Why a points file could not be mapped.
#[derive(Debug, thiserror::Error)]
pub enum PointsError {
    /// The file could not be read as CSV.
    #[error("cannot read the points file {path}: {source}")]
    Read {
        /// The points file.
        path: PathBuf,
        /// What the CSV reader said.
        source: csv::Error,
    },
    /// Neither pair of position columns is in the header.
    #[error(
        "the points file {path} has no position columns: it needs x_px and y_px (pixels) or \
         x_m and y_m (metres from the first pixel's centre); its columns are {found}"
    )]
    NoPositionColumns {
        /// The points file.
        path: PathBuf,
        /// The header it has.
        found: String,
    },
    /// A value is not a number (or not finite).
    #[error("the points file {path}, row {row}: {column} = {value:?} is not a finite number")]
    NotANumber {
        /// The points file.
        path: PathBuf,
        /// Data row, from 1.
        row: usize,
        /// The column.
        column: &'static str,
        /// The text found.
        value: String,
    },
    /// The pass is not trace or retrace.
    #[error("the points file {path}, row {row}: pass {value:?} is neither trace nor retrace")]
    UnknownPass {
        /// The points file.
        path: PathBuf,
        /// Data row, from 1.
        row: usize,
        /// The text found.
        value: String,
    },
    /// The point lies outside the frame the model was fitted on.
    #[error(
        "the points file {path}, row {row}: the point ({x_px:.2}, {y_px:.2}) px lies outside \
         the {columns} x {rows} px frame the model was fitted on, where the model says \
         nothing"
    )]
    OutsideFrame {
        /// The points file.
        path: PathBuf,
        /// Data row, from 1.
        row: usize,
        /// Its place, pixels.
        x_px: f64,
        /// Its place, pixels.
        y_px: f64,
        /// The frame's columns.
        columns: usize,
        /// The frame's rows.
        rows: usize,
    },
    /// The file holds no rows.
    #[error("the points file {path} holds no points")]
    Empty {
        /// The points file.
        path: PathBuf,
    },
    /// The output could not be written.
    #[error(transparent)]
    Write(#[from] WriteError),
}

/// What mapping the points found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointsSummary {
    /// Points mapped.
    pub points: usize,
    /// Of them, recorded outside the frame's time span (`t_s` before its start or after its
    /// end): the drift and creep are extrapolated there.
    pub outside_frame_time: usize,
    /// Whether the model carries its uncertainty (else the σ columns are NaN).
    pub uncertainty_known: bool,
}

/// Where the position and time columns are in the header.
struct Columns {
    x: (usize, &'static str),
    y: (usize, &'static str),
    /// Whether x and y are metres (else pixels).
    metres: bool,
    time: Option<usize>,
    pass: Option<usize>,
}

impl Columns {
    fn find(path: &Path, header: &csv::StringRecord) -> Result<Columns, PointsError> {
        let at = |name: &str| header.iter().position(|h| h.trim() == name);
        let (x, y, metres) = match (at("x_px"), at("y_px"), at("x_m"), at("y_m")) {
            (Some(x), Some(y), _, _) => ((x, "x_px"), (y, "y_px"), false),
            (_, _, Some(x), Some(y)) => ((x, "x_m"), (y, "y_m"), true),
            _ => {
                return Err(PointsError::NoPositionColumns {
                    path: path.to_path_buf(),
                    found: header.iter().collect::<Vec<_>>().join(", "),
                });
            }
        };
        Ok(Columns {
            x,
            y,
            metres,
            time: at("t_s"),
            pass: at("pass"),
        })
    }
}

/// Whether the point at `xy_px` (pixels) lies on the frame, half a pixel around its edge
/// pixels included: the model says nothing beyond.
pub fn inside_frame(geometry: &ScanGeometry, xy_px: [f64; 2]) -> bool {
    let inside = |v: f64, n: usize| (-EDGE_PX..=n as f64 - 1.0 + EDGE_PX).contains(&v);
    inside(xy_px[0], geometry.columns()) && inside(xy_px[1], geometry.rows())
}

/// One input row read: its place in pixels, its time and pass.
struct PointRow {
    xy_px: [f64; 2],
    time_s: Option<f64>,
    pass: ScanPass,
}

/// Reads row `row` (from 1) of the points file.
fn read_row(
    path: &Path,
    row: usize,
    record: &csv::StringRecord,
    columns: &Columns,
    geometry: &ScanGeometry,
) -> Result<PointRow, PointsError> {
    let number = |(at, column): (usize, &'static str)| {
        let text = record.get(at).unwrap_or("").trim();
        text.parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| PointsError::NotANumber {
                path: path.to_path_buf(),
                row,
                column,
                value: text.to_string(),
            })
    };
    let (x, y) = (number(columns.x)?, number(columns.y)?);
    let xy_px = if columns.metres {
        [x / geometry.pitch_x(), y / geometry.pitch_y()]
    } else {
        [x, y]
    };
    // An empty time cell: recorded as the pixel under it was.
    let time_s = columns
        .time
        .filter(|&at| !record.get(at).unwrap_or("").trim().is_empty())
        .map(|at| number((at, "t_s")))
        .transpose()?;
    // No column or an empty cell: the trace.
    let pass = match columns.pass.map(|at| record.get(at).unwrap_or("").trim()) {
        None | Some("") => ScanPass::Trace,
        Some(name) => ScanPass::from_name(name).ok_or_else(|| PointsError::UnknownPass {
            path: path.to_path_buf(),
            row,
            value: name.to_string(),
        })?,
    };
    if !inside_frame(geometry, xy_px) {
        return Err(PointsError::OutsideFrame {
            path: path.to_path_buf(),
            row,
            x_px: xy_px[0],
            y_px: xy_px[1],
            columns: geometry.columns(),
            rows: geometry.rows(),
        });
    }
    Ok(PointRow {
        xy_px,
        time_s,
        pass,
    })
}

/// The mapped columns of `point` as text.
fn mapped_cells(point: &MappedPoint, geometry: &ScanGeometry) -> [String; 7] {
    let [x, y] = point.position_m;
    [
        point.time_s,
        x,
        y,
        point.sigma_m[0],
        point.sigma_m[1],
        x / geometry.pitch_x(),
        y / geometry.pitch_y(),
    ]
    // Debug: the shortest text that reads back to the same number, exponent when small.
    .map(|v| format!("{v:?}"))
}

/// Maps every point of `input` with `model` (fitted on a scan of `geometry`) and writes
/// them, with every input column, to [`POINTS_CSV`] in `folder`.
pub fn map_points_file(
    model: &DistortionModel,
    geometry: &ScanGeometry,
    input: &Path,
    folder: &Path,
) -> Result<PointsSummary, PointsError> {
    let read_error = |source| PointsError::Read {
        path: input.to_path_buf(),
        source,
    };
    let mut reader = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .from_path(input)
        .map_err(read_error)?;
    let header = reader.headers().map_err(read_error)?.clone();
    let columns = Columns::find(input, &header)?;
    let mut rows = Vec::new();
    let mut summary = PointsSummary {
        points: 0,
        outside_frame_time: 0,
        uncertainty_known: true,
    };
    for (k, record) in reader.records().enumerate() {
        let record = record.map_err(read_error)?;
        let point = read_row(input, k + 1, &record, &columns, geometry)?;
        let mapped = map_point(model, geometry, point.pass, point.xy_px, point.time_s);
        summary.points += 1;
        if !(0.0..=geometry.frame_duration()).contains(&mapped.time_s) {
            summary.outside_frame_time += 1;
        }
        summary.uncertainty_known &= mapped.sigma_m.iter().all(|s| s.is_finite());
        let mut out: Vec<String> = record.iter().map(str::to_string).collect();
        out.extend(mapped_cells(&mapped, geometry));
        rows.push(out);
    }
    if rows.is_empty() {
        return Err(PointsError::Empty {
            path: input.to_path_buf(),
        });
    }
    let mut out_header: Vec<String> = header.iter().map(str::to_string).collect();
    out_header.extend(MAPPED_COLUMNS.map(str::to_string));
    write_atomically(&folder.join(POINTS_CSV), |w| {
        let mut writer = csv::Writer::from_writer(w);
        for record in std::iter::once(&out_header).chain(&rows) {
            writer
                .write_record(record)
                .map_err(|e| WriteError::from(std::io::Error::other(e)))?;
        }
        writer.flush()?;
        Ok(())
    })?;
    Ok(summary)
}
