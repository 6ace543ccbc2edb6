//! `report.html`: one self-contained page (pictures embedded in their SVGs, plots as inline
//! SVG, no scripts, no network) that opens with what was measured and what was assumed,
//! then the tables and figures a reader of the DHCT paper expects. Built with the escaping
//! [`Html`] builder.

use dhct_pipeline::{CorrectionSource, WarningCode};
use dhct_scan::{ScanDirection, ValueSource};

use super::figures::Figure;
use super::page::{Html, document};
use super::summary::RunSummary;
use crate::units::{angstrom, degrees, length, picometres, si, si_significant, value_with_sigma};

/// A direction in words.
pub fn direction_words(direction: ScanDirection) -> &'static str {
    match direction {
        ScanDirection::Right => "left to right",
        ScanDirection::Left => "right to left",
        ScanDirection::Down => "top to bottom",
        ScanDirection::Up => "bottom to top",
    }
}

/// A figure with its caption and file names.
pub(crate) fn figure_html(html: &mut Html, figure: &Figure) {
    let files: Vec<String> = figure.files().into_iter().map(|(name, _)| name).collect();
    html.open("figure", &[("id", &figure.stem)])
        .trusted_svg(figure.svg())
        .open("figcaption", &[])
        .element("b", &format!("{}.", figure.title))
        .text(" ")
        .text(&figure.caption)
        .text(" ")
        .element("i", &format!("({})", files.join(", ")))
        .close("figcaption")
        .close("figure");
}

/// A grid of figures.
pub(crate) fn figure_grid(html: &mut Html, figures: &[Figure]) {
    html.open("div", &[("class", "grid")]);
    for figure in figures {
        figure_html(html, figure);
    }
    html.close("div");
}

/// Why the global affine correction was kept: it beat the fitted model, or no model could
/// be fitted.
pub fn affine_reason(summary: &RunSummary) -> &'static str {
    if summary.rejected_model.is_some() {
        "the global affine correction (it beat the drift model)"
    } else {
        "the global affine correction (the drift model could not be fitted)"
    }
}

/// Which correction the corrected data come from, in words.
fn correction_kept(summary: &RunSummary) -> &'static str {
    match summary.correction {
        CorrectionSource::DriftModel => "the drift/creep/hysteresis model",
        CorrectionSource::Affine => affine_reason(summary),
    }
}

/// The opening summary in plain words: what was measured, what was given, what was
/// assumed.
fn summary_section(html: &mut Html, summary: &RunSummary) {
    let mut measured = Vec::new();
    if let Some(found) = &summary.calibration {
        let c = &found.calibration;
        measured.push(format!(
            "The raw lattice in the image, by FFT, against the lattice given: x {:.4}, y {:.4}, \
             shear {} (apparent over true length: the file's pixel-size error and the drift, \
             creep and hysteresis together; the distortion model below separates them).",
            c.scale[0],
            c.scale[1],
            degrees(c.shear_deg, 2)
        ));
    }
    let features: Vec<String> = summary
        .passes
        .iter()
        .map(|p| {
            let outside = if p.outside_frame > 0 {
                format!(
                    "; {} ({:.1} %) lie outside the frame after correction: cropped from the \
                     frame-sized corrected image, kept in features.csv and in full-extent \
                     corrected files",
                    p.outside_frame,
                    100.0 * p.outside_frame as f64 / p.features.max(1) as f64
                )
            } else {
                String::new()
            };
            format!(
                "{} in the {} image ({} indexed{outside})",
                p.features, p.pass, p.indexed
            )
        })
        .collect();
    measured.push(format!("Features: {}.", features.join(", ")));
    for r in &summary.regions {
        measured.push(format!(
            "Region {}: rms deviation from the fitted lattice {}, 1σ ellipse {} × {}.",
            r.region,
            picometres(r.rms_deviation_m),
            picometres(r.whole_ellipse.sigma_major_m),
            picometres(r.whole_ellipse.sigma_minor_m)
        ));
    }
    measured.push(format!("Correction kept: {}.", correction_kept(summary)));
    let given = vec![format!(
        "Lattice {} with nearest-neighbour distance {}.",
        summary.lattice,
        angstrom(summary.nearest_neighbour_distance_m, 3)
    )];
    let assumed = assumptions(summary);
    html.open("div", &[("class", "summary"), ("id", "summary")])
        .element("h2", "Summary")
        .element("p", "Measured from the image:")
        .list(&measured)
        .element("p", "Given:")
        .list(&given)
        .element("p", "Assumed (not stated by the file; results that depend on it are only as right as the assumption):")
        .list(&assumed);
    if !summary.warnings.is_empty() {
        html.element(
            "p",
            &format!(
                "{} warning(s) below say what not to trust and what to do.",
                summary.warnings.len()
            ),
        );
    }
    html.close("div");
}

