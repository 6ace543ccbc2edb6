//! What people look at: `report.html` (and `diagnosis.html`), every figure as an SVG or PNG
//! file, the plots, pictures with scale and colour bars, `model.json`'s content and the
//! formatting of quantities. Imports neither `correct` nor `diagnose`.

pub(crate) mod annotated_png;
pub mod bars;
pub(crate) mod detail;
pub mod figures;
pub mod html;
pub(crate) mod lattice_average;
pub(crate) mod local_figure;
pub(crate) mod model_plots;
pub(crate) mod overlays;
pub mod page;
pub mod plots;
pub(crate) mod raster_text;
pub mod render;
pub mod scatter;
pub mod summary;

use std::io::Write;
use std::path::Path;

use anyhow::Result;
use dhct_sm4_io::{WriteError, write_atomically};
use rayon::prelude::*;

/// Writes `bytes` to `path` atomically.
pub(crate) fn write_bytes(path: &Path, bytes: &[u8]) -> Result<(), WriteError> {
    write_atomically(path, |w| w.write_all(bytes).map_err(WriteError::from))
}

/// Every figure as its own file (PNG or SVG), written in parallel; returns the file names.
pub(crate) fn write_figure_files(dir: &Path, figures: &[figures::Figure]) -> Result<Vec<String>> {
    figures
        .par_iter()
        .map(|figure| {
            figure
                .files()
                .into_iter()
                .map(|(name, bytes)| {
                    write_bytes(&dir.join(&name), bytes)?;
                    Ok(name)
                })
                .collect::<Result<Vec<String>>>()
        })
        .collect::<Result<Vec<Vec<String>>>>()
        .map(|names| names.concat())
}
