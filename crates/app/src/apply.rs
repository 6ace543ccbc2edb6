//! `dhct apply MODEL.json [FILE [RETRACE]] [--points POINTS.csv] -o OUT`: a model `dhct
//! correct` fitted, applied to another file recorded in the same frame and timing (a
//! channel saved separately, a repeated export), and to points of that frame
//! ([`crate::points`]). A file whose size, pixel size, timing or scan directions differ
//! from the model's scan is refused, naming what differs.

use std::path::Path;

use anyhow::{Context, Result, bail};
use dhct_distortion::DistortionModel;
use dhct_scan::{ScanGeometry, ScanPair};
use dhct_sm4_io::GeometryOverrides;
use serde::Deserialize;

use crate::correct::corrected_files::{CorrectedImage, write_corrected_files};
use crate::output_dir::StagedOutput;
use crate::points::{POINTS_CSV, PointsSummary, map_points_file};
use crate::setup::Extent;
use crate::setup::read_pair;

/// What `apply` needs of a `model.json`: the fitted model and the scan it was fitted on.
#[derive(Debug, Clone, Deserialize)]
pub struct SavedModel {
    /// The fitted model.
    pub model: DistortionModel,
    /// The scan's geometry and timing.
    pub geometry: ScanGeometry,
}

/// What to apply to what.
pub struct ApplyRequest<'a> {
    /// The `model.json` a `dhct correct` run wrote.
    pub model: &'a Path,
    /// The file to correct, if any.
    pub input: Option<&'a Path>,
    /// A second file holding its retrace, if any.
    pub retrace: Option<&'a Path>,
    /// The channel (default: the topography).
    pub channel: Option<&'a str>,
    /// A CSV file of points in the frame's coordinates to move into the sample frame.
    pub points: Option<&'a Path>,
    /// The output folder.
    pub output: &'a Path,
    /// The grid of the corrected images (default: the scan's own frame).
    pub extent: Extent,
    /// Replace an earlier run's folder.
    pub overwrite: bool,
}

/// What `apply` wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct Applied {
    /// The files written, by name.
    pub written: Vec<String>,
    /// What mapping the points found, when there were points.
    pub points: Option<PointsSummary>,
}

/// Applies the model to the file and the points of the request.
pub fn run(request: &ApplyRequest) -> Result<Applied> {
    let text = std::fs::read_to_string(request.model)
        .with_context(|| format!("cannot read {}", request.model.display()))?;
    let saved: SavedModel = serde_json::from_str(&text).with_context(|| {
        format!(
            "{} is not a model.json written by dhct correct",
            request.model.display()
        )
    })?;
    let pair = request
        .input
        .map(|input| {
            read_pair(
                input,
                request.retrace,
                &GeometryOverrides::default(),
                request.channel,
            )
        })
        .transpose()?;
    if let Some(pair) = &pair {
        same_scan(&saved.geometry, pair.geometry())?;
    }
    let staged = StagedOutput::prepare(request.output, request.overwrite)?;
    let mut written = match &pair {
        Some(pair) => write_corrected_images(&saved.model, pair, staged.path(), request.extent)?,
        None => Vec::new(),
    };
    let points = request
        .points
        .map(|points| map_points_file(&saved.model, &saved.geometry, points, staged.path()))
        .transpose()?;
    if points.is_some() {
        written.push(POINTS_CSV.to_string());
    }
    staged.commit()?;
    Ok(Applied { written, points })
}

/// Writes the corrected images of every pass of `pair` into `folder` on the grid `extent`
/// names, as `dhct correct` writes them; returns their names.
fn write_corrected_images(
    model: &DistortionModel,
    pair: &ScanPair,
    folder: &Path,
    extent: Extent,
) -> Result<Vec<String>> {
    let mut written = Vec::new();
    for (pass, raw) in pair.images() {
        let image = CorrectedImage {
            stem: format!("corrected_{pass}"),
            raw,
            pass,
            model,
            geometry: pair.geometry(),
        };
        written.extend(write_corrected_files(folder, &image, extent)?);
    }
    Ok(written)
}

