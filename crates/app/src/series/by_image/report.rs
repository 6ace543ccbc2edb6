//! `report.html` of a registration by image: what to trust, what was not determined, the
//! drift over the session, the mean registered image and each pair's comparison.

use std::path::Path;

use anyhow::Result;
use dhct_scan::quantity::length;
use dhct_sm4_io::png_file::Colormap;

use super::ImageSeriesSummary;
use crate::flags::warning_line;
use crate::report::html::{figure_grid, figure_html};
use crate::report::page::{Html, document};
use crate::report::{write_bytes, write_figure_files};
use crate::series::report::{MeanImage, REPORT_HTML, mean_picture, trajectory_figures};

/// Writes `report.html` and its figures into `dir`; returns the names written.
pub fn write_report(
    dir: &Path,
    summary: &ImageSeriesSummary,
    mean: &MeanImage,
    colormap: Colormap,
) -> Result<Vec<String>> {
    let starts: Vec<f64> = summary.frames.iter().map(|f| f.start_s).collect();
    let trajectory = trajectory_figures(
        &summary.drift.trajectory,
        &starts,
        "fitted to where bands of each frame's lines reappear in the frame before",
    );
    let mean_figure = mean_picture(mean, colormap);
    let fit = &summary.drift;
    let mut body = Html::new();
    body.element("h1", "dhct series report: registered by the images")
        .element_with(
            "p",
            &[("class", "sub")],
            &format!(
                "{} frames over {:.0} s, registered without a lattice: {} comparisons of \
                 bands of lines, fitted within ({}, {}) rms",
                summary.frames.len(),
                fit.trajectory.last().map_or(0.0, |p| p.time_s),
                fit.comparisons,
                length(fit.rms_residual_m[0]),
                length(fit.rms_residual_m[1])
            ),
        );
    body.open("div", &[("class", "summary")])
        .element("h2", "What to trust");
    if summary.warnings.is_empty() {
        body.element(
            "p",
            "No warning: every pair was compared on most of its bands of lines and every \
             registered image lines up with the first frame's to half a pixel.",
        );
    } else {
        let lines: Vec<String> = summary.warnings.iter().map(warning_line).collect();
        body.list(&lines);
    }
    body.element("p", "Not determined without a lattice:")
        .list(&summary.undetermined);
    if !summary.notes.is_empty() {
        body.element("p", "Notes and assumptions:")
            .list(&summary.notes);
    }
    body.close("div");
    body.element("h2", "Drift over the session");
    figure_grid(&mut body, &trajectory);
    body.element("h2", "The mean registered image");
    figure_html(&mut body, &mean_figure);
    body.element("h2", "Comparisons");
    let rows: Vec<Vec<String>> = summary
        .comparisons
        .iter()
        .map(|p| {
            vec![
                format!("{} → {}", p.frame - 1, p.frame),
                format!("({:.2}, {:.2})", p.whole_shift_px[0], p.whole_shift_px[1]),
                format!("{:.1}", p.significance),
                format!("{} of {}", p.bands_measured, p.bands),
            ]
        })
        .collect();
    body.table(
        &[
            "frames",
            "whole shift (px)",
            "peak over noise (σ)",
            "bands compared",
        ],
        &rows,
    );
    let page = document("dhct series report", body);
    write_bytes(&dir.join(REPORT_HTML), page.as_bytes())?;
    let mut figures = trajectory;
    figures.push(mean_figure);
    let mut written = write_figure_files(dir, &figures)?;
    written.push(REPORT_HTML.to_string());
    Ok(written)
}
