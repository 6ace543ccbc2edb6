//! Turning options into pipeline inputs: the config (file and flags), what it resolves to
//! (lattice, constant, pipeline options, `--nn auto`), the scan pair read from files and
//! the analysed area (mask). Used by `correct`, `diagnose` and `batch`; imports neither.

mod config;
mod inputs;

use std::path::Path;

use anyhow::{Context, Result, bail};
use dhct_distortion::mask::{polygon_mask, read_mask};
use dhct_scan::{ScanPair, ScanPass};
use ndarray::Array2;

pub use config::{
    ChannelSet, CorrectConfig, Extent, LatticeChoiceError, Length, build_lattice, pipeline_table,
};
pub use inputs::{
    CALIBRATE_PITCH_TOLERANCE, MeasuredNnError, PRESET_PITCH_TOLERANCE, Resolved, resolve,
    with_measured_nn,
};

/// The scan pair to analyse: the file's channel named `channel` (default: its topography;
/// trace and retrace when present), or the first file's trace with the second file's image
/// of the same channel as retrace. An unknown channel name is an error listing the file's
/// channels.
pub fn read_pair(
    input: &Path,
    retrace: Option<&Path>,
    overrides: &dhct_sm4_io::GeometryOverrides,
    channel: Option<&str>,
) -> Result<ScanPair> {
    let file = dhct_sm4_io::read_path_with_limits(input, overrides, &crate::read_limits::get())
        .with_context(|| format!("cannot read {}", input.display()))?;
    let pair = file
        .channel_or_topography(channel)
        .with_context(|| input.display().to_string())?
        .clone();
    let Some(retrace_path) = retrace else {
        return Ok(pair);
    };
    let other =
        dhct_sm4_io::read_path_with_limits(retrace_path, overrides, &crate::read_limits::get())
            .with_context(|| format!("cannot read {}", retrace_path.display()))?;
    let other_pair = other
        .channel_or_topography(channel)
        .with_context(|| retrace_path.display().to_string())?;
    let retrace = other_pair
        .image(ScanPass::Retrace)
        .or_else(|| other_pair.image(ScanPass::Trace))
        .context("the retrace file holds no image")?
        .clone();
    let geometry = pair.geometry().clone();
    let trace = pair
        .trace()
        .context("the first file holds no trace image")?
        .clone();
    if (retrace.rows(), retrace.columns()) != (trace.rows(), trace.columns()) {
        bail!(
            "the retrace image is {} x {} px but the trace is {} x {} px",
            retrace.columns(),
            retrace.rows(),
            trace.columns(),
            trace.rows()
        );
    }
    ScanPair::new(geometry, trace, Some(retrace)).context("cannot pair trace and retrace")
}

/// The analysed area of the config (mask file and polygon intersected; true = used), in
/// raw-image pixels, or `None` for the whole image.
pub fn load_mask(
    config: &CorrectConfig,
    geometry: &dhct_scan::ScanGeometry,
) -> Result<Option<Array2<bool>>> {
    let from_file = match &config.mask {
        Some(path) => Some(read_mask(path).map_err(|e| anyhow::anyhow!("{e}"))?),
        None => None,
    };
    let from_polygon = config
        .mask_polygon
        .as_ref()
        .map(|polygon| polygon_mask(geometry.rows(), geometry.columns(), polygon, true));
    Ok(match (from_file, from_polygon) {
        (Some(a), Some(b)) => Some(
            dhct_distortion::mask::intersect(&a, &b).map_err(|e| anyhow::anyhow!("mask: {e}"))?,
        ),
        (a, b) => a.or(b),
    })
}
