//! The application's core, shared by every front end: a scan pair (or a file) and a config
//! resolved into the lattice, constant and options, and the whole pipeline run on it
//! ([`analyse`], [`analyse_file`]), with typed errors ([`CorrectError`]) that the command
//! line and Python render in their own terms. Nothing here writes a file: `correct`
//! writes the outputs, `diagnose` adds the diagnosis.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Result;
use dhct_calibrate::CalibrationError;
use dhct_lattice::Lattice;
use dhct_pipeline::{Analysis, PipelineError, PipelineOptions, Stage, UserInput};
use dhct_scan::{ScanPair, ScanPass};
use ndarray::Array2;

use crate::hints::{Spelling, explain, explain_calibration, explain_options};
use crate::report::summary::{self, RunSummary};
use crate::setup::{
    CorrectConfig, MeasuredNnError, Resolved, load_mask, read_pair, resolve, with_measured_nn,
};

/// A finished analysis of one scan pair with everything needed to write its outputs
/// (the same files whichever front end asks for them).
pub struct Corrected {
    /// The scan pair analysed (geometry in metres and seconds).
    pub pair: ScanPair,
    /// The config the run was resolved from (file + flags).
    pub config: CorrectConfig,
    /// The lattice as named (preset or file).
    pub lattice_name: String,
    /// The nearest-neighbour distance given or measured (`--nn auto`), metres.
    pub nn_m: Option<f64>,
    /// The lattice the run used (with that nearest-neighbour distance).
    pub lattice: Box<dyn Lattice + Send + Sync>,
    /// The pipeline options the run used.
    pub options: PipelineOptions,
    /// The analysed area (true = used), if a mask was given.
    pub mask: Option<Array2<bool>>,
    /// Every intermediate of the pipeline.
    pub analysis: Analysis,
    /// The content of `model.json` (`outputs` and `write_s` are filled when written).
    pub summary: RunSummary,
    /// The files the scan was read from (input, and the retrace's own file), when it came
    /// from files: the other channels are read from them again.
    pub source: Option<(PathBuf, Option<PathBuf>)>,
}

/// Why an analysis stopped, by which stage refused (the message is the command line's).
#[derive(Debug, thiserror::Error)]
pub enum CorrectError {
    /// The lattice, constant, mask or pipeline options could not be resolved.
    #[error("{0:#}")]
    Options(anyhow::Error),
    /// The image does not match the lattice or constant given.
    #[error("{error}")]
    InputMismatch {
        /// What the image shows against what was given.
        error: CalibrationError,
        /// Whether it happened measuring the nearest-neighbour distance (`auto`).
        measuring_nn: bool,
    },
    /// The pipeline itself failed (too few features, lattice not found, ...).
    #[error("{0}")]
    Analysis(PipelineError),
}

impl CorrectError {
    /// The error with the hint of what to change, spelled for a front end.
    pub fn render(&self, spelling: Spelling) -> String {
        match self {
            CorrectError::Options(e) => explain_options(e, spelling),
            CorrectError::InputMismatch {
                error,
                measuring_nn,
            } => {
                let text = explain_calibration(error, spelling);
                if *measuring_nn {
                    let auto = spelling.set(UserInput::NearestNeighbourDistance, "auto");
                    format!("{auto}: {text}")
                } else {
                    text
                }
            }
            CorrectError::Analysis(e) => explain(e, spelling),
        }
    }
}

/// What to analyse: a scan pair, the config it is resolved with, and labels for the summary.
pub struct AnalyseRequest {
    /// The scan pair (e.g. from [`read_pair`] or built from arrays).
    pub pair: ScanPair,
    /// The config file (if any) overridden by the caller's options.
    pub config: CorrectConfig,
    /// A mask given as an array (true = use), raw-image pixels; intersected with the
    /// config's mask file and polygon.
    pub mask: Option<Array2<bool>>,
    /// The input's name in the summary (a path, or a note for arrays).
    pub input: String,
    /// The retrace file's name in the summary, if it came from its own file.
    pub retrace: Option<String>,
    /// Time spent reading the input, seconds.
    pub read_s: f64,
}

/// Resolves the request's config against its pair and runs the whole pipeline: no file is
/// written. `on_stage` is told each stage.
pub fn analyse(
    request: AnalyseRequest,
    on_stage: &(dyn Fn(Stage) + Sync),
) -> Result<Corrected, CorrectError> {
    let AnalyseRequest {
        pair,
        config,
        mask: given_mask,
        input,
        retrace,
        read_s,
    } = request;
    let geometry = pair.geometry().clone();
    let (mask, resolved) = resolve_for(&pair, &config, given_mask)?;
    let Resolved {
        lattice_name,
        nn_m,
        lattice,
        options,
        ..
    } = resolved;
    let analysis = dhct_pipeline::run(&pair, lattice.as_ref(), mask.as_ref(), &options, on_stage)
        .map_err(|e| match e {
        PipelineError::Calibration(error) => CorrectError::InputMismatch {
            error: *error,
            measuring_nn: false,
        },
        e => CorrectError::Analysis(e),
    })?;
    let mut summary = summary::summarise(
        input,
        retrace,
        lattice.as_ref(),
        &geometry,
        &analysis,
        read_s,
    );
    summary.lattice_assumed = config.lattice.is_none();
    Ok(Corrected {
        pair,
        config,
        lattice_name,
        nn_m,
        lattice,
        options,
        mask,
        analysis,
        summary,
        source: None,
    })
}

