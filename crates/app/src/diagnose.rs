//! `dhct diagnose`: where the fitted DHCT model and the image disagree, which unmodelled
//! effect explains it and how far the gap shrinks (dhct-diagnose). The same section is added to `dhct correct --diagnose`'s
//! report.

use std::io::Write as _;
use std::path::Path;

use anyhow::{Context, Result};
use dhct_diagnose::{
    Bin, DiagnoseOptions, DiagnosisReport, FloorEstimate, GapLocation, ResidualImage, VerdictKind,
    diagnose_with_model, pair_views,
};
use dhct_distortion::PassInput;
use dhct_features::FeatureSet;
use dhct_scan::ScanGeometry;
use dhct_sm4_io::png_file::Colormap;
use ndarray::Array2;

use crate::analysis::analyse_file;
use crate::output_dir::StagedOutput;
use crate::report::bars::ColourBar;
use crate::report::figures::{Figure, PictureStyle, metres_per_picture_px};
use crate::report::html::figure_grid;
use crate::report::page::{Html, document};
use crate::report::plots::{BLUE, ORANGE, Plot, Series, Style, thin};
use crate::report::render::{Canvas, heat_colour, upscale_for};
use crate::report::{write_bytes, write_figure_files};
use crate::setup::CorrectConfig;

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

/// The diagnosis of a `dhct correct` run: on its features, options and mask, starting from
/// the correction the run made (its drift model, or the affine map it chose) without
/// refitting it, with what only the images show (what `correct --diagnose` and `dhct
/// diagnose` write as diagnosis.json), and the residual images.
pub fn diagnosis_of(
    corrected: &crate::analysis::Corrected,
) -> Result<(DiagnosisReport, Vec<ResidualImage>)> {
    let passes = &corrected.analysis.passes;
    let inputs: Vec<PassInput> = passes
        .iter()
        .map(|p| PassInput {
            features: p.features.features.as_slice(),
            mask: corrected.mask.as_ref(),
        })
        .collect();
    let report = diagnose_with_model(
        &inputs,
        corrected.pair.geometry(),
        corrected.lattice.as_ref(),
        &corrected.analysis.dhct.model,
        &corrected.options.lattice_fit,
        &DiagnoseOptions::default(),
    )
    .context("diagnosis")?;
    let feature_sets: Vec<&FeatureSet> = passes.iter().map(|p| &p.features).collect();
    Ok(pair_views(
        report,
        &corrected.pair,
        &feature_sets,
        &corrected.options.features,
        corrected.mask.as_ref(),
    ))
}

fn bin_plot(title: &str, x_label: &str, bins: &[Bin], noise: [f64; 2]) -> Plot {
    let series = |k: usize| bins.iter().map(|b| (b.centre, b.rms_m[k] * 1e12)).collect();
    let (x0, x1) = bins
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), bin| {
            (a.min(bin.centre), b.max(bin.centre))
        });
    let floor = |k: usize| vec![(x0, noise[k] * 1e12), (x1, noise[k] * 1e12)];
    Plot::new(title, x_label, "rms residual (pm)")
        .with(Series::new("x", series(0), Style::Line, BLUE))
        .with(Series::new("y", series(1), Style::Line, ORANGE))
        .with(Series::new("noise floor x", floor(0), Style::Dashed, BLUE))
        .with(Series::new(
            "noise floor y",
            floor(1),
            Style::Dashed,
            ORANGE,
        ))
}

/// The gap binned by frame time and by fast phase, and the residual spectrum.
fn location_figures(location: &GapLocation, noise: [f64; 2]) -> Vec<Figure> {
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
    let peaks: Vec<String> = spectrum
        .peaks
        .iter()
        .map(|p| {
            format!(
                "{:.3} Hz, false-alarm p {:.1e}",
                p.frequency_hz, p.false_alarm_probability
            )
        })
        .collect();
    vec![
        Figure::plot(
            "diagnosis_frame_time",
            "Gap against frame time (slow axis)",
            "RMS of measured − predicted feature positions of the base model, binned by \
             acquisition time, against the independent noise floor (dashed)."
                .into(),
            &bin_plot(
                "Gap vs frame time",
                "time since frame start (s)",
                &location.by_frame_time,
                noise,
            ),
        ),
        Figure::plot(
            "diagnosis_fast_phase",
            "Gap against time since line start (fast phase)",
            "The same residuals binned by their fast phase: the time since the start of their \
             scan line as a fraction τ/T of the line scan time (0 = line start, 1 = line end)."
                .into(),
            &bin_plot(
                "Gap vs fast phase",
                "fast phase τ/T (time since line start / line scan time)",
                &location.by_fast_phase,
                noise,
            ),
        ),
        Figure::plot(
            "diagnosis_spectrum",
            "Spectrum of the residuals against time",
            format!(
                "Periodic signals in the base-model residuals; grey lines: significant peaks ({}).",
                if peaks.is_empty() {
                    "none".to_string()
                } else {
                    peaks.join("; ")
                }
            ),
            &plot,
        ),
    ]
}