/// The scan geometry's assumed values and the pipeline's assumption warnings, in words.
fn assumptions(summary: &RunSummary) -> Vec<String> {
    let g = &summary.geometry;
    let mut assumed = Vec::new();
    if g.scale_source() == ValueSource::Assumed {
        assumed.push(format!(
            "Pixel size {} × {} (placeholder: lengths and velocities scale with it).",
            length(g.pitch_x()),
            length(g.pitch_y())
        ));
    }
    if g.timing_source() == ValueSource::Assumed {
        assumed.push(format!(
            "Scan timing: {} per pixel, line period {}, frame {} (placeholder: drift \
             velocities and creep times scale with it).",
            si(g.pixel_period(), "s"),
            si(g.line_period(), "s"),
            si(g.frame_duration(), "s")
        ));
    }
    for w in &summary.warnings {
        if matches!(
            w.code,
            WarningCode::AssumedTiming | WarningCode::AssumedPixelSize
        ) {
            assumed.push(w.message.clone());
        }
    }
    if assumed.is_empty() {
        assumed.push("Nothing: pixel size and scan timing are stated by the file.".into());
    }
    assumed
}

/// The pipeline's warnings, each with what to do (the stable code as a tooltip).
fn warnings_section(html: &mut Html, summary: &RunSummary) {
    for w in &summary.warnings {
        html.open("p", &[("class", "note"), ("title", w.code.name())])
            .element("b", "Warning:")
            .text(" ")
            .text(&w.message)
            .open("br", &[])
            .element("b", "What to do:")
            .text(" ")
            .text(&w.what_to_do);
        if !w.inputs.is_empty() {
            let flags: Vec<&str> = w.inputs.iter().map(|i| crate::flags::flag(*i)).collect();
            html.text(&format!(" (options: {})", flags.join(", ")));
        }
        html.close("p");
    }
}

/// What the image shows, the calibration from it, and the affine floor.
fn calibration_section(html: &mut Html, summary: &RunSummary) {
    html.element("h2", "Calibration from the lattice");
    let Some(found) = &summary.calibration else {
        html.element(
            "p",
            &format!(
                "The lattice could not be measured from the image ({}); the file's pixel size \
                 was taken as right and the inputs were not checked.",
                summary
                    .calibration_note
                    .as_deref()
                    .unwrap_or("no reason given")
            ),
        );
        return;
    };
    html.element(
        "p",
        "Measured from the Fourier transform of each raw image before anything else, in the \
         file's units: the raw lattice against the lattice named, as apparent over true \
         lengths. These numbers hold the file's pixel-size error and the distortion by drift, \
         creep and hysteresis together; the model below separates them, and the corrected \
         images' check shows what is left. 1, 1 and 0° mean the raw image already has the \
         lattice's size and shape. A pixel-size error along the slow axis and a constant \
         slow drift look the same in one frame.",
    );
    let mut rows: Vec<(String, String)> = found
        .passes
        .iter()
        .flat_map(|p| {
            [
                (format!("{} shows", p.pass), p.lattice.describe()),
                (format!("{} explained", p.pass), p.matched.explanation()),
            ]
        })
        .collect();
    let c = &found.calibration;
    rows.extend([
        (
            "x scale".into(),
            format!("{:.4} ± {:.4}", c.scale[0], c.scale_sigma[0]),
        ),
        (
            "y scale".into(),
            format!("{:.4} ± {:.4}", c.scale[1], c.scale_sigma[1]),
        ),
        (
            "shear".into(),
            format!(
                "{} ± {}",
                degrees(c.shear_deg, 2),
                degrees(c.shear_sigma_deg, 2)
            ),
        ),
        (
            "lattice rotation".into(),
            format!(
                "{} (modulo the lattice's {})",
                degrees(
                    super::summary::within_period(c.rotation_deg, summary.rotation_period_deg),
                    2
                ),
                degrees(summary.rotation_period_deg, 0)
            ),
        ),
    ]);
    for a in &summary.affine_baseline {
        rows.push((
            format!("region {}: rms from the lattice", a.region),
            format!(
                "{} (drift model, {} features) vs {} (global affine, {})",
                picometres(a.model_rms_m),
                a.model_used,
                picometres(a.affine_rms_m),
                a.affine_used
            ),
        ));
    }
    if let Some(routes) = &summary.model_routes {
        rows.push(("model: local vs global route".into(), routes.describe()));
    }
    if let Some(note) = &summary.model_route_note {
        rows.push(("model: how it was found".into(), note.clone()));
    }
    for check in &summary.corrected_images {
        let k = &check.calibration;
        rows.push((
            format!("corrected {}: its lattice by FFT", check.pass),
            format!(
                "{:.4} × {:.4} of the lattice given along x × y, shear {}{}",
                k.scale[0],
                k.scale[1],
                degrees(k.shear_deg, 2),
                if check.passes() {
                    ""
                } else {
                    " (off: see the warning)"
                }
            ),
        ));
    }
    rows.push(("correction kept".into(), correction_kept(summary).into()));
    html.pairs("", &rows);
}

