//! `dhct diagnose`: where the fitted DHCT model and the image disagree, which unmodelled
//! effect explains it and how far the gap shrinks (dhct-diagnose); `--validate` runs the
//! withheld-effect validation. The same section is added to `dhct correct --diagnose`'s
//! report.

use std::fmt::Write as _;
use std::io::Write as _;
use std::path::Path;

use anyhow::{Context, Result};
use dhct_diagnose::{
    Bin, DiagnoseOptions, DiagnosisReport, FloorEstimate, FloorSource, ValidationOptions, diagnose,
    validate,
};
use dhct_distortion::PassInput;
use dhct_features::{Feature, find_features_in_pair};
use dhct_lattice::Lattice;
use dhct_pipeline::PipelineOptions;
use dhct_scan::ScanGeometry;
use dhct_sm4_io::png_file::Colormap;
use ndarray::Array2;

use crate::correct::figures::{Figure, FigureContent};
use crate::correct::plots::{
    BLUE, GREEN, ORANGE, Plot, Series, Style, VERMILION, html_escape, thin,
};
use crate::correct::render::{Canvas, heat_colour};
use crate::correct::report::{STYLE, figure_html, header, row};
use crate::correct::{self, CorrectConfig};
use crate::output_dir::StagedOutput;

/// Writes `text` to a locked stdout and flushes it. A closed pipe (`dhct … --json | head -1`)
/// is success, not a panic: the reader has all it wanted.
pub fn write_stdout(text: &str) -> Result<()> {
    let mut out = std::io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => {
            Err(e).context("writing to standard output")
        }
        _ => Ok(()),
    }
}

/// Runs the diagnosis on already found features (trace first); `mask` (raw-image pixels,
/// true = use) restricts it as it restricts the correction.
pub fn diagnose_features(
    sets: &[&[Feature]],
    geometry: &ScanGeometry,
    lattice: &dyn Lattice,
    mask: Option<&Array2<bool>>,
    pipeline: &PipelineOptions,
) -> Result<DiagnosisReport> {
    let inputs: Vec<PassInput> = sets
        .iter()
        .map(|features| PassInput { features, mask })
        .collect();
    let options = DiagnoseOptions {
        dhct: pipeline.dhct,
        ..DiagnoseOptions::default()
    };
    diagnose(&inputs, geometry, lattice, &options).context("diagnosis")
}

fn bin_plot(title: &str, x_label: &str, bins: &[Bin], x_scale: f64, noise: [f64; 2]) -> Plot {
    let series = |k: usize| {
        bins.iter()
            .map(|b| (b.centre * x_scale, b.rms_m[k] * 1e12))
            .collect()
    };
    let x_range: Vec<f64> = bins.iter().map(|b| b.centre * x_scale).collect();
    let (x0, x1) = (
        x_range.iter().copied().fold(f64::INFINITY, f64::min),
        x_range.iter().copied().fold(f64::NEG_INFINITY, f64::max),
    );
    Plot::new(title, x_label, "rms residual (pm)")
        .with(Series::new("x", series(0), Style::Line, BLUE))
        .with(Series::new("y", series(1), Style::Line, ORANGE))
        .with(Series::new(
            "noise floor x",
            vec![(x0, noise[0] * 1e12), (x1, noise[0] * 1e12)],
            Style::Line,
            GREEN,
        ))
        .with(Series::new(
            "noise floor y",
            vec![(x0, noise[1] * 1e12), (x1, noise[1] * 1e12)],
            Style::Line,
            VERMILION,
        ))
}

fn floor_source(source: FloorSource) -> &'static str {
    match source {
        FloorSource::Localisation => "localisation uncertainty of the feature fits",
        FloorSource::LocalisationRaisedToSuccessive => {
            "localisation, raised to the successive differences"
        }
        FloorSource::SuccessiveDifferences => "successive differences",
        FloorSource::ResidualSpread => "residual spread: no independent floor",
    }
}

