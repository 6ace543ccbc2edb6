//! `report.html`: one self-contained page (pictures embedded as data URIs, plots as inline
//! SVG, no scripts, no network) with the tables and figures a reader of the DHCT paper
//! expects.

use std::fmt::Write as _;

use base64::Engine as _;

use super::figures::{Figure, FigureContent};
use super::plots::html_escape;
use super::summary::RunSummary;
use crate::info::si;

pub(crate) const STYLE: &str = "body{font-family:system-ui,-apple-system,'Segoe UI',sans-serif;max-width:1180px;margin:24px auto;padding:0 16px;color:#222}
h1{font-size:1.6em;margin-bottom:0}h2{border-bottom:1px solid #ccc;padding-bottom:4px;margin-top:2em}
.sub{color:#666;margin-top:4px}table{border-collapse:collapse;margin:8px 0 16px}td,th{border:1px solid #ddd;padding:3px 8px;text-align:right;font-variant-numeric:tabular-nums}
th{background:#f4f4f4}td:first-child,th:first-child{text-align:left}.grid{display:grid;grid-template-columns:repeat(auto-fill,minmax(520px,1fr));gap:18px}
figure{margin:0;border:1px solid #e4e4e4;padding:8px;background:#fff}figure img,figure svg{width:100%;height:auto;image-rendering:pixelated}
figcaption{font-size:.88em;color:#444;margin-top:6px}figcaption b{color:#222}.note{background:#fff8e0;border:1px solid #eed;padding:6px 10px}";

pub(crate) fn row(html: &mut String, cells: &[String]) {
    html.push_str("<tr>");
    for c in cells {
        let _ = write!(html, "<td>{}</td>", html_escape(c));
    }
    html.push_str("</tr>\n");
}

pub(crate) fn header(html: &mut String, cells: &[&str]) {
    html.push_str("<tr>");
    for c in cells {
        let _ = write!(html, "<th>{}</th>", html_escape(c));
    }
    html.push_str("</tr>\n");
}

fn pm(metres: f64) -> String {
    format!("{:.1} pm", metres * 1e12)
}

/// A parameter value ± uncertainty: SI prefix for plain units, the value rounded to the
/// uncertainty's second significant digit.
pub fn value_with_sigma(value: f64, sigma: f64, unit: &str) -> String {
    let prefixable = matches!(unit, "m" | "m/s" | "m/s^2" | "s");
    let (scale, unit) = if prefixable && value.is_finite() && value != 0.0 {
        let prefixes = [
            (1e-15, "f"),
            (1e-12, "p"),
            (1e-9, "n"),
            (1e-6, "µ"),
            (1e-3, "m"),
            (1.0, ""),
        ];
        let (scale, prefix) = prefixes
            .iter()
            .rev()
            .find(|(s, _)| value.abs() >= *s)
            .copied()
            .unwrap_or(prefixes[0]);
        (scale, format!("{prefix}{unit}"))
    } else {
        (
            1.0,
            if unit == "1" {
                String::new()
            } else {
                unit.to_string()
            },
        )
    };
    let (v, e) = (value / scale, sigma / scale);
    if !e.is_finite() || e <= 0.0 {
        return format!("{v:.4} {unit} (fixed)").trim().replace("  ", " ");
    }
    let decimals = (1 - e.abs().log10().floor() as i32).clamp(0, 12) as usize;
    format!("{v:.decimals$} ± {e:.decimals$} {unit}")
        .trim()
        .to_string()
}

pub(crate) fn figure_html(html: &mut String, figure: &Figure) {
    html.push_str("<figure>");
    match &figure.content {
        FigureContent::Png(full, preview) => {
            let data =
                base64::engine::general_purpose::STANDARD.encode(preview.as_ref().unwrap_or(full));
            let _ = write!(
                html,
                "<img alt='{}' src='data:image/png;base64,{data}'>",
                html_escape(&figure.title)
            );
        }
        FigureContent::Svg(svg) => {
            // Strip any XML prolog; inline SVG needs only the element.
            let start = svg.find("<svg").unwrap_or(0);
            html.push_str(&svg[start..]);
        }
    }
    let _ = writeln!(
        html,
        "<figcaption><b>{}.</b> {} <i>({})</i></figcaption></figure>",
        html_escape(&figure.title),
        html_escape(&figure.caption),
        html_escape(&figure.file_name())
    );
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

/// What the image shows, the calibration from it, and the affine floor.
fn calibration_section(html: &mut String, summary: &RunSummary) {
    html.push_str("<h2>Calibration from the lattice</h2>");
    let Some(found) = &summary.calibration else {
        let _ = writeln!(
            html,
            "<p>The lattice could not be measured from the image ({}); the file's pixel size \
             was taken as right and the inputs were not checked.</p>",
            html_escape(
                summary
                    .calibration_note
                    .as_deref()
                    .unwrap_or("no reason given")
            )
        );
        return;
    };
    html.push_str(
        "<p>Measured from the Fourier transform of each image before anything else, in the \
         file's units; the scales are apparent over true lengths (1 = the file's pixel size \
         is right). A pixel-size error along the slow axis and a constant slow drift look the \
         same in one frame.</p><table>\n",
    );
    header(html, &["", "value"]);
    for pass in &found.passes {
        row(
            html,
            &[
                format!("{} shows", pass.pass),
                html_escape(&pass.lattice.describe()),
            ],
        );
    }
    let c = &found.calibration;
    let rows = [
        (
            "x scale",
            format!("{:.4} ± {:.4}", c.scale[0], c.scale_sigma[0]),
        ),
        (
            "y scale",
            format!("{:.4} ± {:.4}", c.scale[1], c.scale_sigma[1]),
        ),
        (
            "shear",
            format!("{:.2}° ± {:.2}°", c.shear_deg, c.shear_sigma_deg),
        ),
        ("lattice rotation", format!("{:.2}°", c.rotation_deg)),
    ];
    for (name, value) in rows {
        row(html, &[name.into(), value]);
    }
    for a in &summary.affine_baseline {
        row(
            html,
            &[
                format!("region {}: rms from the lattice", a.region),
                format!(
                    "{:.1} pm (drift model, {} features) vs {:.1} pm (global affine, {})",
                    a.model_rms_m * 1e12,
                    a.model_used,
                    a.affine_rms_m * 1e12,
                    a.affine_used
                ),
            ],
        );
    }
    for check in &summary.corrected_images {
        let k = &check.calibration;
        row(
            html,
            &[
                format!("corrected {}: its lattice by FFT", check.pass),
                format!(
                    "{:.4} × {:.4} of the lattice given along x × y, shear {:.2}°{}",
                    k.scale[0],
                    k.scale[1],
                    k.shear_deg,
                    if check.passes() {
                        ""
                    } else {
                        " (off: see the warning)"
                    }
                ),
            ],
        );
    }
    let kept = match summary.correction {
        dhct_pipeline::CorrectionSource::DriftModel => "the drift/creep/hysteresis model",
        dhct_pipeline::CorrectionSource::Affine => affine_reason(summary),
    };
    row(html, &["correction kept".into(), kept.into()]);
    html.push_str("</table>\n");
}

/// The whole page.
pub fn report_html(
    summary: &RunSummary,
    figures: &[Figure],
    extra_section: Option<&str>,
) -> String {
    let mut html = String::with_capacity(1 << 20);
    let _ = writeln!(
        html,
        "<!DOCTYPE html>\n<html lang='en'><head><meta charset='utf-8'><title>dhct report: {}</title><style>{STYLE}</style></head><body>",
        html_escape(&summary.input)
    );
    let g = &summary.geometry;
    let _ = write!(
        html,
        "<h1>DHCT distortion correction</h1><p class='sub'>{}{} · lattice {} (NN {}) · dhct {}</p>",
        html_escape(&summary.input),
        summary
            .retrace_input
            .as_ref()
            .map(|r| format!(" + retrace {}", html_escape(r)))
            .unwrap_or_default(),
        html_escape(&summary.lattice),
        si(summary.nearest_neighbour_distance_m, "m"),
        summary.dhct_version
    );

    for w in &summary.warnings {
        let _ = writeln!(
            html,
            "<p class='note'><b>Warning ({}):</b> {} <br><b>What to do:</b> {}</p>",
            w.code.name(),
            html_escape(&w.message),
            html_escape(&w.what_to_do)
        );
    }
    calibration_section(&mut html, summary);
    html.push_str("<h2>Scan and features</h2><table>\n");
    header(&mut html, &["", "value"]);
    row(
        &mut html,
        &[
            "image".into(),
            format!(
                "{} × {} px, {} × {}",
                g.columns(),
                g.rows(),
                si(g.width(), "m"),
                si(g.height(), "m")
            ),
        ],
    );
    row(
        &mut html,
        &[
            "timing".into(),
            format!(
                "{} per pixel, line period {}, frame {} ({:?})",
                si(g.pixel_period(), "s"),
                si(g.line_period(), "s"),
                si(g.frame_duration(), "s"),
                g.timing_source()
            ),
        ],
    );
    row(
        &mut html,
        &[
            "scan".into(),
            format!("trace {:?}, slow {:?}", g.trace_fast(), g.slow_direction()),
        ],
    );
    html.push_str("</table><table>\n");
    header(
        &mut html,
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
    );
    for p in &summary.passes {
        row(
            &mut html,
            &[
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
                format!("{:.3} Å", p.rdf_fit.nn_distance_m * 1e10),
                format!(
                    "{:.3} Å",
                    p.rdf_fit.fwhm_m.first().copied().unwrap_or(f64::NAN) * 1e10
                ),
            ],
        );
    }
    html.push_str("</table>\n");

    html.push_str("<h2>Distortion model</h2><p>D(t) = v + a·t + C/(t + t0) for drift and creep, and the fast-scan hysteresis law S(τ), fitted jointly to trace and retrace.</p><table>\n");
    header(&mut html, &["parameter", "value ± 1σ"]);
    for p in &summary.parameters {
        row(
            &mut html,
            &[p.name.clone(), value_with_sigma(p.value, p.sigma, &p.unit)],
        );
    }
    html.push_str("</table><table>\n");
    let gf = &summary.goodness;
    header(&mut html, &["goodness of fit", "value"]);
    row(
        &mut html,
        &[
            "local measurements".into(),
            gf.local_measurements.to_string(),
        ],
    );
    row(
        &mut html,
        &[
            "rms S residual".into(),
            format!("{:.4}", gf.rms_scale_residual),
        ],
    );
    row(
        &mut html,
        &[
            "rms Dx residual (rms Dx)".into(),
            format!(
                "{} ({})",
                si(gf.rms_drift_residual_m_per_s[0], "m/s"),
                si(gf.rms_drift_m_per_s[0], "m/s")
            ),
        ],
    );
    row(
        &mut html,
        &[
            "rms Dy residual (rms Dy)".into(),
            format!(
                "{} ({})",
                si(gf.rms_drift_residual_m_per_s[1], "m/s"),
                si(gf.rms_drift_m_per_s[1], "m/s")
            ),
        ],
    );
    html.push_str("</table>\n");

    html.push_str("<h2>Lattice fit and confidence ellipses</h2><table>\n");
    header(
        &mut html,
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
    );
    for r in &summary.regions {
        let e = &r.whole_ellipse;
        row(
            &mut html,
            &[
                r.region.to_string(),
                format!("{} ({} used)", r.features_indexed, r.features_used_in_fit),
                format!("{:.2}°", r.angle_deg),
                format!("{:.4} Å", r.lattice_constant_m[0] * 1e10),
                format!("{:.4} Å", r.lattice_constant_m[1] * 1e10),
                pm(r.rms_deviation_m),
                r.set_offsets_m
                    .first()
                    .map(|o| format!("({}, {})", pm(o[0]), pm(o[1])))
                    .unwrap_or_else(|| "—".into()),
                format!("{} × {}", pm(e.sigma_major_m), pm(e.sigma_minor_m)),
                format!("{} × {}", pm(e.two_sigma_major_m), pm(e.two_sigma_minor_m)),
                e.sigma_z.map(pm).unwrap_or_else(|| "—".into()),
                r.local_ellipse
                    .as_ref()
                    .map(|l| format!("{} × {}", pm(l.sigma_major_m), pm(l.sigma_minor_m)))
                    .unwrap_or_else(|| "—".into()),
                r.local_cells.to_string(),
            ],
        );
    }
    html.push_str("</table>\n");
    for s in &summary.skipped_regions {
        let _ = writeln!(
            html,
            "<p class='note'>Region {} ({} px, {} features) skipped: {}</p>",
            s.region,
            s.pixels,
            s.features,
            html_escape(&s.reason)
        );
    }

    html.push_str("<h2>Unit cell</h2>");
    match &summary.unit_cell {
        Some(c) => {
            let _ = write!(
                html,
                "<p>{} of {} local cells averaged; symmetry average in <b>{}</b>. Symmetry residual ‖A − S(A)‖/‖A − ⟨A⟩‖ of the translational average for every plane group compatible with the lattice (smaller = closer to that symmetry):</p><table>",
                c.cells_selected, c.cells_available, c.group
            );
            header(&mut html, &["plane group", "residual"]);
            let mut residuals = c.residuals.clone();
            residuals.sort_by(|a, b| a.residual.total_cmp(&b.residual));
            for r in &residuals {
                row(
                    &mut html,
                    &[r.group.to_string(), format!("{:.4}", r.residual)],
                );
            }
            html.push_str("</table>\n");
        }
        None => {
            let _ = writeln!(
                html,
                "<p class='note'>No unit-cell average: {}</p>",
                html_escape(summary.unit_cell_note.as_deref().unwrap_or(""))
            );
        }
    }

    html.push_str("<h2>Figures</h2><div class='grid'>\n");
    for f in figures {
        figure_html(&mut html, f);
    }
    html.push_str("</div>\n");
    if let Some(section) = extra_section {
        html.push_str(section);
    }
    html.push_str("<h2>Timing</h2><table>\n");
    let t = &summary.timings;
    header(&mut html, &["stage", "seconds"]);
    for (name, v) in [
        ("read", summary.read_s),
        ("features", t.features_s),
        ("neighbours, local distortion, model fit", t.model_s),
        ("correction and resampling", t.correction_s),
        ("lattice fit", t.lattice_fit_s),
        ("unit cells", t.unit_cells_s),
        ("analysis total", t.total_s),
        ("writing outputs", summary.write_s),
    ] {
        row(&mut html, &[name.into(), format!("{v:.3}")]);
    }
    html.push_str("</table><p class='sub'>Method: Yothers, Browder &amp; Bumm, Rev. Sci. Instrum. 88, 013708 (2017). Every number on this page is in model.json; every feature in features.csv.</p></body></html>\n");
    html
}
