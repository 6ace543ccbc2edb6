//! `dhct apply MODEL.json FILE [RETRACE] -o OUT`: a model `dhct correct` fitted, applied to
//! another file recorded in the same frame and timing (a channel saved separately, a
//! repeated export). A file whose size, pixel size, timing or scan directions differ from
//! the model's scan is refused, naming what differs.

use std::path::Path;

use anyhow::{Context, Result, bail};
use dhct_distortion::{DistortionModel, correct_image};
use dhct_scan::{ImageChannel, ScanGeometry};
use dhct_sm4_io::{GeometryOverrides, write_atomically};
use serde::Deserialize;

use crate::output_dir::StagedOutput;
use crate::setup::read_pair;

/// What `apply` needs of a `model.json`.
#[derive(Deserialize)]
struct SavedModel {
    model: DistortionModel,
    geometry: ScanGeometry,
}

/// What to apply to what.
pub struct ApplyRequest<'a> {
    /// The `model.json` a `dhct correct` run wrote.
    pub model: &'a Path,
    /// The file to correct.
    pub input: &'a Path,
    /// A second file holding its retrace, if any.
    pub retrace: Option<&'a Path>,
    /// The channel (default: the topography).
    pub channel: Option<&'a str>,
    /// The output folder.
    pub output: &'a Path,
    /// Replace an earlier run's folder.
    pub overwrite: bool,
}

/// Applies the model; returns the files written.
pub fn run(request: &ApplyRequest) -> Result<Vec<String>> {
    let text = std::fs::read_to_string(request.model)
        .with_context(|| format!("cannot read {}", request.model.display()))?;
    let saved: SavedModel = serde_json::from_str(&text).with_context(|| {
        format!(
            "{} is not a model.json written by dhct correct",
            request.model.display()
        )
    })?;
    let pair = read_pair(
        request.input,
        request.retrace,
        &GeometryOverrides::default(),
        request.channel,
    )?;
    let geometry = pair.geometry();
    same_scan(&saved.geometry, geometry)?;
    let staged = StagedOutput::prepare(request.output, request.overwrite)?;
    let pitch = [geometry.pitch_x(), geometry.pitch_y()];
    let mut written = Vec::new();
    for (pass, image) in pair.images() {
        let z = correct_image(&saved.model, geometry, pass, &image.z)?;
        let channel =
            ImageChannel::new(format!("{} (corrected)", image.name), image.unit.clone(), z);
        let stem = format!("corrected_{pass}");
        write_atomically(&staged.path().join(format!("{stem}.tiff")), |w| {
            dhct_sm4_io::tiff_file::write_f32_with_pixel_size(&channel, pitch, w)
        })?;
        write_atomically(&staged.path().join(format!("{stem}.gsf")), |w| {
            dhct_sm4_io::gsf::write_pass(&channel, geometry, pass, w)
        })?;
        written.extend([format!("{stem}.tiff"), format!("{stem}.gsf")]);
    }
    staged.commit()?;
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
    Ok(())
}
