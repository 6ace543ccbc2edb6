//! `dhct correct`: the whole DHCT chain on one file (or a trace/retrace pair of files), with
//! every result written into an output directory and summarised in `report.html`.

pub(crate) mod corrected_files;
pub mod feature_table;

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use dhct_pipeline::{Analysis, Stage};
use dhct_scan::{ImageChannel, ScanPair, ScanPass};
use dhct_sm4_io::png_file::Colormap;
use dhct_sm4_io::write_atomically;
use indicatif::{ProgressBar, ProgressStyle};
use ndarray::Array2;
use rayon::prelude::*;

pub use crate::analysis::{AnalyseRequest, CorrectError, Corrected, analyse, analyse_file};
use crate::report::figures::{FigureInputs, make_figures};
pub use crate::report::summary::RunSummary;
use crate::report::{html, write_bytes, write_figure_files};
pub use crate::setup::{
    ChannelSet, CorrectConfig, Extent, Length, MeasuredNnError, Resolved, build_lattice, load_mask,
    read_pair, resolve, with_measured_nn,
};
use corrected_files::{CorrectedImage, write_corrected_files};
use feature_table::write_features_csv;

/// What to run.
pub struct CorrectRequest<'a> {
    /// The scan file (trace, or the only image).
    pub input: &'a Path,
    /// A second file whose image of the same channel is the retrace.
    pub retrace: Option<&'a Path>,
    /// The output directory.
    pub output: &'a Path,
    /// The config file (if any) overridden by the command-line flags.
    pub config: CorrectConfig,
    /// Show progress on stderr (only when it is a terminal).
    pub progress: bool,
    /// Also run the sim-to-real gap diagnosis and add it to the report.
    pub diagnose: bool,
}

pub(crate) fn progress_bar(enabled: bool) -> ProgressBar {
    if enabled && std::io::IsTerminal::is_terminal(&std::io::stderr()) {
        let bar = ProgressBar::new_spinner();
        bar.set_style(
            ProgressStyle::with_template("{spinner} [{elapsed_precise}] {msg}")
                .unwrap_or_else(|_| ProgressStyle::default_spinner()),
        );
        bar.enable_steady_tick(Duration::from_millis(120));
        bar
    } else {
        ProgressBar::hidden()
    }
}

/// Runs `dhct correct`; returns the summary (also written as `model.json`).
pub fn run(request: CorrectRequest) -> Result<RunSummary> {
    // Everything is written into a staging folder, moved into place at the end.
    let staged =
        crate::output_dir::StagedOutput::prepare(request.output, request.config.overwrite)?;
    let bar = progress_bar(request.progress);
    bar.set_message("reading");
    let corrected = analyse_file(
        request.input,
        request.retrace,
        request.config,
        &|stage: Stage| bar.set_message(stage.describe()),
    )?;
    let summary = write_into(staged.path(), &corrected, request.diagnose, &bar)?;
    staged.commit()?;
    bar.finish_and_clear();
    Ok(summary)
}

/// Writes every output of `corrected` into `output` (through a staging folder, replacing
/// an earlier run only with `overwrite`), as `dhct correct` does; returns `model.json`'s
/// content.
pub fn write(
    corrected: &Corrected,
    output: &Path,
    overwrite: bool,
    diagnose: bool,
) -> Result<RunSummary> {
    let staged = crate::output_dir::StagedOutput::prepare(output, overwrite)?;
    let summary = write_into(staged.path(), corrected, diagnose, &ProgressBar::hidden())?;
    staged.commit()?;
    Ok(summary)
}

