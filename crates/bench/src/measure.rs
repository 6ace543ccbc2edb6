//! Timing one end-to-end run: read the SM4 file, then the whole chain
//! (`dhct_pipeline::run`), with the pipeline's own per-stage wall times, the split of its
//! model stage into neighbours + local distortion and the model fit (timed again after the
//! run on the same features), and the process's peak memory.
//!
//! For a clean peak-memory figure the `headline` binary runs [`measure_file`] in a child
//! process of its own (`headline measure FILE LATTICE_JSON`), which prints a
//! [`Measurement`] as one JSON line.

use std::path::Path;
use std::time::Instant;

use dhct_distortion::{
    LocalSettings, PassInput, estimate_lattice_angle, fit_model, local_distortions, select_features,
};
use dhct_lattice::Lattice;
use dhct_pipeline::{Analysis, PipelineOptions};
use serde::{Deserialize, Serialize};

use crate::machine;

/// Wall time of each stage of one run, seconds.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct StageTimes {
    /// Reading and decoding the SM4 file.
    pub read_s: f64,
    /// Measuring the lattice the images show (FFT) and checking the inputs.
    #[serde(default)]
    pub calibration_s: f64,
    /// Feature finding and fitting, both images.
    pub features_s: f64,
    /// Neighbours, RDF, selection and local distortion (part of `model_s`, timed again).
    pub neighbours_local_s: f64,
    /// The joint drift/creep/hysteresis fit (part of `model_s`, timed again).
    pub model_fit_s: f64,
    /// Neighbours + local distortion + model fit, as the pipeline timed it.
    pub model_s: f64,
    /// Correction of features and resampling of both images.
    pub correction_s: f64,
    /// Lattice fits, indices, confidence ellipses.
    pub lattice_fit_s: f64,
    /// Local cells, averaged and symmetry-averaged cell.
    pub unit_cells_s: f64,
    /// `dhct_pipeline::run` as a whole.
    pub pipeline_s: f64,
    /// Read + pipeline.
    pub end_to_end_s: f64,
}

/// One measured run.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Measurement {
    /// Image size, `[columns, rows]`.
    pub pixels: [usize; 2],
    /// Features found, both passes.
    pub features: usize,
    /// Wall times.
    pub times: StageTimes,
    /// Peak resident memory of the process that ran it (VmHWM), MiB.
    pub peak_memory_mib: Option<f64>,
    /// Peak resident memory of each stage (read, then the pipeline's stages), MiB; empty
    /// where the peak cannot be reset.
    #[serde(default)]
    pub stage_peaks_mib: Vec<(String, f64)>,
    /// Rayon worker threads.
    pub threads: usize,
    /// Load average (1, 5, 15 min) when the run ended.
    pub load: String,
    /// Mean number of CPUs other processes kept busy during the run (read + pipeline).
    pub other_cpus: Option<f64>,
}

/// Reads `path` (any format `dhct_sm4_io` reads) and runs the chain on its topography.
/// Returns the measurement and the analysis.
pub fn measure_file(
    path: &Path,
    lattice: &dyn Lattice,
    options: &PipelineOptions,
) -> Result<(Measurement, Analysis), String> {
    let probe = machine::ContentionProbe::start();
    let peaks = machine::StagePeaks::default();
    peaks.start("read");
    let start = Instant::now();
    let file = dhct_sm4_io::read_path(path).map_err(|e| format!("reading {path:?}: {e}"))?;
    let pair = file
        .topography()
        .ok_or_else(|| format!("{path:?} has no topography channel"))?;
    let read_s = start.elapsed().as_secs_f64();
    let analysis = dhct_pipeline::run(pair, lattice, None, options, &|stage| {
        peaks.start(&format!("{stage:?}"))
    })
    .map_err(|e| format!("pipeline: {e}"))?;
    let end_to_end_s = start.elapsed().as_secs_f64();
    let stage_peaks_mib = peaks.finish();
    let other_cpus = probe.other_cpus();
    let (neighbours_local_s, model_fit_s) =
        model_breakdown(&analysis, pair.geometry(), lattice, options)?;
    let t = analysis.timings;
    let geometry = pair.geometry();
    let measurement = Measurement {
        pixels: [geometry.columns(), geometry.rows()],
        features: analysis
            .passes
            .iter()
            .map(|p| p.features.features.len())
            .sum(),
        times: StageTimes {
            read_s,
            calibration_s: t.calibration_s,
            features_s: t.features_s,
            neighbours_local_s,
            model_fit_s,
            model_s: t.model_s,
            correction_s: t.correction_s,
            lattice_fit_s: t.lattice_fit_s,
            unit_cells_s: t.unit_cells_s,
            pipeline_s: t.total_s,
            end_to_end_s,
        },
        peak_memory_mib: stage_peaks_mib
            .iter()
            .map(|(_, peak)| *peak)
            .reduce(f64::max)
            .or_else(machine::peak_memory_mib),
        stage_peaks_mib,
        threads: rayon::current_num_threads(),
        load: machine::load_string(),
        other_cpus,
    };
    Ok((measurement, analysis))
}

/// Times the two halves of the model stage on the run's own features, the way
/// `dhct_distortion::analyse` runs them: (neighbours + local distortion, model fit), s.
fn model_breakdown(
    analysis: &Analysis,
    geometry: &dhct_scan::ScanGeometry,
    lattice: &dyn Lattice,
    options: &PipelineOptions,
) -> Result<(f64, f64), String> {
    let inputs: Vec<PassInput> = analysis
        .passes
        .iter()
        .map(|p| PassInput {
            features: &p.features.features,
            mask: None,
        })
        .collect();
    let method = options
        .dhct
        .method
        .unwrap_or_else(|| lattice.local_distortion_method());
    let start = Instant::now();
    let mut pooled = Vec::new();
    for input in &inputs {
        let points_px: Vec<[f64; 2]> = input.features.iter().map(|f| [f.x_px, f.y_px]).collect();
        let selection = select_features(
            &points_px,
            geometry,
            None,
            lattice,
            &options.dhct.neighbours,
        )
        .map_err(|e| format!("neighbours: {e}"))?;
        let points_m: Vec<[f64; 2]> = points_px
            .iter()
            .map(|p| [p[0] * geometry.pitch_x(), p[1] * geometry.pitch_y()])
            .collect();
        let angle = estimate_lattice_angle(&points_m, &selection.selected, lattice);
        pooled.extend(local_distortions(
            input.features,
            &selection.selected,
            &LocalSettings {
                geometry,
                lattice,
                method,
                lattice_angle_rad: angle,
            },
        ));
    }
    let local_s = start.elapsed().as_secs_f64();
    let start = Instant::now();
    fit_model(
        &pooled,
        geometry.frame_duration(),
        geometry.line_scan_time(),
        &options.dhct.fit,
    )
    .map_err(|e| format!("model fit: {e}"))?;
    Ok((local_s, start.elapsed().as_secs_f64()))
}
