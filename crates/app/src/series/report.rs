//! `report.html` of a series: what to trust (warnings first), the drift over the whole
//! session with its 1σ band and the frame starts, the mean registered image with its
//! scale bar, each frame's placement and check, and the model's parameters. Its plots and
//! picture are also files beside it (`trajectory_{x,y}.svg`, `mean.png`, `mean.svg`).

use std::path::Path;

use anyhow::Result;
use dhct_distortion::series::TrajectoryPoint;
use dhct_pipeline::CorrectedImageCheck;
use dhct_scan::quantity::{length, value_with_sigma};
use dhct_scan::{ImageChannel, ScanGeometry};
use dhct_sm4_io::png_file::Colormap;

use super::SeriesSummary;
use crate::flags::warning_line;
use crate::report::figures::{
    Figure, PictureStyle, REDUCED, channel_colour_bar, metres_per_picture_px,
};
use crate::report::html::{figure_grid, figure_html};
use crate::report::page::{Html, document};
use crate::report::plots::{GREY, INK, Plot, Series, Style};
use crate::report::render::{Canvas, display_range, upscale_for};
use crate::report::{write_bytes, write_figure_files};

/// File name of the report.
pub const REPORT_HTML: &str = "report.html";

/// The mean registered image and the grid it is on.
pub struct MeanImage<'a> {
    /// The image (NaN where no frame reached).
    pub channel: &'a ImageChannel,
    /// The first frame's grid.
    pub grid: &'a ScanGeometry,
}

/// Writes `report.html` and its figures into `dir`; returns the names written.
pub fn write_report(
    dir: &Path,
    summary: &SeriesSummary,
    mean: &MeanImage,
    colormap: Colormap,
) -> Result<Vec<String>> {
    let trajectory = trajectory_plots(summary);
    let mean_figure = mean_picture(mean, colormap);
    let mut body = Html::new();
    body.element("h1", "dhct series report").element_with(
        "p",
        &[("class", "sub")],
        &headline(summary),
    );
    trust_section(&mut body, summary);
    body.element("h2", "Drift over the session");
    figure_grid(&mut body, &trajectory);
    body.element("h2", "The mean registered image");
    figure_html(&mut body, &mean_figure);
    frames_section(&mut body, summary);
    parameters_section(&mut body, summary);
    let page = document("dhct series report", body);
    write_bytes(&dir.join(REPORT_HTML), page.as_bytes())?;
    let mut figures = trajectory;
    figures.push(mean_figure);
    let mut written = write_figure_files(dir, &figures)?;
    written.push(REPORT_HTML.to_string());
    Ok(written)
}

/// One line under the title: frames, session length, features, rms.
fn headline(summary: &SeriesSummary) -> String {
    let fit = &summary.fit;
    format!(
        "{} frames over {:.0} s; {} features fitted; rms deviation from the lattice {}",
        summary.frames.len(),
        fit.trajectory.last().map_or(0.0, |p| p.time_s),
        fit.features,
        length(fit.rms_deviation_m)
    )
}

/// Warnings (each frame's, then the series'), then notes and assumptions.
fn trust_section(html: &mut Html, summary: &SeriesSummary) {
    let mut lines: Vec<String> = Vec::new();
    for (k, frame) in summary.frames.iter().enumerate() {
        lines.extend(
            frame
                .warnings
                .iter()
                .map(|w| format!("frame {k}: {}", warning_line(w))),
        );
    }
    lines.extend(summary.warnings.iter().map(warning_line));
    html.open("div", &[("class", "summary")])
        .element("h2", "What to trust");
    if lines.is_empty() {
        html.element(
            "p",
            "No warning: every frame's inputs agree with its image, every registered image \
             shows the lattice given when measured by its Fourier transform, and the \
             session's model explains every frame.",
        );
    } else {
        html.list(&lines);
    }
    if !summary.notes.is_empty() {
        html.element("p", "Notes and assumptions:")
            .list(&summary.notes);
    }
    html.close("div");
}