/// Writes the images, figures, feature table, config, `model.json` and report into `dir`.
fn write_into(
    dir: &Path,
    corrected: &Corrected,
    diagnose: bool,
    bar: &ProgressBar,
) -> Result<RunSummary> {
    let Corrected {
        pair,
        config,
        lattice,
        analysis,
        mask,
        ..
    } = corrected;
    bar.set_message("writing outputs and report");
    let write_start = Instant::now();
    let mut summary = corrected.summary.clone();
    let colormap = config.colormap.unwrap_or(Colormap::Gold);
    // Figures, data images and the feature table are independent: made and written in
    // parallel.
    let ((figures, images), csv) = rayon::join(
        || {
            rayon::join(
                || {
                    make_figures(&FigureInputs {
                        pair,
                        lattice: lattice.as_ref(),
                        analysis,
                        mask: mask.as_ref(),
                        colormap,
                    })
                },
                || {
                    let extent = config.extent.unwrap_or_default();
                    let mut written = write_data_images(dir, pair, analysis, extent)?;
                    if config.displacement == Some(true) {
                        written.extend(write_displacement_fields(dir, pair, analysis)?);
                    }
                    if config.channels == Some(ChannelSet::All) {
                        written.extend(write_other_channels(dir, corrected)?);
                    }
                    Ok::<_, anyhow::Error>(written)
                },
            )
        },
        || write_features_csv(dir, analysis),
    );
    let mut outputs = images?;
    outputs.push(csv?);
    outputs.extend(write_figure_files(dir, &figures)?);
    write_resolved_config(dir, corrected, colormap)?;
    outputs.extend(["config.toml", "model.json", "report.html"].map(String::from));
    summary.outputs = outputs;
    summary.write_s = write_start.elapsed().as_secs_f64();
    let json = serde_json::to_string_pretty(&summary).context("cannot serialise model.json")?;
    write_bytes(&dir.join("model.json"), json.as_bytes())?;
    let section = if diagnose {
        bar.set_message("diagnosing the sim-to-real gap");
        Some(write_diagnosis(dir, corrected)?)
    } else {
        None
    };
    let html = html::report_html(&summary, &figures, section);
    write_bytes(&dir.join("report.html"), html.as_bytes())?;
    Ok(summary)
}

/// `config.toml`: the resolved config, everything needed to repeat the run.
fn write_resolved_config(dir: &Path, corrected: &Corrected, colormap: Colormap) -> Result<()> {
    let config = &corrected.config;
    let resolved = CorrectConfig {
        lattice: Some(corrected.lattice_name.clone()),
        // As given (a preset's own constant is exact; the NN distance derived from its
        // vectors may differ in the last bit), in Rust's shortest round-trip form: the TOML
        // writer prints small floats as long decimals.
        nn: corrected.nn_m.map(|nn| Length::Text(format!("{nn:e}"))),
        polarity: Some(corrected.options.features.polarity),
        colormap: Some(colormap),
        geometry: config.geometry.clone(),
        pipeline: Some(crate::setup::pipeline_table(&corrected.options)?),
        ..config.clone()
    };
    let toml_text = format!(
        "# dhct correct: the resolved configuration of this run (use with --config)\n{}",
        toml::to_string(&resolved).context("cannot serialise the resolved config")?
    );
    write_bytes(&dir.join("config.toml"), toml_text.as_bytes())?;
    Ok(())
}

/// The sim-to-real gap diagnosis (`diagnosis.json` and its figures); returns the report
/// section.
fn write_diagnosis(dir: &Path, corrected: &Corrected) -> Result<crate::report::page::Html> {
    let geometry = corrected.pair.geometry();
    let (diagnosis, residuals) = crate::diagnose::diagnosis_of(corrected)?;
    write_bytes(&dir.join("diagnosis.json"), diagnosis.to_json().as_bytes())?;
    crate::diagnose::write_residual_images(dir, &residuals, geometry)?;
    let (section, diagnosis_figures) =
        crate::diagnose::diagnosis_section(&diagnosis, &residuals, geometry);
    write_figure_files(dir, &diagnosis_figures)?;
    Ok(section)
}

fn channel_like(pair: &ScanPair, pass: ScanPass, z: &Array2<f64>) -> ImageChannel {
    let (name, unit) = pair
        .image(pass)
        .map(|c| (format!("{} (corrected)", c.name), c.unit.clone()))
        .unwrap_or_else(|| ("corrected".into(), "m".into()));
    ImageChannel::new(name, unit, z.clone())
}

/// How one data image is written.
enum DataFormat {
    /// Float TIFF with the pixel size (metres, x and y) when it has one.
    Tiff(Option<[f64; 2]>),
    /// GSF of the given pass (pixel size and geometry from the scan).
    Gsf(ScanPass),
}