/// The figures and the HTML section of a diagnosis.
pub fn diagnosis_section(
    report: &DiagnosisReport,
    geometry: &ScanGeometry,
) -> (String, Vec<Figure>) {
    let mut figures = Vec::new();
    let noise = report.noise.sigma_m;
    if let Some(location) = &report.location {
        figures.push(Figure::svg(
            "diagnosis_frame_time",
            "Gap against frame time (slow axis)",
            "RMS of measured − predicted feature positions of the base model, binned by \
             acquisition time, against the independent noise floor."
                .into(),
            &bin_plot(
                "Gap vs frame time",
                "time since frame start (s)",
                &location.by_frame_time,
                1.0,
                noise,
            ),
        ));
        figures.push(Figure::svg(
            "diagnosis_fast_phase",
            "Gap against time since line start (fast phase)",
            "The same residuals binned by their fast phase: the time since the start of their \
             scan line as a fraction τ/T of the line scan time (0 = line start, 1 = line end)."
                .into(),
            &bin_plot(
                "Gap vs fast phase",
                "fast phase τ/T (time since line start / line scan time)",
                &location.by_fast_phase,
                1.0,
                noise,
            ),
        ));
        let spectrum = &location.spectrum;
        let mut plot = Plot::new(
            "Residual spectrum (Lomb–Scargle)",
            "frequency (Hz)",
            "power",
        )
        .with(Series::new(
            "power",
            spectrum
                .frequency_hz
                .iter()
                .zip(&spectrum.power)
                .map(|(f, p)| (*f, *p))
                .collect(),
            Style::Line,
            BLUE,
        ));
        plot.vertical_lines = spectrum.peaks.iter().map(|p| p.frequency_hz).collect();
        figures.push(Figure::svg(
            "diagnosis_spectrum",
            "Spectrum of the residuals against time",
            format!(
                "Periodic signals in the base-model residuals; grey lines: significant peaks ({}).",
                if spectrum.peaks.is_empty() {
                    "none".to_string()
                } else {
                    spectrum
                        .peaks
                        .iter()
                        .map(|p| {
                            format!(
                                "{:.3} Hz, false-alarm p {:.1e}",
                                p.frequency_hz, p.false_alarm_probability
                            )
                        })
                        .collect::<Vec<_>>()
                        .join("; ")
                }
            ),
            &plot,
        ));
    }
    // Residuals against time before and after the added effects.
    let before: Vec<(f64, f64)> = report
        .residuals
        .iter()
        .filter(|r| !r.outlier)
        .map(|r| (r.time_s, r.base_m[0].hypot(r.base_m[1]) * 1e12))
        .collect();
    let after: Vec<(f64, f64)> = report
        .residuals
        .iter()
        .filter(|r| !r.outlier)
        .map(|r| (r.time_s, r.final_m[0].hypot(r.final_m[1]) * 1e12))
        .collect();
    let mut plot = Plot::new(
        "Residual magnitude vs time",
        "time since frame start (s)",
        "|residual| (pm)",
    )
    .with(Series::new(
        "base model",
        thin(before, 3000),
        Style::Points,
        BLUE,
    ));
    if !report.added.is_empty() {
        plot = plot.with(Series::new(
            "with added effects",
            thin(after, 3000),
            Style::Points,
            ORANGE,
        ));
    }
    figures.push(Figure::svg(
        "diagnosis_residuals_time",
        "Residuals against time, before and after",
        "Distance of each feature from its predicted position: base model (blue) and with the \
         identified effects added (orange)."
            .into(),
        &plot,
    ));
    // Residual map.
    let scale = crate::correct::render::upscale_for(geometry.rows(), geometry.columns(), 512);
    let blank = Array2::<f64>::zeros((geometry.rows(), geometry.columns()));
    let mut canvas = Canvas::from_image(blank.view(), Colormap::Greys, Some((-1.0, 1.0)), scale);
    let magnitudes: Vec<f64> = report
        .residuals
        .iter()
        .map(|r| r.base_m[0].hypot(r.base_m[1]))
        .collect();
    let mut sorted = magnitudes.clone();
    sorted.sort_by(f64::total_cmp);
    let top = sorted
        .get((sorted.len() as f64 * 0.99) as usize)
        .copied()
        .unwrap_or(1e-12)
        .max(1e-15);
    for (r, m) in report.residuals.iter().zip(&magnitudes) {
        let centre = [
            (r.controller_m[0] / geometry.pitch_x() + 0.5) * scale as f64,
            (r.controller_m[1] / geometry.pitch_y() + 0.5) * scale as f64,
        ];
        canvas.disc(centre, 1.5 * scale as f64, heat_colour(m / top));
    }
    figures.push(Figure {
        stem: "diagnosis_map".into(),
        title: "Where the gap lies (map)".into(),
        caption: format!(
            "Each feature at its raw position, coloured by its base-model residual: black 0 → \
             yellow {:.1} pm (99th percentile).",
            top * 1e12
        ),
        content: FigureContent::Png(canvas.png(), canvas.preview(1100).map(|p| p.png())),
    });

    let mut html = String::from("<h2>Sim-to-real gap diagnosis</h2>\n");
    let v = &report.verdict_details;
    let _ = writeln!(
        html,
        "<p class='verdict'><b>Verdict: {}.</b> {}</p>",
        html_escape(report.verdict.name()),
        html_escape(&v.summary)
    );
    if !v.remaining.is_empty() {
        html.push_str("<p>Where the remaining gap lies:</p><table>\n");
        header(
            &mut html,
            &["where", "features", "gap / floor", "share of the excess"],
        );
        for p in &v.remaining {
            row(
                &mut html,
                &[
                    p.label.clone(),
                    p.count.to_string(),
                    format!("{:.2}", p.gap_to_noise),
                    format!("{:.0} %", 100.0 * p.share),
                ],
            );
        }
        html.push_str("</table>\n");
    }
    html.push_str("<table>\n");
    header(&mut html, &["", "x", "y", "gap / noise", "χ²/dof"]);
    let n = &report.noise;
    row(
        &mut html,
        &[
            format!("noise floor ({})", floor_source(n.source)),
            format!("{:.2} pm", n.sigma_m[0] * 1e12),
            format!("{:.2} pm", n.sigma_m[1] * 1e12),
            "1".into(),
            "—".into(),
        ],
    );
    for (name, estimate) in [
        ("localisation (feature fits)", &n.localisation),
        ("successive differences", &n.successive_differences),
        ("trace/retrace pairs (not used)", &n.trace_retrace),
    ] {
        let (x, y) = match estimate {
            FloorEstimate::Estimated { sigma_m, .. } => (
                format!("{:.2} pm", sigma_m[0] * 1e12),
                format!("{:.2} pm", sigma_m[1] * 1e12),
            ),
            FloorEstimate::Unavailable { reason } => (format!("— ({reason})"), "—".into()),
        };
        row(&mut html, &[name.into(), x, y, "".into(), "".into()]);
    }
    for (name, gap) in [
        ("DHCT fit (local distortions)", &report.dhct),
        ("base model (position fit)", &report.base.gap),
        ("with identified effects", &report.final_model.gap),
    ] {
        row(
            &mut html,
            &[
                name.into(),
                format!("{:.2} pm", gap.rms_m[0] * 1e12),
                format!("{:.2} pm", gap.rms_m[1] * 1e12),
                format!("{:.2}", gap.gap_to_noise),
                format!("{:.2}", gap.chi2_per_dof),
            ],
        );
    }
    html.push_str("</table>\n");
    let _ = writeln!(
        html,
        "<p>Gap/noise {:.2} → {} → {:.2} after the greedy set.</p>",
        report.shrink.before,
        report
            .shrink
            .after_top
            .map(|v| format!("{v:.2} after the top effect"))
            .unwrap_or_else(|| "—".into()),
        report.shrink.after_greedy
    );
    if let Some(round) = report.rounds.first() {
        html.push_str("<p>Candidates of the first round (ΔBIC, ΔAIC < 0 and cross-validation ratio < 1 are improvements):</p><table>\n");
        header(
            &mut html,
            &[
                "candidate",
                "shape",
                "added parameters",
                "Δχ²",
                "ΔBIC",
                "ΔAIC",
                "CV ratio",
                "passes",
            ],
        );
        let mut scores = round.scores.clone();
        scores.sort_by(|a, b| a.delta_bic.total_cmp(&b.delta_bic));
        for s in &scores {
            row(
                &mut html,
                &[
                    s.candidate.to_string(),
                    s.shape.clone(),
                    s.added_parameters.to_string(),
                    format!("{:.1}", s.delta_chi2),
                    format!("{:.1}", s.delta_bic),
                    format!("{:.1}", s.delta_aic),
                    format!("{:.3}", s.cv_ratio),
                    if s.passes { "yes".into() } else { "no".into() },
                ],
            );
        }
        html.push_str("</table>\n");
    }
    for added in &report.added {
        let _ = writeln!(
            html,
            "<p>Added <b>{}</b> ({}):</p><table>",
            html_escape(&added.candidate.to_string()),
            html_escape(&added.shape)
        );
        header(&mut html, &["parameter", "value", "1σ"]);
        for p in &added.parameters {
            row(
                &mut html,
                &[
                    p.name.clone(),
                    format!("{:.4e}", p.value),
                    p.sigma
                        .map(|s| format!("{s:.2e}"))
                        .unwrap_or_else(|| "fixed".into()),
                ],
            );
        }
        html.push_str("</table>\n");
    }
    if let Some(location) = &report.location
        && !location.hot_spots.is_empty()
    {
        html.push_str("<p>Where the gap concentrates (bins with the largest excess over the noise):</p><table>\n");
        header(
            &mut html,
            &["bin", "features", "rms x", "rms y", "excess z"],
        );
        for b in &location.hot_spots {
            row(
                &mut html,
                &[
                    b.label.clone(),
                    b.count.to_string(),
                    format!("{:.2} pm", b.rms_m[0] * 1e12),
                    format!("{:.2} pm", b.rms_m[1] * 1e12),
                    format!("{:.1}", b.excess_z),
                ],
            );
        }
        html.push_str("</table>\n");
    }
    html.push_str("<div class='grid'>\n");
    for f in &figures {
        figure_html(&mut html, f);
    }
    html.push_str("</div>\n");
    (html, figures)
}