/// Residual magnitudes against time before and after the added effects.
fn residual_time_figure(report: &DiagnosisReport) -> Figure {
    let magnitudes = |f: &dyn Fn(&dhct_diagnose::FeatureResidual) -> [f64; 2]| -> Vec<(f64, f64)> {
        report
            .residuals
            .iter()
            .filter(|r| !r.outlier)
            .map(|r| {
                let d = f(r);
                (r.time_s, d[0].hypot(d[1]) * 1e12)
            })
            .collect()
    };
    let mut plot = Plot::new(
        "Residual magnitude vs time",
        "time since frame start (s)",
        "|residual| (pm)",
    )
    .with(Series::new(
        "base model",
        thin(magnitudes(&|r| r.base_m), 3000),
        Style::Points,
        BLUE,
    ));
    if !report.added.is_empty() {
        plot = plot.with(Series::new(
            "with added effects",
            thin(magnitudes(&|r| r.final_m), 3000),
            Style::Points,
            ORANGE,
        ));
    }
    Figure::plot(
        "diagnosis_residuals_time",
        "Residuals against time, before and after",
        "Distance of each feature from its predicted position: base model (blue) and with the \
         identified effects added (orange)."
            .into(),
        &plot,
    )
}

/// Each feature at its raw position coloured by its base-model residual.
fn residual_map_figure(report: &DiagnosisReport, geometry: &ScanGeometry) -> Figure {
    let scale = upscale_for(geometry.rows(), geometry.columns(), 512);
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
    Figure::picture(
        "diagnosis_map",
        "Where the gap lies (map)",
        format!(
            "Each feature at its raw position, coloured by its base-model residual (colour \
             bar; values above the 99th percentile, {:.1} pm, saturate).",
            top * 1e12
        ),
        &canvas,
        PictureStyle {
            metres_per_px: metres_per_picture_px(geometry, scale),
            colour: Some(ColourBar {
                colormap: Colormap::Inferno,
                low: 0.0,
                high: top,
                unit: "m".into(),
                label: "|residual|".into(),
            }),
            max_side: None,
        },
    )
}

/// One pass's residual image, grey over ±4 × its pixel noise.
fn residual_image_figure(r: &ResidualImage, geometry: &ScanGeometry) -> Figure {
    let scale = upscale_for(geometry.rows(), geometry.columns(), 512);
    let noise = r.summary.pixel_noise;
    let span = if noise.is_finite() && noise > 0.0 {
        4.0 * noise
    } else {
        1.0
    };
    let canvas = Canvas::from_image(
        r.residual.view(),
        Colormap::Greys,
        Some((-span, span)),
        scale,
    );
    Figure::picture(
        &format!("diagnosis_residual_image_{}", r.pass),
        &format!("The image minus the rendered model ({})", r.pass),
        format!(
            "The {} image minus the final model (the atom as the image shows it, placed where the \
             base fit and the named effects predict every feature), each line's median removed; \
             grey from −4 to +4 × the pixel noise. {}.",
            r.pass,
            r.summary.describe()
        ),
        &canvas,
        PictureStyle {
            metres_per_px: metres_per_picture_px(geometry, scale),
            colour: Some(ColourBar {
                colormap: Colormap::Greys,
                low: -span,
                high: span,
                unit: r.summary.z_unit.clone(),
                label: "image − model".into(),
            }),
            max_side: None,
        },
    )
}

/// The residual images' rms over their pixel noise against the fast phase.
fn residual_phase_figure(residuals: &[ResidualImage]) -> Figure {
    let bins = dhct_diagnose::FAST_PHASE_BINS as f64;
    let mut plot = Plot::new(
        "Image residual vs fast phase",
        "fast phase τ/T (time since line start / line scan time)",
        "rms / pixel noise",
    );
    for (r, colour) in residuals.iter().zip([BLUE, ORANGE]) {
        let points = r
            .summary
            .by_fast_phase
            .iter()
            .enumerate()
            .filter_map(|(k, v)| Some(((k as f64 + 0.5) / bins, (*v)?)))
            .collect();
        plot = plot.with(Series::new(r.pass.to_string(), points, Style::Line, colour));
    }
    Figure::plot(
        "diagnosis_residual_fast_phase",
        "Image residual against the fast phase",
        "RMS of the image minus the rendered model over the pixel noise (1 = the model explains \
         every pixel), binned by the time since line start."
            .into(),
        &plot,
    )
}