/// `D_x(T)` and `D_y(T)` with their 1σ band and grey lines at the frame starts.
fn trajectory_plots(summary: &SeriesSummary) -> Vec<Figure> {
    let starts: Vec<f64> = summary.frames.iter().map(|f| f.start_s).collect();
    trajectory_figures(
        &summary.fit.trajectory,
        &starts,
        "fitted to every feature of every frame",
    )
}

/// `D_x(T)` and `D_y(T)` of `trajectory` with their 1σ band and grey lines at `starts`
/// (session seconds); `fitted_to` says what the drift was fitted to.
pub(super) fn trajectory_figures(
    trajectory: &[TrajectoryPoint],
    starts: &[f64],
    fitted_to: &str,
) -> Vec<Figure> {
    (0..2)
        .map(|axis| {
            let name = ["x", "y"][axis];
            let curve = |k: f64| -> Vec<(f64, f64)> {
                trajectory
                    .iter()
                    .map(|p| {
                        (
                            p.time_s,
                            (p.displacement_m[axis] + k * p.sigma_m[axis]) * 1e9,
                        )
                    })
                    .collect()
            };
            let mut plot = Plot::new(
                &format!("Drift D{name} over the session"),
                "session time T (s)",
                &format!("D{name} (nm)"),
            )
            .with(Series::new(
                "D ± 1σ",
                band(curve(1.0), curve(-1.0)),
                Style::Dashed,
                GREY,
            ))
            .with(Series::new("D (fitted)", curve(0.0), Style::Line, INK));
            plot.vertical_lines = starts.to_vec();
            let largest_sigma = trajectory
                .iter()
                .map(|p| p.sigma_m[axis])
                .fold(0.0, f64::max);
            Figure::plot(
                &format!("trajectory_{name}"),
                &format!("Drift along {name}"),
                format!(
                    "The tip's displacement relative to the sample along instrument {name} \
                     against session time (black), with its 1σ band (grey dashes; at most {}), \
                     {fitted_to}; grey verticals: frame starts. trajectory.csv holds the \
                     numbers.",
                    length(largest_sigma)
                ),
                &plot,
            )
        })
        .collect()
}

/// The outline of a band: `upper` forward, then `lower` back.
fn band(upper: Vec<(f64, f64)>, lower: Vec<(f64, f64)>) -> Vec<(f64, f64)> {
    upper.into_iter().chain(lower.into_iter().rev()).collect()
}

/// The mean registered image with scale and colour bars.
pub(super) fn mean_picture(mean: &MeanImage, colormap: Colormap) -> Figure {
    let z = &mean.channel.z;
    let range = display_range(z.view());
    let scale = upscale_for(z.nrows(), z.ncols(), 512);
    Figure::picture(
        "mean",
        "Mean of the registered frames",
        format!(
            "Every frame's trace and retrace resampled onto the first frame's grid in the \
             session frame and averaged where they hold values (noise down by √N where all \
             frames overlap; magenta where none reached). {} × {}; registered/mean.gsf holds \
             the values.",
            length(mean.grid.width()),
            length(mean.grid.height())
        ),
        &Canvas::from_image(z.view(), colormap, range, scale),
        PictureStyle {
            metres_per_px: metres_per_picture_px(mean.grid, scale),
            colour: channel_colour_bar(mean.channel, colormap, range),
            max_side: Some(REDUCED),
        },
    )
}