/// Image size, timing (stated or assumed), scan directions and the per-image counts.
fn scan_section(html: &mut Html, summary: &RunSummary) {
    let g = &summary.geometry;
    let source = |s: ValueSource| match s {
        ValueSource::Stated => "stated by the file",
        ValueSource::Assumed => "assumed: the file does not say",
    };
    html.element("h2", "Scan and features").pairs(
        "",
        &[
            (
                "image".into(),
                format!(
                    "{} × {} px, {} × {} ({})",
                    g.columns(),
                    g.rows(),
                    length(g.width()),
                    length(g.height()),
                    source(g.scale_source())
                ),
            ),
            (
                "timing".into(),
                format!(
                    "{} per pixel, line period {}, frame {} ({})",
                    si(g.pixel_period(), "s"),
                    si(g.line_period(), "s"),
                    si(g.frame_duration(), "s"),
                    source(g.timing_source())
                ),
            ),
            (
                "scan".into(),
                format!(
                    "trace lines {}, slow axis {}",
                    direction_words(g.trace_fast()),
                    direction_words(g.slow_direction())
                ),
            ),
        ],
    );
    let rows: Vec<Vec<String>> = summary
        .passes
        .iter()
        .map(|p| {
            vec![
                p.pass.to_string(),
                p.features.to_string(),
                p.candidates.to_string(),
                p.rejected.to_string(),
                if p.neighbours_refined {
                    format!("{} (found in the corrected frame)", p.selected_for_model)
                } else {
                    p.selected_for_model.to_string()
                },
                p.local_distortions.to_string(),
                p.indexed.to_string(),
                angstrom(p.rdf_fit.nn_distance_m, 3),
                angstrom(p.rdf_fit.fwhm_m.first().copied().unwrap_or(f64::NAN), 3),
            ]
        })
        .collect();
    html.table(
        &[
            "image",
            "features",
            "candidates",
            "rejected",
            "with full NN shell",
            "local distortions",
            "indexed",
            "RDF 1st shell",
            "FWHM",
        ],
        &rows,
    );
}

/// The fitted parameters with uncertainties and the goodness of fit.
fn model_section(html: &mut Html, summary: &RunSummary) {
    html.element("h2", "Distortion model").element(
        "p",
        "D(t) = v + a·t + C/(t + t0) for drift and creep, and the fast-scan hysteresis law \
         S(τ), fitted jointly to trace and retrace.",
    );
    let rows: Vec<Vec<String>> = summary
        .parameters
        .iter()
        .map(|p| vec![p.name.clone(), value_with_sigma(p.value, p.sigma, &p.unit)])
        .collect();
    html.table(&["parameter", "value ± 1σ"], &rows);
    if let Some(words) =
        super::summary::hysteresis_words(&summary.model.hysteresis, &summary.geometry)
    {
        html.element("p", &format!("Hysteresis: {words}."));
    }
    let gf = &summary.goodness;
    // Without local measurements (the global registration route) there is nothing to show.
    let or_none = |v: Option<f64>, show: &dyn Fn(f64) -> String| v.map_or("–".into(), show);
    let velocity = |v: f64| si_significant(v, "m/s", 3);
    let drift = |k: usize| {
        format!(
            "{} of {}",
            or_none(gf.rms_drift_residual_m_per_s[k], &velocity),
            or_none(gf.rms_drift_m_per_s[k], &velocity)
        )
    };
    html.table(
        &["goodness of fit", "value"],
        &[
            vec![
                "local measurements".into(),
                gf.local_measurements.to_string(),
            ],
            vec![
                "rms S residual".into(),
                or_none(gf.rms_scale_residual, &|v| format!("{v:.4}")),
            ],
            vec!["rms Dx residual, of rms Dx".into(), drift(0)],
            vec!["rms Dy residual, of rms Dy".into(), drift(1)],
        ],
    );
}

