//! `dhct series FRAME... -o OUTDIR`: frames of one area fitted with one physical model
//! (drift continuous over the session, creep after every move, one hysteresis law) and
//! registered into one sample frame. Each frame is first analysed alone, as `dhct correct`
//! does; its features and its own model start the series fit
//! ([`dhct_distortion::series`]).

pub mod by_image;
mod correlation;
mod order;
mod outputs;
mod placement;
mod report;
mod sources;
mod steps;
mod trust;

use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result};
use dhct_distortion::series::{KnotChoice, SeriesFit, SeriesFrame, SeriesOptions, fit_series};
use dhct_distortion::{FitOptions, PassInput};
use dhct_pipeline::{CorrectedImageCheck, Warning};
use rayon::prelude::*;
use serde::Serialize;

use crate::analysis::{FrameModel, analyse_model_pair};
use crate::flags::warning_line;
use crate::setup::CorrectConfig;

pub use order::Timed;
pub use sources::FrameSource;
pub use trust::UNEXPLAINED_FRAME_RATIO;

/// What `dhct series` was asked to do.
pub struct SeriesRequest<'a> {
    /// Folders, glob patterns or files: the frames.
    pub inputs: &'a [String],
    /// The output directory.
    pub output: &'a Path,
    /// The config every frame is analysed with.
    pub config: CorrectConfig,
    /// The drift spline's knots (`None`: cross-validated).
    pub knots: Option<usize>,
}

/// One frame as the series saw it.
#[derive(Debug, Clone, Serialize)]
pub struct FrameSummary {
    /// Its file.
    pub file: String,
    /// Seconds since the first frame's start.
    pub start_s: f64,
    /// Its scan angle, degrees.
    pub scan_angle_deg: f64,
    /// Its frame centre, metres (instrument frame).
    pub offset_m: [f64; 2],
    /// Features found (all passes).
    pub features: usize,
    /// Its own model's hysteresis parameters (fitted to this frame alone).
    pub own_hysteresis: Vec<dhct_distortion::Parameter>,
    /// What its analysis alone found about the inputs (its pixel size calibrated from the
    /// lattice, its lattice not measured, its timing assumed).
    pub warnings: Vec<Warning>,
    /// Its registered images' lattices, measured by FFT (passes where one was measured).
    pub registered_checks: Vec<CorrectedImageCheck>,
    /// Its registered images' shifts against the first frame's registered trace (or the
    /// frame before's), measured from the pixels alone.
    pub registered_shifts: Vec<PassShift>,
}

/// A registered image's shift against another frame's registered trace: the sub-pixel
/// shift that best maps one onto the other over their overlap (gain, offset and tilt
/// fitted alongside); 0 when both are registered alike, blind to whole lattice periods.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct PassShift {
    /// Trace or retrace.
    pub pass: dhct_scan::ScanPass,
    /// The frame whose registered trace it was measured against: the first, or the one
    /// before where the first overlaps it too little.
    pub against_frame: Option<usize>,
    /// (columns, rows) of the first frame's grid, pixels; `None` when no frame overlaps it
    /// enough to measure it.
    pub shift_px: Option<[f64; 2]>,
}

/// `series.json`: the frames, the fit and what was assumed.
#[derive(Debug, Clone, Serialize)]
pub struct SeriesSummary {
    /// The frames in time order.
    pub frames: Vec<FrameSummary>,
    /// The series fit.
    pub fit: SeriesFit,
    /// The mean registered image's lattice, measured by FFT (if it could be).
    pub mean_check: Option<CorrectedImageCheck>,
    /// What the series' results should not be trusted for: frames the session's model
    /// does not explain, registered images whose lattice is off or not measurable. Each
    /// frame's own warnings are in its [`FrameSummary::warnings`].
    pub warnings: Vec<Warning>,
    /// Notes and assumptions (clock, order).
    pub notes: Vec<String>,
    /// Files written into the output directory.
    pub outputs: Vec<String>,
    /// Wall time of each stage, seconds.
    pub timings: SeriesTimings,
}

/// Wall time of each stage of `dhct series`, seconds.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct SeriesTimings {
    /// Every frame analysed alone (read, lattice, features, its own model), side by side.
    pub frames_s: f64,
    /// The frames' stages summed over the frames (seconds of one core each).
    pub frame_stages: dhct_pipeline::StageTimings,
    /// Consecutive frames compared by their images (the steps between them).
    pub steps_s: f64,
    /// The series fit.
    pub fit_s: f64,
    /// The features, the trajectory and the registered images written and checked.
    pub registered_s: f64,
    /// The report.
    pub report_s: f64,
    /// The whole run.
    pub total_s: f64,
}