/// The analysed area (the config's mask file and polygon, intersected with `given_mask`)
/// and the config resolved against `pair` (lattice, constant — measured for `--nn auto` —
/// and pipeline options).
fn resolve_for(
    pair: &ScanPair,
    config: &CorrectConfig,
    given_mask: Option<Array2<bool>>,
) -> Result<(Option<Array2<bool>>, Resolved), CorrectError> {
    let mask = match (load_mask(config, pair.geometry()), given_mask) {
        (Err(e), _) => return Err(CorrectError::Options(e)),
        (Ok(Some(a)), Some(b)) => Some(
            dhct_distortion::mask::intersect(&a, &b)
                .map_err(|e| CorrectError::Options(anyhow::anyhow!("mask: {e}")))?,
        ),
        (Ok(a), b) => a.or(b),
    };
    let resolved = resolve(config).map_err(CorrectError::Options)?;
    let resolved = with_measured_nn(resolved, pair, mask.as_ref()).map_err(|e| match e {
        MeasuredNnError::Mismatch(error) => CorrectError::InputMismatch {
            error,
            measuring_nn: true,
        },
        MeasuredNnError::Options(e) => CorrectError::Options(e),
    })?;
    Ok((mask, resolved))
}

/// What [`analyse_model_file`] keeps of one scan: its geometry, the lattice and options it
/// was resolved to, and its features and model; no image (a series holds many frames).
pub struct FrameModel {
    /// The scan's geometry.
    pub geometry: dhct_scan::ScanGeometry,
    /// The lattice the run used.
    pub lattice: Box<dyn Lattice + Send + Sync>,
    /// The pipeline options the run used.
    pub options: PipelineOptions,
    /// The analysed area, if a mask was given.
    pub mask: Option<Array2<bool>>,
    /// The features and the model.
    pub run: dhct_pipeline::ModelRun,
}

/// Reads `input` and runs the pipeline's stages 0–2 on it ([`dhct_pipeline::run_model`]):
/// the calibration check, the features and the model, with the config resolved as
/// `dhct correct` resolves it, then `adjust`ed; errors in the command line's words.
pub fn analyse_model_file(
    input: &Path,
    config: &CorrectConfig,
    adjust: fn(&mut PipelineOptions),
) -> Result<FrameModel> {
    let pair = read_pair(input, None, &config.geometry, config.channel.as_deref())?;
    analyse_model_pair(pair, config, adjust)
}

/// [`analyse_model_file`] of a pair already read.
pub fn analyse_model_pair(
    pair: ScanPair,
    config: &CorrectConfig,
    adjust: fn(&mut PipelineOptions),
) -> Result<FrameModel> {
    let render = |e: CorrectError| anyhow::anyhow!(e.render(Spelling::CommandLine));
    let (mask, mut resolved) = resolve_for(&pair, config, None).map_err(render)?;
    adjust(&mut resolved.options);
    let run = dhct_pipeline::run_model(
        &pair,
        resolved.lattice.as_ref(),
        mask.as_ref(),
        &resolved.options,
        &|_| {},
    )
    .map_err(|e| match e {
        PipelineError::Calibration(error) => render(CorrectError::InputMismatch {
            error: *error,
            measuring_nn: false,
        }),
        e => render(CorrectError::Analysis(e)),
    })?;
    Ok(FrameModel {
        geometry: pair.geometry().clone(),
        lattice: resolved.lattice,
        options: resolved.options,
        mask,
        run,
    })
}

/// Reads `input` (and `retrace`, if given) with the config's geometry and channel and runs
/// [`analyse`] on it, as `dhct correct` and `dhct diagnose` do; errors in the command
/// line's words.
pub fn analyse_file(
    input: &Path,
    retrace: Option<&Path>,
    config: CorrectConfig,
    on_stage: &(dyn Fn(Stage) + Sync),
) -> Result<Corrected> {
    let start = Instant::now();
    let pair = read_pair(input, retrace, &config.geometry, config.channel.as_deref())?;
    let read_s = start.elapsed().as_secs_f64();
    let source = (input.to_path_buf(), retrace.map(Path::to_path_buf));
    analyse(
        AnalyseRequest {
            pair,
            config,
            mask: None,
            input: input.display().to_string(),
            retrace: retrace_name(input, retrace),
            read_s,
        },
        on_stage,
    )
    .map_err(|e| match e {
        e @ CorrectError::Options(_) => anyhow::anyhow!(e.render(Spelling::CommandLine)),
        e @ CorrectError::InputMismatch { .. } => {
            anyhow::anyhow!(e.render(Spelling::CommandLine))
        }
        e @ CorrectError::Analysis(_) => anyhow::anyhow!(e.render(Spelling::CommandLine))
            .context(format!("analysing {}", input.display())),
    })
    .map(|corrected| Corrected {
        source: Some(source),
        ..corrected
    })
}

/// The name of the file the retrace came from: the one given, or the NPY retrace paired
/// with an NPY trace through their sidecars.
fn retrace_name(input: &Path, retrace: Option<&Path>) -> Option<String> {
    let paired = || match dhct_sm4_io::npy_sidecar::other_pass_file(input) {
        Some((path, ScanPass::Retrace)) => Some(path),
        _ => None,
    };
    retrace
        .map(Path::to_path_buf)
        .or_else(paired)
        .map(|p| p.display().to_string())
}