/// The data images: corrected images (TIFF with the scan's pixel size, GSF) and the unit
/// cells (TIFF without a pixel size: their grid is in lattice coordinates), written in
/// parallel.
fn write_data_images(
    dir: &Path,
    pair: &ScanPair,
    analysis: &Analysis,
    extent: Extent,
) -> Result<Vec<String>> {
    let geometry = pair.geometry();
    let pitch = [geometry.pitch_x(), geometry.pitch_y()];
    let mut written = Vec::new();
    // One copy of each image, shared by its files (a huge scan's images are gigabytes).
    let mut jobs: Vec<(String, Arc<ImageChannel>, DataFormat)> = Vec::new();
    for pass in &analysis.passes {
        if extent == Extent::Full {
            let Some(raw) = pair.image(pass.pass) else {
                continue;
            };
            let image = CorrectedImage {
                stem: format!("corrected_{}", pass.pass),
                raw,
                pass: pass.pass,
                model: &analysis.dhct.model,
                geometry,
            };
            written.extend(write_corrected_files(dir, &image, extent)?);
            continue;
        }
        let channel = Arc::new(channel_like(pair, pass.pass, &pass.corrected_image));
        let name = format!("corrected_{}", pass.pass);
        jobs.push((
            format!("{name}.tiff"),
            Arc::clone(&channel),
            DataFormat::Tiff(Some(pitch)),
        ));
        jobs.push((format!("{name}.gsf"), channel, DataFormat::Gsf(pass.pass)));
    }
    if let Some(cell) = &analysis.unit_cell {
        for (name, values) in [
            ("unit_cell_averaged.tiff", &cell.averaged.values),
            ("unit_cell_symmetrized.tiff", &cell.symmetrized.values),
        ] {
            let channel = Arc::new(ImageChannel::new(name, "m", values.clone()));
            jobs.push((name.into(), channel, DataFormat::Tiff(None)));
        }
    }
    let from_jobs: Vec<String> = jobs
        .par_iter()
        .map(|(name, channel, format)| {
            write_atomically(&dir.join(name), |w| match format {
                DataFormat::Gsf(pass) => dhct_sm4_io::gsf::write_pass(channel, geometry, *pass, w),
                DataFormat::Tiff(Some(pitch)) => {
                    dhct_sm4_io::tiff_file::write_f32_with_pixel_size(channel, *pitch, w)
                }
                DataFormat::Tiff(None) => dhct_sm4_io::tiff_file::write_f32(channel, w),
            })?;
            Ok(name.clone())
        })
        .collect::<Result<_>>()?;
    written.extend(from_jobs);
    Ok(written)
}

/// Every other image channel of the source file(s), corrected with the model kept:
/// `corrected_{channel}_{pass}.tiff` (float, pixel size, unit) and `.gsf`. Channels of
/// another size than the analysed one are left out with a note on stderr.
fn write_other_channels(dir: &Path, corrected: &Corrected) -> Result<Vec<String>> {
    let Some((input, retrace)) = &corrected.source else {
        anyhow::bail!("channels = all needs the scan's file: the other channels are read from it");
    };
    let analysed = corrected.pair.images().next().map(|(_, c)| c.name.clone());
    let geometry = corrected.pair.geometry();
    let file = dhct_sm4_io::read_path_with_limits(
        input,
        &corrected.config.geometry,
        &crate::read_limits::get(),
    )
    .with_context(|| format!("cannot read {} again for its channels", input.display()))?;
    let mut names = Vec::new();
    let mut used: Vec<String> = Vec::new();
    for other in &file.pairs {
        let Some((_, first)) = other.images().next() else {
            continue;
        };
        if Some(&first.name) == analysed.as_ref() {
            continue;
        }
        let pair = crate::setup::read_pair(
            input,
            retrace.as_deref(),
            &corrected.config.geometry,
            Some(&first.name),
        )?;
        if pair.geometry().frame() != geometry.frame() {
            eprintln!(
                "note: channel {} belongs to frame {} of the file, recorded at another time \
                 than the analysed frame {}: not corrected with this frame's model",
                first.name,
                pair.geometry().frame(),
                geometry.frame()
            );
            continue;
        }
        if (pair.geometry().columns(), pair.geometry().rows())
            != (geometry.columns(), geometry.rows())
        {
            eprintln!(
                "note: channel {} is {} x {} px, not the analysed {} x {}: not corrected",
                first.name,
                pair.geometry().columns(),
                pair.geometry().rows(),
                geometry.columns(),
                geometry.rows()
            );
            continue;
        }
        let stem = unique_stem(&first.name, &mut used);
        for (pass, image) in pair.images() {
            let image = CorrectedImage {
                stem: format!("corrected_{stem}_{pass}"),
                raw: image,
                pass,
                model: &corrected.analysis.dhct.model,
                geometry,
            };
            let extent = corrected.config.extent.unwrap_or_default();
            names.extend(write_corrected_files(dir, &image, extent)?);
        }
    }
    Ok(names)
}