/// Runs `dhct series`; returns the summary (also written as `series.json`).
pub fn run(request: &SeriesRequest) -> Result<SeriesSummary> {
    let started = Instant::now();
    let mut timings = SeriesTimings::default();
    let sources = sources::find_frames(request)?;
    let staged =
        crate::output_dir::StagedOutput::prepare(request.output, request.config.overwrite)?;
    // Each frame keeps its features and model only: the images are read again when the
    // registered ones are written, so memory holds the images of the frames being analysed
    // (one per worker thread) at a time. Frames are analysed side by side: one 512² frame
    // alone does not keep the cores busy.
    let corrected: Vec<FrameModel> = sources
        .par_iter()
        .map(|source| {
            source
                .read(&request.config)
                .and_then(|pair| analyse_model_pair(pair, &request.config, frame_options))
                .map(kept_for_the_series)
                .with_context(|| format!("frame {source} cannot be analysed alone"))
        })
        .collect::<Result<_>>()?;
    timings.frames_s = started.elapsed().as_secs_f64();
    timings.frame_stages = summed_stages(&corrected);
    let steps_started = Instant::now();
    let geometries: Vec<(FrameSource, &dhct_scan::ScanGeometry)> = sources
        .iter()
        .zip(&corrected)
        .map(|(p, c)| (p.clone(), &c.geometry))
        .collect();
    let (timed, mut notes) = order::order(&geometries)?;
    let steps = steps::observed(&corrected, &timed, &request.config)?;
    notes.extend(steps::notes(&steps));
    let steps: Vec<_> = steps.iter().map(|s| s.map(|s| s.step)).collect();
    timings.steps_s = steps_started.elapsed().as_secs_f64();
    let fit_started = Instant::now();
    let fit = fit_frames(&corrected, &timed, &steps, request)?;
    timings.fit_s = fit_started.elapsed().as_secs_f64();
    let warnings = trust::unexplained_frames(&fit, &timed);
    let mut summary = SeriesSummary {
        frames: timed
            .iter()
            .map(|t| frame_summary(t, &corrected[t.input]))
            .collect(),
        fit,
        mean_check: None,
        warnings,
        notes,
        outputs: Vec::new(),
        timings,
    };
    let written_started = Instant::now();
    let written = outputs::write_all(staged.path(), &summary, &corrected, &timed, &request.config)?;
    let lattice = corrected[timed[0].input].lattice.as_ref();
    summary.warnings.extend(trust::registered_image_warnings(
        &written.checks,
        &timed,
        lattice,
    ));
    for (frame, checks) in summary.frames.iter_mut().zip(written.checks.frames) {
        frame.registered_checks = checks;
    }
    for (frame, shifts) in summary.frames.iter_mut().zip(written.checks.shifts) {
        frame.registered_shifts = shifts;
    }
    summary.mean_check = written.checks.mean;
    summary.timings.registered_s = written_started.elapsed().as_secs_f64();
    let report_started = Instant::now();
    let grid = &corrected[timed[0].input].geometry;
    let pitch = [grid.pitch_x(), grid.pitch_y()];
    let shifted = trust::shift_warnings(&summary.frames, pitch);
    summary.warnings.extend(shifted);
    let mean = report::MeanImage {
        channel: &written.mean,
        grid,
    };
    let colormap = request
        .config
        .colormap
        .unwrap_or(dhct_sm4_io::png_file::Colormap::Gold);
    let mut files = written.files.clone();
    files.extend(report::write_report(
        staged.path(),
        &summary,
        &mean,
        colormap,
    )?);
    summary.outputs = files;
    summary.timings.report_s = report_started.elapsed().as_secs_f64();
    summary.timings.total_s = started.elapsed().as_secs_f64();
    outputs::write_summary(staged.path(), &summary)?;
    staged.commit()?;
    Ok(summary)
}

/// The frames' stage timings summed.
fn summed_stages(frames: &[FrameModel]) -> dhct_pipeline::StageTimings {
    let mut sum = dhct_pipeline::StageTimings::default();
    for t in frames.iter().map(|f| &f.run.timings) {
        sum.calibration_s += t.calibration_s;
        sum.features_s += t.features_s;
        sum.model_s += t.model_s;
        sum.total_s += t.total_s;
    }
    sum
}

/// Each frame's own model only starts the series fit: the paper's local route alone, without
/// the global registration and its cross-validation (a third of the cost of a frame), and
/// each local distortion compared with the model's derivative, as the series fit does, not
/// its secant over the neighbours (half the cost of the model fit).
fn frame_options(options: &mut dhct_pipeline::PipelineOptions) {
    options.dhct.route = dhct_distortion::RoutePolicy::LocalOnly;
    options.dhct.fit.secant = false;
}

/// `frame` without what the series does not read (the rejected candidates, each feature's
/// local distortion), so that a long session holds little more than its features.
fn kept_for_the_series(mut frame: FrameModel) -> FrameModel {
    for set in &mut frame.run.features {
        set.rejected = Vec::new();
        set.features.shrink_to_fit();
    }
    frame.run.dhct.passes = Vec::new();
    frame.run.dhct.routes = None;
    frame
}