/// One row per region of the lattice fit with its confidence ellipses.
fn lattice_section(html: &mut Html, summary: &RunSummary) {
    let pair = |a: f64, b: f64| format!("{} × {}", picometres(a), picometres(b));
    let rows: Vec<Vec<String>> = summary
        .regions
        .iter()
        .map(|r| {
            let e = &r.whole_ellipse;
            vec![
                r.region.to_string(),
                format!("{} ({} used)", r.features_indexed, r.features_used_in_fit),
                degrees(r.angle_deg, 2),
                angstrom(r.lattice_constant_m[0], 4),
                angstrom(r.lattice_constant_m[1], 4),
                picometres(r.rms_deviation_m),
                r.set_offsets_m
                    .first()
                    .map(|o| format!("({}, {})", picometres(o[0]), picometres(o[1])))
                    .unwrap_or_else(|| "—".into()),
                pair(e.sigma_major_m, e.sigma_minor_m),
                pair(e.two_sigma_major_m, e.two_sigma_minor_m),
                e.sigma_z.map(picometres).unwrap_or_else(|| "—".into()),
                r.local_ellipse
                    .as_ref()
                    .map(|l| pair(l.sigma_major_m, l.sigma_minor_m))
                    .unwrap_or_else(|| "—".into()),
                r.local_cells.to_string(),
            ]
        })
        .collect();
    html.element("h2", "Lattice fit and confidence ellipses")
        .table(
            &[
                "region",
                "features",
                "angle",
                "a along x",
                "a along y",
                "rms dev.",
                "retrace offset",
                "1σ ellipse (whole)",
                "2σ ellipse (whole)",
                "σz",
                "1σ ellipse (local cells)",
                "cells",
            ],
            &rows,
        );
    for s in &summary.skipped_regions {
        html.element_with(
            "p",
            &[("class", "note")],
            &format!(
                "Region {} ({} px, {} features) skipped: {}",
                s.region, s.pixels, s.features, s.reason
            ),
        );
    }
}

/// The averaged cell and the symmetry residuals of every compatible plane group.
fn unit_cell_section(html: &mut Html, summary: &RunSummary) {
    html.element("h2", "Unit cell");
    let Some(c) = &summary.unit_cell else {
        html.element_with(
            "p",
            &[("class", "note")],
            &format!(
                "No unit-cell average: {}",
                summary.unit_cell_note.as_deref().unwrap_or("")
            ),
        );
        return;
    };
    html.element(
        "p",
        &format!(
            "{} of {} local cells averaged; symmetry average in {}. Symmetry residual \
             ‖A − S(A)‖/‖A − ⟨A⟩‖ of the translational average for every plane group \
             compatible with the lattice (smaller = closer to that symmetry):",
            c.cells_selected, c.cells_available, c.group
        ),
    );
    let mut residuals = c.residuals.clone();
    residuals.sort_by(|a, b| a.residual.total_cmp(&b.residual));
    let rows: Vec<Vec<String>> = residuals
        .iter()
        .map(|r| vec![r.group.to_string(), format!("{:.4}", r.residual)])
        .collect();
    html.table(&["plane group", "residual"], &rows);
}

/// Time per stage.
fn timing_section(html: &mut Html, summary: &RunSummary) {
    let t = &summary.timings;
    let rows: Vec<Vec<String>> = [
        ("read", summary.read_s),
        ("features", t.features_s),
        ("neighbours, local distortion, model fit", t.model_s),
        ("correction and resampling", t.correction_s),
        ("lattice fit", t.lattice_fit_s),
        ("unit cells", t.unit_cells_s),
        ("analysis total", t.total_s),
        ("writing outputs", summary.write_s),
    ]
    .into_iter()
    .map(|(name, v)| vec![name.to_string(), format!("{v:.3}")])
    .collect();
    html.element("h2", "Timing")
        .table(&["stage", "seconds"], &rows);
}

/// The whole page; `extra_section` (the diagnosis) goes after the figures.
pub fn report_html(
    summary: &RunSummary,
    figures: &[Figure],
    extra_section: Option<Html>,
) -> String {
    let mut html = Html::new();
    let retrace = summary
        .retrace_input
        .as_ref()
        .map(|r| format!(" + retrace {r}"))
        .unwrap_or_default();
    html.element("h1", "DHCT distortion correction")
        .element_with(
            "p",
            &[("class", "sub")],
            &format!(
                "{}{retrace} · lattice {} (NN {}) · dhct {}",
                summary.input,
                summary.lattice,
                angstrom(summary.nearest_neighbour_distance_m, 3),
                summary.dhct_version
            ),
        );
    summary_section(&mut html, summary);
    warnings_section(&mut html, summary);
    calibration_section(&mut html, summary);
    scan_section(&mut html, summary);
    model_section(&mut html, summary);
    lattice_section(&mut html, summary);
    unit_cell_section(&mut html, summary);
    html.element("h2", "Figures");
    figure_grid(&mut html, figures);
    if let Some(section) = extra_section {
        html.append(section);
    }
    timing_section(&mut html, summary);
    html.element_with(
        "p",
        &[("class", "sub")],
        "Method: Yothers, Browder & Bumm, Rev. Sci. Instrum. 88, 013708 (2017). Every number \
         on this page is in model.json; every feature in features.csv.",
    );
    document(&format!("dhct report: {}", summary.input), html)
}