/// An error naming the first way `file`'s scan differs from the `model`'s.
fn same_scan(model: &ScanGeometry, file: &ScanGeometry) -> Result<()> {
    // Relative agreement to 1e-6, and a floor for quantities that may be zero.
    let same = |m: f64, f: f64, floor: f64| (m - f).abs() <= 1e-6 * m.abs().max(f.abs()) + floor;
    let numbers = [
        (
            "columns",
            model.columns() as f64,
            file.columns() as f64,
            "",
            0.0,
        ),
        ("rows", model.rows() as f64, file.rows() as f64, "", 0.0),
        ("pixel size x", model.pitch_x(), file.pitch_x(), " m", 0.0),
        ("pixel size y", model.pitch_y(), file.pitch_y(), " m", 0.0),
        (
            "pixel period",
            model.pixel_period(),
            file.pixel_period(),
            " s",
            0.0,
        ),
        (
            "turnaround",
            model.turnaround_time(),
            file.turnaround_time(),
            " s",
            1e-9,
        ),
        (
            "scan angle",
            model.scan_angle(),
            file.scan_angle(),
            " rad",
            1e-9,
        ),
    ];
    for (what, m, f, unit, floor) in numbers {
        if !same(m, f, floor) {
            bail!(
                "the file's {what} is {f}{unit} but the model was fitted on a scan with {m}{unit}: \
                 a model applies only to a file recorded in the same frame and timing"
            );
        }
    }
    if (model.trace_fast(), model.slow_direction()) != (file.trace_fast(), file.slow_direction()) {
        bail!(
            "the file was scanned {:?} then {:?}, the model's scan {:?} then {:?}: a model \
             applies only to the same scan directions",
            file.trace_fast(),
            file.slow_direction(),
            model.trace_fast(),
            model.slow_direction()
        );
    }
    if model.frame() != file.frame() {
        bail!(
            "the image is frame {} of its file, the model was fitted on frame {}: the frames \
             of a multi-frame file were recorded at different times, and a model applies only \
             to the frame it was fitted on",
            file.frame() + 1,
            model.frame() + 1
        );
    }
    Ok(())
}

/// What a run wrote, in words: the files, and for points how many were mapped, how many
/// were recorded outside the frame's time span (extrapolated) and whether their 1σ is known.
pub fn describe(applied: &Applied, folder: &Path) -> String {
    let mut text = format!(
        "wrote {} into {}\n",
        applied.written.join(", "),
        folder.display()
    );
    if let Some(points) = &applied.points {
        let plural = if points.points == 1 { "" } else { "s" };
        text.push_str(&format!("mapped {} point{plural}", points.points));
        if points.outside_frame_time > 0 {
            let (count, verb) = match points.outside_frame_time {
                1 => ("1 point".to_string(), "was"),
                n => (format!("{n} points"), "were"),
            };
            text.push_str(&format!(
                "; warning: {count} {verb} recorded outside the frame's time span, where the \
                 drift and creep are extrapolated from the frame: their positions are only as \
                 good as that extrapolation (see their sigma)",
            ));
        }
        if !points.uncertainty_known {
            text.push_str(
                "; their 1σ is not known (the correction kept has no fitted uncertainties, as \
                 when the global affine map was kept, or a parameter was not determined): the \
                 sigma columns are NaN",
            );
        }
        text.push('\n');
    }
    text
}

#[cfg(test)]
mod tests {
    use dhct_scan::ScanDirection;

    use super::*;

    #[test]
    fn a_model_applies_only_to_its_own_frame() {
        let geometry = ScanGeometry::new(
            8,
            8,
            1e-10,
            1e-10,
            1e-3,
            ScanDirection::Right,
            ScanDirection::Up,
        )
        .unwrap();
        assert!(same_scan(&geometry, &geometry.clone()).is_ok());
        let other = same_scan(&geometry, &geometry.clone().with_frame(2)).unwrap_err();
        assert!(other.to_string().contains("frame 3"), "{other}");
    }
}