/// Each residual image as a float TIFF with the scan's pixel size
/// (`residual_trace.tiff`, `residual_retrace.tiff`).
pub fn write_residual_images(
    dir: &Path,
    residuals: &[ResidualImage],
    geometry: &ScanGeometry,
) -> Result<()> {
    for r in residuals {
        let channel = dhct_scan::ImageChannel::new(
            "image minus the rendered model",
            r.summary.z_unit.clone(),
            r.residual.clone(),
        );
        let mut bytes = Vec::new();
        dhct_sm4_io::tiff_file::write_f32_with_pixel_size(
            &channel,
            [geometry.pitch_x(), geometry.pitch_y()],
            &mut bytes,
        )?;
        write_bytes(&dir.join(format!("residual_{}.tiff", r.pass)), &bytes)?;
    }
    Ok(())
}

/// The verdict and where the remaining gap lies.
fn verdict_html(html: &mut Html, report: &DiagnosisReport) {
    let v = &report.verdict_details;
    html.open("p", &[("class", "verdict")])
        .element("b", &format!("Verdict: {}.", verdict_words(report.verdict)))
        .text(" ")
        .text(&v.summary)
        .close("p");
    if let Some(view) = report.sub_feature.as_ref().filter(|v| !v.vibration_found) {
        // A vibration found is already in the verdict's words.
        html.element("p", &format!("Image view: {}.", view.describe()));
    }
    if !v.remaining.is_empty() {
        let rows: Vec<Vec<String>> = v
            .remaining
            .iter()
            .map(|p| {
                vec![
                    p.label.clone(),
                    p.count.to_string(),
                    format!("{:.2}", p.gap_to_noise),
                    format!("{:.0} %", 100.0 * p.share),
                ]
            })
            .collect();
        html.element("p", "Where the remaining gap lies:").table(
            &["where", "features", "gap / floor", "share of the excess"],
            &rows,
        );
    }
}

/// The verdict in words.
fn verdict_words(verdict: VerdictKind) -> &'static str {
    match verdict {
        VerdictKind::NoGap => "no gap beyond the noise",
        VerdictKind::Explained => "the gap is explained",
        VerdictKind::PartlyExplained => "the gap is partly explained",
        VerdictKind::Unexplained => "the gap is not explained",
    }
}

/// The noise floor estimates and the gap of each model.
fn noise_and_gap_html(html: &mut Html, report: &DiagnosisReport) {
    let n = &report.noise;
    let pm = |v: f64| format!("{:.2} pm", v * 1e12);
    let mut rows = vec![vec![
        format!("noise floor ({})", n.source.describe()),
        pm(n.sigma_m[0]),
        pm(n.sigma_m[1]),
        "1".into(),
        "—".into(),
    ]];
    for (name, estimate) in [
        ("localisation (feature fits)", &n.localisation),
        ("successive differences", &n.successive_differences),
        (
            "trace/retrace pairs (an upper bound only)",
            &n.trace_retrace,
        ),
    ] {
        let (x, y) = match estimate {
            FloorEstimate::Estimated { sigma_m, .. } => (pm(sigma_m[0]), pm(sigma_m[1])),
            FloorEstimate::Unavailable { reason } => (format!("— ({reason})"), "—".into()),
        };
        rows.push(vec![name.into(), x, y, String::new(), String::new()]);
    }
    for (name, gap) in [
        ("DHCT fit (local distortions)", &report.dhct),
        ("base model (position fit)", &report.base.gap),
        ("with identified effects", &report.final_model.gap),
    ] {
        rows.push(vec![
            name.into(),
            pm(gap.rms_m[0]),
            pm(gap.rms_m[1]),
            format!("{:.2}", gap.gap_to_noise),
            format!("{:.2}", gap.chi2_per_dof),
        ]);
    }
    html.table(&["", "x", "y", "gap / noise", "χ²/dof"], &rows);
    html.element(
        "p",
        &format!(
            "Gap/noise {:.2} → {} → {:.2} after the greedy set.",
            report.shrink.before,
            report
                .shrink
                .after_top
                .map(|v| format!("{v:.2} after the top effect"))
                .unwrap_or_else(|| "—".into()),
            report.shrink.after_greedy
        ),
    );
}