/// `dhct diagnose INPUT [RETRACE] -o OUTDIR`.
pub fn run_file(
    input: &Path,
    retrace: Option<&Path>,
    output: &Path,
    config: CorrectConfig,
    json: bool,
) -> Result<()> {
    // Written into a staging folder, moved into place at the end (see `output_dir`).
    let target = output;
    let staged = StagedOutput::prepare(target, config.overwrite)?;
    let output = staged.path();
    let pair = correct::read_pair(input, retrace, &config.geometry, config.channel.as_deref())?;
    let geometry = pair.geometry().clone();
    let mask = correct::load_mask(&config, &geometry)?;
    let correct::Resolved {
        lattice, options, ..
    } = correct::with_measured_nn(correct::resolve(&config)?, &pair, mask.as_ref())?;
    let sets = find_features_in_pair(&pair, &options.features).context("feature finding")?;
    let refs: Vec<&[Feature]> = sets.iter().map(|s| s.features.as_slice()).collect();
    let report = diagnose_features(&refs, &geometry, lattice.as_ref(), mask.as_ref(), &options)?;
    correct::write_bytes(&output.join("diagnosis.json"), report.to_json().as_bytes())?;
    let (section, figures) = diagnosis_section(&report, &geometry);
    correct::write_figure_files(output, &figures)?;
    let page = format!(
        "<!DOCTYPE html>\n<html lang='en'><head><meta charset='utf-8'><title>dhct diagnosis: {}</title><style>{STYLE}</style></head><body><h1>DHCT sim-to-real gap</h1><p class='sub'>{} · lattice {}</p>{section}</body></html>\n",
        html_escape(&input.display().to_string()),
        html_escape(&input.display().to_string()),
        html_escape(lattice.name())
    );
    correct::write_bytes(&output.join("diagnosis.html"), page.as_bytes())?;
    staged.commit()?;
    if json {
        write_stdout(&format!("{}\n", report.to_json()))
    } else {
        write_stdout(&format!(
            "{report}report: {}\n",
            target.join("diagnosis.html").display()
        ))
    }
}

/// `dhct diagnose --validate`: the withheld-effect validation.
pub fn run_validation(seeds: Option<usize>, output: Option<&Path>, json: bool) -> Result<()> {
    let mut options = ValidationOptions::default();
    if let Some(n) = seeds {
        options.truncate_seeds(n);
    }
    let report = validate(&options);
    if let Some(dir) = output {
        let staged = StagedOutput::prepare(dir, false)?;
        let text = serde_json::to_string_pretty(&report)?;
        correct::write_bytes(&staged.path().join("validation.json"), text.as_bytes())?;
        staged.commit()?;
    }
    if json {
        write_stdout(&format!("{}\n", serde_json::to_string_pretty(&report)?))?;
    } else {
        write_stdout(&report.to_string())?;
    }
    if !report.accepted() {
        anyhow::bail!("the validation missed its acceptance targets (see the table above)");
    }
    Ok(())
}