/// A file-name-safe stem for channel `name` (letters, digits, `-`, `_`; others become
/// `_`), made unique among `used`.
fn unique_stem(name: &str, used: &mut Vec<String>) -> String {
    let base: String = name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' {
                c
            } else {
                '_'
            }
        })
        .collect();
    let base = if base.is_empty() {
        "channel".to_string()
    } else {
        base
    };
    let mut stem = base.clone();
    let mut k = 2;
    while used.contains(&stem) {
        stem = format!("{base}_{k}");
        k += 1;
    }
    used.push(stem.clone());
    stem
}

/// Each pass's displacement field under the correction kept: `displacement_{pass}.npy`
/// (shape `(2, rows, columns)`: `dx`, `dy` in metres) and `displacement_{pass}.tiff` (the
/// same as two float pages with the pixel size).
fn write_displacement_fields(
    dir: &Path,
    pair: &ScanPair,
    analysis: &Analysis,
) -> Result<Vec<String>> {
    let geometry = pair.geometry();
    let pitch = [geometry.pitch_x(), geometry.pitch_y()];
    let mut names = Vec::new();
    for pass in &analysis.passes {
        let field = dhct_distortion::displacement_field(&analysis.dhct.model, geometry, pass.pass);
        let stem = format!("displacement_{}", pass.pass);
        write_atomically(&dir.join(format!("{stem}.npy")), |w| {
            dhct_sm4_io::npy::write_stack(&[&field.dx_m, &field.dy_m], w)
        })?;
        let dx = ImageChannel::new(format!("{stem} dx"), "m", field.dx_m);
        let dy = ImageChannel::new(format!("{stem} dy"), "m", field.dy_m);
        write_atomically(&dir.join(format!("{stem}.tiff")), |w| {
            dhct_sm4_io::tiff_file::write_f32_pages_with_pixel_size(&[&dx, &dy], pitch, w)
        })?;
        names.extend([format!("{stem}.npy"), format!("{stem}.tiff")]);
    }
    Ok(names)
}