/// The candidates of the first round and the parameters of every added effect.
fn candidates_html(html: &mut Html, report: &DiagnosisReport) {
    if let Some(round) = report.rounds.first() {
        let mut scores = round.scores.clone();
        scores.sort_by(|a, b| a.delta_bic.total_cmp(&b.delta_bic));
        let rows: Vec<Vec<String>> = scores
            .iter()
            .map(|s| {
                vec![
                    s.candidate.to_string(),
                    s.shape.clone(),
                    s.added_parameters.to_string(),
                    format!("{:.1}", s.delta_chi2),
                    format!("{:.1}", s.delta_bic),
                    format!("{:.1}", s.delta_aic),
                    format!("{:.3}", s.cv_ratio),
                    if s.passes { "yes" } else { "no" }.into(),
                ]
            })
            .collect();
        html.element(
            "p",
            "Candidates of the first round (ΔBIC, ΔAIC < 0 and cross-validation ratio < 1 are improvements):",
        )
        .table(
            &["candidate", "shape", "added parameters", "Δχ²", "ΔBIC", "ΔAIC", "CV ratio", "passes"],
            &rows,
        );
    }
    for added in &report.added {
        let rows: Vec<Vec<String>> = added
            .parameters
            .iter()
            .map(|p| {
                vec![
                    p.name.clone(),
                    format!("{:.4e}", p.value),
                    p.sigma
                        .map(|s| format!("{s:.2e}"))
                        .unwrap_or_else(|| "fixed".into()),
                ]
            })
            .collect();
        html.open("p", &[])
            .text("Added ")
            .element("b", &added.candidate.to_string())
            .text(&format!(" ({}):", added.shape))
            .close("p")
            .table(&["parameter", "value", "1σ"], &rows);
    }
}

/// The bins where the gap concentrates.
fn hot_spots_html(html: &mut Html, report: &DiagnosisReport) {
    let Some(location) = report.location.as_ref().filter(|l| !l.hot_spots.is_empty()) else {
        return;
    };
    let rows: Vec<Vec<String>> = location
        .hot_spots
        .iter()
        .map(|b| {
            vec![
                b.label.clone(),
                b.count.to_string(),
                format!("{:.2} pm", b.rms_m[0] * 1e12),
                format!("{:.2} pm", b.rms_m[1] * 1e12),
                format!("{:.1}", b.excess_z),
            ]
        })
        .collect();
    html.element(
        "p",
        "Where the gap concentrates (bins with the largest excess over the noise):",
    )
    .table(&["bin", "features", "rms x", "rms y", "excess z"], &rows);
}

/// The figures and the HTML section of a diagnosis with its residual images.
pub fn diagnosis_section(
    report: &DiagnosisReport,
    residuals: &[ResidualImage],
    geometry: &ScanGeometry,
) -> (Html, Vec<Figure>) {
    let mut figures = report
        .location
        .as_ref()
        .map(|l| location_figures(l, report.noise.sigma_m))
        .unwrap_or_default();
    figures.push(residual_time_figure(report));
    figures.push(residual_map_figure(report, geometry));
    figures.extend(residuals.iter().map(|r| residual_image_figure(r, geometry)));
    if !residuals.is_empty() {
        figures.push(residual_phase_figure(residuals));
    }
    let mut html = Html::new();
    html.element("h2", "Sim-to-real gap diagnosis");
    verdict_html(&mut html, report);
    noise_and_gap_html(&mut html, report);
    candidates_html(&mut html, report);
    hot_spots_html(&mut html, report);
    for p in &report.image_residual {
        html.element(
            "p",
            &format!(
                "Image minus the final model rendered with the measured atom, {}.",
                p.describe()
            ),
        );
    }
    figure_grid(&mut html, &figures);
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
    // The same pipeline as `dhct correct` (options, calibration, mask, regions, the
    // correction it keeps), diagnosed from that correction.
    let corrected = analyse_file(input, retrace, config, &|_| {})?;
    let geometry = corrected.pair.geometry();
    let lattice = &corrected.lattice;
    let (report, residuals) = diagnosis_of(&corrected)?;
    write_bytes(&output.join("diagnosis.json"), report.to_json().as_bytes())?;
    write_residual_images(output, &residuals, geometry)?;
    let (section, figures) = diagnosis_section(&report, &residuals, geometry);
    write_figure_files(output, &figures)?;
    let mut body = Html::new();
    body.element("h1", "DHCT sim-to-real gap")
        .element_with(
            "p",
            &[("class", "sub")],
            &format!("{} · lattice {}", input.display(), lattice.name()),
        )
        .append(section);
    let page = document(&format!("dhct diagnosis: {}", input.display()), body);
    write_bytes(&output.join("diagnosis.html"), page.as_bytes())?;
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
