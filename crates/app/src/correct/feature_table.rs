//! `features.csv`: one row per feature of every image, written with the `csv` crate from
//! [`FeatureRow`]s. The columns are documented in docs/outputs.md; each column is a
//! different quantity (the fitted Gaussian's signed `height` only: its magnitude, the
//! former `amplitude` column, is `|height|`).

use std::path::Path;

use anyhow::Result;
use dhct_pipeline::{Analysis, PassOutput};
use dhct_sm4_io::{WriteError, write_atomically};
use serde::Serialize;

/// File name in the output directory.
pub const FEATURES_CSV: &str = "features.csv";

/// One row of `features.csv`. Positions are in the controller frame of the feature's
/// image (x = column, y = row, metres = px · pitch) unless named `corrected_`; z values
/// are in the channel's unit (metres for topography).
#[derive(Debug, Serialize)]
pub struct FeatureRow {
    /// Index within its image's feature set.
    pub id: usize,
    /// `trace` or `retrace`.
    pub pass: String,
    /// Fitted centre x (column), px.
    pub x_px: f64,
    /// Fitted centre y (row), px.
    pub y_px: f64,
    /// Fitted centre x, metres.
    pub x_m: f64,
    /// Fitted centre y, metres.
    pub y_m: f64,
    /// 1σ uncertainty of the centre x from the fit covariance, px.
    pub x_sigma_px: f64,
    /// 1σ uncertainty of the centre y from the fit covariance, px.
    pub y_sigma_px: f64,
    /// Gaussian width along the major axis, px.
    pub sigma_major_px: f64,
    /// Gaussian width along the minor axis, px.
    pub sigma_minor_px: f64,
    /// Major axis from +x towards +y, radians.
    pub theta_rad: f64,
    /// Signed apparent height of the fitted Gaussian (positive: bright, negative: dark).
    pub height: f64,
    /// Fitted background level (after the line levelling).
    pub z0: f64,
    /// What the lattice line levelling subtracted at the centre (line offsets and steps).
    pub removed_level: f64,
    /// RMS residual of the fit.
    pub residual_rms: f64,
    /// Pixels in the fitted region.
    pub pixel_count: usize,
    /// Peak normalised cross-correlation of the region.
    pub ncc_peak: f64,
    /// Fit status (`ok` or why not).
    pub status: String,
    /// Levenberg–Marquardt iterations the fit took.
    pub fit_iterations: usize,
    /// Acquisition time since frame start, seconds.
    pub time_s: f64,
    /// Acquisition time since the start of the feature's scan line, seconds.
    pub line_time_s: f64,
    /// Position x after the correction, sample frame, metres.
    pub corrected_x_m: f64,
    /// Position y after the correction, sample frame, metres.
    pub corrected_y_m: f64,
    /// Region of the lattice fit the feature is indexed in (empty when not indexed).
    pub region: Option<usize>,
    /// Cell index along a1 (empty when not indexed).
    pub n: Option<i64>,
    /// Cell index along a2 (empty when not indexed).
    pub m: Option<i64>,
    /// Motif site within the cell (empty when not indexed).
    pub site: Option<usize>,
    /// Corrected position x minus the fitted lattice site's, metres.
    pub deviation_x_m: Option<f64>,
    /// Corrected position y minus the fitted lattice site's, metres.
    pub deviation_y_m: Option<f64>,
}

/// The row of feature `k` of `pass`.
pub fn feature_row(pass: &PassOutput, k: usize) -> FeatureRow {
    let f = &pass.features.features[k];
    let index = pass.indices.get(k).copied().flatten();
    let corrected = pass.corrected.get(k);
    let status = serde_json::to_value(f.status)
        .ok()
        .and_then(|v| v.as_str().map(str::to_owned))
        .unwrap_or_default();
    FeatureRow {
        id: f.id,
        pass: f.pass.to_string(),
        x_px: f.x_px,
        y_px: f.y_px,
        x_m: f.x_m,
        y_m: f.y_m,
        x_sigma_px: f.x_sigma_px,
        y_sigma_px: f.y_sigma_px,
        sigma_major_px: f.sigma_major_px,
        sigma_minor_px: f.sigma_minor_px,
        theta_rad: f.theta_rad,
        height: f.height,
        z0: f.z0,
        removed_level: f.removed_level,
        residual_rms: f.residual_rms,
        pixel_count: f.pixel_count,
        ncc_peak: f.ncc_peak,
        status,
        fit_iterations: f.fit_iterations,
        time_s: f.time_s,
        line_time_s: f.line_time_s,
        corrected_x_m: corrected.map_or(f64::NAN, |c| c.x_m),
        corrected_y_m: corrected.map_or(f64::NAN, |c| c.y_m),
        region: index.map(|i| i.region),
        n: index.map(|i| i.n),
        m: index.map(|i| i.m),
        site: index.map(|i| i.site),
        deviation_x_m: index.map(|i| i.deviation_m[0]),
        deviation_y_m: index.map(|i| i.deviation_m[1]),
    }
}

/// Writes `features.csv` into `dir`; returns its name.
pub fn write_features_csv(dir: &Path, analysis: &Analysis) -> Result<String> {
    write_atomically(&dir.join(FEATURES_CSV), |w| {
        let mut writer = csv::Writer::from_writer(w);
        for pass in &analysis.passes {
            for k in 0..pass.features.features.len() {
                writer
                    .serialize(feature_row(pass, k))
                    .map_err(|e| WriteError::from(std::io::Error::other(e)))?;
            }
        }
        writer.flush()?;
        Ok(())
    })?;
    Ok(FEATURES_CSV.to_string())
}