/// One row per frame: time, angle, features, placement, fit, checks.
fn frames_section(html: &mut Html, summary: &SeriesSummary) {
    let fit = &summary.fit;
    let rows: Vec<Vec<String>> = summary
        .frames
        .iter()
        .enumerate()
        .map(|(k, frame)| {
            let start = fit.frame_starts.get(k);
            let d = |axis: usize| {
                start.map_or(String::new(), |p| {
                    shown(p.displacement_m[axis], p.sigma_m[axis])
                })
            };
            let rms = |list: &[f64]| list.get(k).map_or(String::new(), |&v| length(v));
            vec![
                k.to_string(),
                frame.file.clone(),
                format!("{:.1}", frame.start_s),
                format!("{:.1}", frame.scan_angle_deg),
                frame.features.to_string(),
                d(0),
                d(1),
                rms(&fit.frame_rms_m),
                rms(&fit.own_rms_m),
                checks_text(&frame.registered_checks),
                shifts_text(&frame.registered_shifts),
                frame.warnings.len().to_string(),
            ]
        })
        .collect();
    html.element("h2", "Frames").element(
        "p",
        "D at each frame's start (instrument frame, relative to the session's mean), the \
         robust rms deviation of its features from the lattice under the session's model \
         and under its own model alone, its registered images' lattice measured by FFT \
         (apparent over true length along x and y, the largest angle error), and their \
         shift against the first frame's registered trace (or the frame before's, named) \
         measured from the pixels alone: 0 when they line up.",
    );
    html.table(
        &[
            "frame",
            "file",
            "start (s)",
            "scan angle (°)",
            "features",
            "D x at start",
            "D y at start",
            "rms, series",
            "rms, own",
            "registered image by FFT",
            "pixel shift (px)",
            "warnings",
        ],
        &rows,
    );
}

/// "trace x 1.000, y 0.999, 0.04°; retrace …" (or "not measured").
fn checks_text(checks: &[CorrectedImageCheck]) -> String {
    if checks.is_empty() {
        return "not measured".into();
    }
    checks
        .iter()
        .map(|c| {
            format!(
                "{} x {:.4}, y {:.4}, {:.2}°{}",
                c.pass,
                c.calibration.scale[0],
                c.calibration.scale[1],
                c.angle_error_deg,
                if c.passes() { "" } else { " (off)" }
            )
        })
        .collect::<Vec<_>>()
        .join("; ")
}

/// "trace (0.004, −0.002); retrace (…) vs 3" (or "—").
fn shifts_text(shifts: &[super::PassShift]) -> String {
    if shifts.is_empty() {
        return "—".into();
    }
    shifts
        .iter()
        .map(|s| match (s.shift_px, s.against_frame) {
            (Some(d), Some(0)) => format!("{} ({:.3}, {:.3})", s.pass, d[0], d[1]),
            (Some(d), Some(k)) => format!("{} ({:.3}, {:.3}) vs frame {k}", s.pass, d[0], d[1]),
            _ => format!("{} not measured", s.pass),
        })
        .collect::<Vec<_>>()
        .join("; ")
}

/// Every fitted parameter with 1σ.
fn parameters_section(html: &mut Html, summary: &SeriesSummary) {
    let fit = &summary.fit;
    let rows: Vec<(String, String)> = fit
        .parameters
        .iter()
        .map(|p| (p.name.clone(), value_with_sigma(p.value, p.sigma, &p.unit)))
        .collect();
    html.element("h2", "Model parameters").element(
        "p",
        &format!(
            "Drift: {}; one hysteresis law for every frame; the scanner's y gain relative to \
             x; 1σ from the fit's covariance.",
            drift_description(fit)
        ),
    );
    html.pairs("parameter", &rows);
}

/// "a cubic spline … with N interior knots (cross-validated); M creep(s) after moves".
pub fn drift_description(fit: &dhct_distortion::series::SeriesFit) -> String {
    format!(
        "a cubic spline in session time with {} interior knots{}; {} creep(s) after moves",
        fit.drift.basis.interior_knots,
        if fit.knot_scores.is_empty() {
            " (as given)"
        } else {
            " (cross-validated)"
        },
        fit.drift.creeps.len()
    )
}

/// `value ± σ` in metres, or the value alone when σ is 0 (the session's reference).
pub fn shown(value: f64, sigma: f64) -> String {
    if sigma > 0.0 {
        value_with_sigma(value, sigma, "m")
    } else {
        length(value)
    }
}