/// The series fit of the analysed frames in time order, each placed from the frame before
/// by `steps` where given.
fn fit_frames(
    corrected: &[FrameModel],
    timed: &[Timed],
    steps: &[Option<dhct_distortion::series::ObservedStep>],
    request: &SeriesRequest,
) -> Result<SeriesFit> {
    let frames: Vec<SeriesFrame> = timed
        .iter()
        .zip(steps)
        .map(|(t, &observed_step)| {
            let c = &corrected[t.input];
            SeriesFrame {
                geometry: &c.geometry,
                inputs: c
                    .run
                    .features
                    .iter()
                    .map(|set| PassInput {
                        features: &set.features,
                        mask: c.mask.as_ref(),
                    })
                    .collect(),
                model: &c.run.dhct.model,
                start_s: t.start_s,
                observed_step,
            }
        })
        .collect();
    let lattice = corrected[timed[0].input].lattice.as_ref();
    let options = SeriesOptions {
        fit: FitOptions {
            secant: false,
            ..corrected[timed[0].input].options.dhct.fit
        },
        knots: request
            .knots
            .map_or(KnotChoice::CrossValidated, KnotChoice::Fixed),
    };
    fit_series(&frames, lattice, &options).context("the series fit failed")
}

fn frame_summary(t: &Timed, c: &FrameModel) -> FrameSummary {
    let g = &c.geometry;
    let model = &c.run.dhct.model;
    let drift_count = model
        .parameters
        .iter()
        .take_while(|p| !matches!(p.name.as_str(), "k" | "n" | "amplitude" | "c0"))
        .count();
    FrameSummary {
        file: t.source.to_string(),
        start_s: t.start_s,
        scan_angle_deg: g.scan_angle().to_degrees(),
        offset_m: [g.offset().0, g.offset().1],
        features: c.run.features.iter().map(|set| set.features.len()).sum(),
        own_hysteresis: model.parameters[drift_count..].to_vec(),
        warnings: c.run.input_warnings.clone(),
        registered_checks: Vec::new(),
        registered_shifts: Vec::new(),
    }
}

/// The warnings, for stderr: each frame's own (the inputs it was analysed with), then the
/// series'.
pub fn warning_lines(summary: &SeriesSummary) -> String {
    let frames = summary.frames.iter().enumerate().flat_map(|(k, frame)| {
        frame
            .warnings
            .iter()
            .map(move |w| format!("warning: frame {k} ({}): {}\n", frame.file, warning_line(w)))
    });
    let series = summary
        .warnings
        .iter()
        .map(|w| format!("warning: {}\n", warning_line(w)));
    frames.chain(series).collect()
}

/// "registered images line up within … px": the largest pixel shift between registered
/// images, measured from their pixels.
fn shift_line(summary: &SeriesSummary) -> String {
    let shifts: Vec<f64> = summary
        .frames
        .iter()
        .flat_map(|f| &f.registered_shifts)
        .filter_map(|s| s.shift_px.map(|d| d[0].hypot(d[1])))
        .collect();
    let missing = summary
        .frames
        .iter()
        .flat_map(|f| &f.registered_shifts)
        .filter(|s| s.shift_px.is_none())
        .count();
    let largest = shifts.iter().copied().fold(0.0, f64::max);
    format!(
        "registered images line up within {largest:.3} px of each other by their pixels ({} \
         compared{})",
        shifts.len(),
        if missing > 0 {
            format!(", {missing} overlapping too little")
        } else {
            String::new()
        }
    )
}

/// What `dhct series` prints: the frames, the drift, the hysteresis and where the outputs
/// are.
pub fn text_summary(summary: &SeriesSummary, output: &Path) -> String {
    use dhct_scan::quantity::{length, value_with_sigma};
    use std::fmt::Write as _;
    let fit = &summary.fit;
    let mut text = String::new();
    for note in &summary.notes {
        if note.starts_with("assumption:") {
            let _ = writeln!(text, "{note}");
        } else {
            let _ = writeln!(text, "note: {note}");
        }
    }
    let session = fit.trajectory.last().map_or(0.0, |p| p.time_s);
    let _ = writeln!(
        text,
        "{} frames over {:.0} s; {} features fitted, rms deviation from the lattice {}",
        summary.frames.len(),
        session,
        fit.features,
        length(fit.rms_deviation_m)
    );
    let _ = writeln!(text, "drift: {}", report::drift_description(fit));
    for start in &fit.unresolved_creeps_s {
        let _ = writeln!(
            text,
            "  the creep after the move at {start:.1} s is not resolved (its time constant \
             ran to a bound): left out, the drift spline takes it"
        );
    }
    for (k, (frame, start)) in summary.frames.iter().zip(&fit.frame_starts).enumerate() {
        let _ = writeln!(
            text,
            "  frame {k:>2} at {:>7.1} s: D = ({}, {}) {}",
            frame.start_s,
            report::shown(start.displacement_m[0], start.sigma_m[0]),
            report::shown(start.displacement_m[1], start.sigma_m[1]),
            frame.file
        );
    }
    for p in &fit.parameters {
        let _ = writeln!(
            text,
            "  {} = {}",
            p.name,
            value_with_sigma(p.value, p.sigma, &p.unit)
        );
    }
    let _ = writeln!(text, "{}", shift_line(summary));
    let _ = writeln!(text, "outputs: {}", output.display());
    let _ = writeln!(text, "report: {}", output.join("report.html").display());
    text
}