/// A one-screen text summary.
pub fn text_summary(summary: &RunSummary, output: &Path) -> String {
    use std::fmt::Write as _;
    let mut s = String::new();
    let counts: Vec<String> = summary
        .passes
        .iter()
        .map(|p| {
            let [x, y] = p.correlated_noise_factor;
            let raised = if x > 1.005 || y > 1.005 {
                format!("; fit 1σ × {x:.2} × {y:.2} for correlated pixel noise")
            } else {
                String::new()
            };
            let outside = if p.outside_frame > 0 {
                format!(
                    "; {} outside the frame after correction: not in a frame-sized corrected \
                     image (the full extent keeps them)",
                    p.outside_frame
                )
            } else {
                String::new()
            };
            format!(
                "{} {} ({} indexed{raised}{outside})",
                p.pass, p.features, p.indexed
            )
        })
        .collect();
    s.push_str(&calibration_lines(summary));
    let _ = writeln!(s, "features: {}", counts.join(", "));
    for p in &summary.passes {
        let _ = writeln!(s, "line levelling, {}: {}", p.pass, p.line_levelling);
    }
    for p in &summary.parameters {
        let _ = writeln!(
            s,
            "  {:<28} {}",
            p.name,
            crate::units::value_with_sigma(p.value, p.sigma, &p.unit)
        );
    }
    if let Some(words) =
        crate::report::summary::hysteresis_words(&summary.model.hysteresis, &summary.geometry)
    {
        let _ = writeln!(s, "hysteresis: {words}");
    }
    for r in &summary.regions {
        let _ = writeln!(
            s,
            "region {}: a = {:.4} x {:.4} Å, angle {:.2}°, rms deviation {:.1} pm, 1σ ellipse {:.1} x {:.1} pm",
            r.region,
            r.lattice_constant_m[0] * 1e10,
            r.lattice_constant_m[1] * 1e10,
            r.angle_deg,
            r.rms_deviation_m * 1e12,
            r.whole_ellipse.sigma_major_m * 1e12,
            r.whole_ellipse.sigma_minor_m * 1e12
        );
    }
    if let Some(c) = &summary.unit_cell {
        let _ = writeln!(
            s,
            "unit cell: {} cells averaged, symmetrised in {}",
            c.cells_selected, c.group
        );
    } else if let Some(note) = &summary.unit_cell_note {
        let _ = writeln!(s, "unit cell: not averaged ({note})");
    }
    let _ = writeln!(
        s,
        "analysis {:.2} s (read {:.2} s, write {:.2} s)",
        summary.timings.total_s, summary.read_s, summary.write_s
    );
    let _ = writeln!(s, "report: {}", output.join("report.html").display());
    s
}

/// The calibration and which correction was kept, one line each.
fn calibration_lines(summary: &RunSummary) -> String {
    use std::fmt::Write as _;
    let mut s = String::new();
    match (&summary.calibration, &summary.calibration_note) {
        (Some(found), _) => {
            for pass in &found.passes {
                let noise = pass.periodic_noise_note();
                let _ = writeln!(
                    s,
                    "{}: the image shows {}; {}{}{}",
                    pass.pass,
                    pass.lattice.describe(),
                    pass.matched.explanation(),
                    if noise.is_empty() { "" } else { "; " },
                    noise
                );
            }
            let c = &found.calibration;
            let _ = writeln!(
                s,
                "raw lattice against the named one: x {:.4} ± {:.4}, y {:.4} ± {:.4}, shear \
                 {:.2}° ± {:.2}° (apparent / true length: the file's pixel-size error and the \
                 drift, creep and hysteresis together; the model separates them)",
                c.scale[0],
                c.scale_sigma[0],
                c.scale[1],
                c.scale_sigma[1],
                c.shear_deg,
                c.shear_sigma_deg
            );
        }
        (None, Some(note)) => {
            let _ = writeln!(s, "calibration: not measured ({note})");
        }
        (None, None) => {}
    }
    for c in &summary.affine_baseline {
        let _ = writeln!(
            s,
            "region {}: rms deviation {:.1} pm with the drift model, {:.1} pm with a global affine correction",
            c.region,
            c.model_rms_m * 1e12,
            c.affine_rms_m * 1e12
        );
    }
    for check in &summary.corrected_images {
        let k = &check.calibration;
        let _ = writeln!(
            s,
            "corrected {} checked by FFT: {:.4} × {:.4} of the lattice along x × y, shear {:.2}°",
            check.pass, k.scale[0], k.scale[1], k.shear_deg
        );
    }
    if let Some(routes) = &summary.model_routes {
        let _ = writeln!(s, "model: {}", routes.describe());
    }
    if let Some(note) = &summary.model_route_note {
        let _ = writeln!(s, "model: {note}");
    }
    if summary.correction == dhct_pipeline::CorrectionSource::Affine {
        let _ = writeln!(s, "correction: {}", html::affine_reason(summary));
    }
    s
}

/// The warnings, for stderr.
pub fn warning_lines(summary: &RunSummary) -> String {
    summary
        .warnings
        .iter()
        .map(|w| format!("warning: {}\n", crate::flags::warning_line(w)))
        .collect()
}

/// Output directory for an input in batch mode.
pub fn batch_output(root: &Path, input: &Path) -> PathBuf {
    let stem = input
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "input".into());
    root.join(stem)
}
