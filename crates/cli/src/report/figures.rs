//! Every picture and plot of a `dhct correct` run, made once and used both as files in the
//! output directory and inside the report.

use dhct_lattice::Lattice;
use dhct_pipeline::{Analysis, RegionFit, UnitCellAnalysis};
use dhct_scan::{ScanGeometry, ScanPair, ScanPass};
use dhct_sm4_io::png_file::Colormap;
use dhct_unitcell::ConfidenceEllipse;
use ndarray::{Array2, s};
use rayon::prelude::*;

use super::plots::{BLUE, GREEN, ORANGE, Plot, Series, Style, VERMILION, thin};
use super::render::{Canvas, display_range, heat_colour, upscale_for};

/// A figure: a PNG picture or an SVG plot, with its file stem and caption.
pub struct Figure {
    /// File stem in the output directory (`stem.png` / `stem.svg`).
    pub stem: String,
    pub title: String,
    pub caption: String,
    pub content: FigureContent,
}

pub enum FigureContent {
    /// The full-resolution PNG (the file) and, for large pictures, a smaller preview for
    /// the report.
    Png(Vec<u8>, Option<Vec<u8>>),
    Svg(String),
}

impl Figure {
    pub(crate) fn png(stem: &str, title: &str, caption: String, canvas: &Canvas) -> Figure {
        Figure {
            stem: stem.into(),
            title: title.into(),
            caption,
            content: FigureContent::Png(canvas.png(), canvas.preview(1100).map(|p| p.png())),
        }
    }
    /// A picture kept only at reduced size (at most `max_side` px): for views whose full
    /// resolution is in another output (raw data, NCC, the deviation table).
    pub(crate) fn png_reduced(
        stem: &str,
        title: &str,
        caption: String,
        canvas: &Canvas,
        max_side: usize,
    ) -> Figure {
        let bytes = canvas
            .preview(max_side)
            .map(|p| p.png())
            .unwrap_or_else(|| canvas.png());
        Figure {
            stem: stem.into(),
            title: title.into(),
            caption,
            content: FigureContent::Png(bytes, None),
        }
    }
    pub(crate) fn svg(stem: &str, title: &str, caption: String, plot: &Plot) -> Figure {
        Figure {
            stem: stem.into(),
            title: title.into(),
            caption,
            content: FigureContent::Svg(plot.svg(560, 360)),
        }
    }
    pub fn file_name(&self) -> String {
        match self.content {
            FigureContent::Png(..) => format!("{}.png", self.stem),
            FigureContent::Svg(_) => format!("{}.svg", self.stem),
        }
    }
}

/// Longest side of the pictures kept only as views (raw, NCC, deviation map), px.
const REDUCED: usize = 1100;

const WHITE: [u8; 3] = [255, 255, 255];
const CYAN: [u8; 3] = [0, 220, 255];
const GREEN_PX: [u8; 3] = [40, 220, 90];
const RED_PX: [u8; 3] = [240, 60, 40];

/// All figures, in report order.
pub fn make_figures(
    pair: &ScanPair,
    lattice: &(dyn Lattice + Sync),
    analysis: &Analysis,
    mask: Option<&Array2<bool>>,
    colormap: Colormap,
) -> Vec<Figure> {
    let geometry = pair.geometry();
    let scale = upscale_for(geometry.rows(), geometry.columns(), 512);
    // Each job makes one or more figures; they run in parallel (PNG encoding dominates) and
    // are collected in this order.
    type Job<'a> = Box<dyn Fn() -> Vec<Figure> + Send + Sync + 'a>;
    let mut jobs: Vec<Job> = Vec::new();
    for pass in &analysis.passes {
        let Some(raw) = pair.image(pass.pass) else {
            continue;
        };
        let range = display_range(raw.z.view());
        jobs.push(Box::new(move || {
            let mut canvas = Canvas::from_image(raw.z.view(), colormap, range, scale);
            if let Some(mask) = mask {
                canvas.dim_outside(mask, scale);
            }
            vec![Figure::png_reduced(
                &format!("raw_{}", pass.pass),
                &format!("Raw {} image", pass.pass),
                format!(
                    "As acquired (controller frame), {} × {} px, {:.2} × {:.2} nm{}.",
                    geometry.columns(),
                    geometry.rows(),
                    geometry.width() * 1e9,
                    geometry.height() * 1e9,
                    if mask.is_some() {
                        "; greyed: outside the mask (not analysed)"
                    } else {
                        ""
                    }
                ),
                &canvas,
                REDUCED,
            )]
        }));
        jobs.push(Box::new(move || {
            vec![Figure::png(
                &format!("corrected_{}", pass.pass),
                &format!("Corrected {} image", pass.pass),
                "Resampled onto the sample-frame grid with the fitted drift/creep/hysteresis \
                 model (same pixel grid and colour scale as the raw image; z values are not \
                 altered; magenta = no data)."
                    .into(),
                &Canvas::from_image(pass.corrected_image.view(), colormap, range, scale),
            )]
        }));
    }
    for pass in &analysis.passes {
        if let Some(ncc) = &pass.correlation {
            jobs.push(Box::new(move || {
                vec![Figure::png_reduced(
                    &format!("ncc_{}", pass.pass),
                    &format!("Normalised cross-correlation ({})", pass.pass),
                    format!(
                        "NCC with the Gaussian kernel (σ = {:.2} px), −1 (black) to 1 \
                         (yellow); {} features found of {} candidates.",
                        pass.features.kernel_sigma_px,
                        pass.features.features.len(),
                        pass.features.candidates
                    ),
                    &Canvas::from_image(ncc.view(), Colormap::Viridis, Some((-1.0, 1.0)), scale),
                    REDUCED,
                )]
            }));
        }
    }
    jobs.push(Box::new(|| vec![rdf_plot(analysis)]));
    jobs.push(Box::new(|| {
        let Some(adf) = analysis.regions.first().and_then(|r| r.adf.as_ref()) else {
            return Vec::new();
        };
        let points = adf
            .angles_rad
            .iter()
            .zip(&adf.counts)
            .map(|(a, &c)| (a.to_degrees(), c as f64))
            .collect();
        let plot = Plot::new(
            "Angular distribution of NN bonds",
            "bond angle (°)",
            "bonds",
        )
        .with(Series::new("corrected", points, Style::Bars, BLUE));
        vec![Figure::svg(
            "adf",
            "Angular distribution (ADF, paper Fig. S2)",
            format!(
                "Directions of the {} nearest-neighbour bonds of the corrected features; lattice \
                 angle {:.2}°.",
                adf.bonds,
                adf.lattice_angle_rad.to_degrees()
            ),
            &plot,
        )]
    }));
    jobs.push(Box::new(|| vec![hysteresis_plot(geometry, analysis)]));
    jobs.push(Box::new(|| drift_plots(analysis)));
    jobs.push(Box::new(|| {
        analysis
            .regions
            .first()
            .map(deviation_scatter)
            .into_iter()
            .collect()
    }));
    jobs.push(Box::new(|| {
        vec![deviation_map(geometry, lattice, analysis)]
    }));
    jobs.push(Box::new(|| {
        lattice_overlay(geometry, lattice, analysis, colormap)
            .into_iter()
            .collect()
    }));
    if let Some(cell) = &analysis.unit_cell {
        let region = analysis.regions.first();
        jobs.push(Box::new(move || {
            vec![cell_picture(
                "unit_cell_averaged",
                "Translationally averaged unit cell (paper Fig. 10)",
                lattice,
                cell,
                false,
                region,
                colormap,
            )]
        }));
        jobs.push(Box::new(move || {
            vec![cell_picture(
                "unit_cell_symmetrized",
                &format!(
                    "Symmetry-averaged unit cell, {} (paper Fig. 11)",
                    cell.group
                ),
                lattice,
                cell,
                true,
                region,
                colormap,
            )]
        }));
    }
    jobs.par_iter().flat_map_iter(|job| job()).collect()
}

fn rdf_plot(analysis: &Analysis) -> Figure {
    let mut plot = Plot::new("Radial distribution function", "r (Å)", "g(r)");
    let colours = [(BLUE, ORANGE), (GREEN, VERMILION)];
    let mut caption = String::from(
        "g(r) of the raw (controller-frame) and corrected (sample-frame) features; grey lines: \
         the fitted shell positions of the raw RDF.",
    );
    for (k, pass) in analysis.passes.iter().enumerate() {
        let Some(raw) = analysis.dhct.passes.iter().find(|p| p.pass == pass.pass) else {
            continue;
        };
        let (c_raw, c_corr) = colours[k % 2];
        let rdf = &raw.selection.rdf;
        plot = plot.with(Series::new(
            format!("{} raw", pass.pass),
            rdf.r_m
                .iter()
                .zip(&rdf.g)
                .map(|(r, g)| (r * 1e10, *g))
                .collect(),
            Style::Line,
            c_raw,
        ));
        if let Some(after) = &pass.rdf_corrected {
            plot = plot.with(Series::new(
                format!("{} corrected", pass.pass),
                after
                    .r_m
                    .iter()
                    .zip(&after.g)
                    .map(|(r, g)| (r * 1e10, *g))
                    .collect(),
                Style::Line,
                c_corr,
            ));
        }
        if k == 0 {
            plot.vertical_lines = raw
                .selection
                .rdf_fit
                .shells_m
                .iter()
                .map(|r| r * 1e10)
                .collect();
            let fit = &raw.selection.rdf_fit;
            caption.push_str(&format!(
                " First shell (raw {}): {:.3} Å, FWHM {:.3} Å.",
                pass.pass,
                fit.nn_distance_m * 1e10,
                fit.fwhm_m.first().copied().unwrap_or(f64::NAN) * 1e10
            ));
        }
    }
    Figure::svg(
        "rdf",
        "Radial distribution function (paper Fig. 6)",
        caption,
        &plot,
    )
}

fn hysteresis_plot(geometry: &ScanGeometry, analysis: &Analysis) -> Figure {
    let mut plot = Plot::new(
        "Fast-scan hysteresis",
        "time since line start τ (ms)",
        "local scale S",
    );
    for (pass, colour) in [(ScanPass::Trace, BLUE), (ScanPass::Retrace, ORANGE)] {
        let points: Vec<(f64, f64)> = analysis
            .dhct
            .passes
            .iter()
            .filter(|p| p.pass == pass)
            .flat_map(|p| p.local.iter().map(|l| (l.line_time_s * 1e3, l.scale)))
            .collect();
        if !points.is_empty() {
            plot = plot.with(Series::new(
                format!("{pass} (local)"),
                thin(points, 2500),
                Style::Points,
                colour,
            ));
        }
    }
    let law = &analysis.dhct.model.hysteresis;
    let t_line = geometry.line_scan_time();
    let curve = (0..=200)
        .map(|i| {
            let tau = t_line * (i as f64 + 0.5) / 201.0;
            (tau * 1e3, law.scale(tau))
        })
        .collect();
    plot = plot.with(Series::new("fitted law", curve, Style::Line, VERMILION));
    Figure::svg(
        "hysteresis",
        "Hysteresis fit (paper Fig. 8)",
        format!(
            "Local fast-axis scale S of every selected feature against its time since the \
             start of its line, trace and retrace pooled; red: the fitted law {}.",
            describe_law(law)
        ),
        &plot,
    )
}

fn describe_law(law: &dhct_distortion::HysteresisLaw) -> String {
    use dhct_distortion::HysteresisLaw::*;
    match law {
        Power { k, n } => format!("S = k·τ^n with k = {k:.4} s^-n, n = {n:.4}"),
        Exponential {
            amplitude,
            time_constant_s,
        } => format!(
            "S = 1 + A·exp(−τ/τh) with A = {amplitude:.4}, τh = {:.3} ms",
            time_constant_s * 1e3
        ),
        Quartic {
            coefficients,
            time_scale_s,
        } => format!(
            "S = 1 + Σ c_k (τ/τs)^k with c = {coefficients:.4?}, τs = {:.3} ms",
            time_scale_s * 1e3
        ),
    }
}

fn drift_plots(analysis: &Analysis) -> Vec<Figure> {
    let drift = &analysis.dhct.model.drift;
    let t_max = analysis
        .dhct
        .passes
        .iter()
        .flat_map(|p| p.local.iter().map(|l| l.time_s))
        .fold(0.0, f64::max);
    ["x", "y"]
        .iter()
        .enumerate()
        .map(|(axis, name)| {
            let mut plot = Plot::new(
                &format!("Drift + creep, D{name}"),
                "time since frame start t (s)",
                &format!("D{name} (pm/s)"),
            );
            for (pass, colour) in [(ScanPass::Trace, BLUE), (ScanPass::Retrace, ORANGE)] {
                let points: Vec<(f64, f64)> = analysis
                    .dhct
                    .passes
                    .iter()
                    .filter(|p| p.pass == pass)
                    .flat_map(|p| p.local.iter().map(|l| (l.time_s, l.drift_m_per_s[axis] * 1e12)))
                    .collect();
                if !points.is_empty() {
                    plot = plot.with(Series::new(format!("{pass} (local)"), thin(points, 2500), Style::Points, colour));
                }
            }
            let curve = (0..=200)
                .map(|i| {
                    let t = t_max * i as f64 / 200.0;
                    (t, drift.velocity(t)[axis] * 1e12)
                })
                .collect();
            plot = plot.with(Series::new("fitted v + a·t + C/(t+t0)", curve, Style::Line, VERMILION));
            Figure::svg(
                &format!("drift_{name}"),
                &format!("Drift and creep along {name} (paper Fig. 9)"),
                format!(
                    "Local drift velocity D{name} of every selected feature against acquisition \
                     time; red: the fitted drift + creep velocity (v = {:.2} pm/s, a = {:.3} pm/s², \
                     C = {:.1} pm, t0 = {:.1} s).",
                    drift.velocity_m_per_s[axis] * 1e12,
                    drift.acceleration_m_per_s2[axis] * 1e12,
                    drift.creep_m[axis] * 1e12,
                    drift.t0_s
                ),
                &plot,
            )
        })
        .collect()
}

fn deviation_scatter(region: &RegionFit) -> Figure {
    let points: Vec<(f64, f64)> = region.fit.points[0]
        .iter()
        .map(|p| (p.deviation_m[0] * 1e12, p.deviation_m[1] * 1e12))
        .collect();
    let ellipse = |e: &ConfidenceEllipse, k: f64| -> Vec<(f64, f64)> {
        let mut o: Vec<(f64, f64)> = e
            .outline(e.mean_m, k, 120)
            .into_iter()
            .map(|[x, y]| (x * 1e12, y * 1e12))
            .collect();
        o.push(o[0]);
        o
    };
    let e = &region.whole_ellipse;
    let mut plot = Plot::new("Deviations from the fitted lattice", "Δx (pm)", "Δy (pm)")
        .with(Series::new(
            "features (trace)",
            thin(points, 4000),
            Style::Points,
            BLUE,
        ))
        .with(Series::new("1σ", ellipse(e, 1.0), Style::Line, VERMILION))
        .with(Series::new("2σ", ellipse(e, 2.0), Style::Line, ORANGE));
    if let Some(local) = &region.local_ellipse {
        plot = plot.with(Series::new(
            "1σ local cells",
            ellipse(local, 1.0),
            Style::Line,
            GREEN,
        ));
    }
    Figure::svg(
        "deviation_scatter",
        "Confidence ellipses",
        format!(
            "Deviation of each corrected feature from its fitted lattice site (region 0). \
             Whole-image 1σ ellipse {:.1} × {:.1} pm at {:.1}°{}; σz {:.1} pm.",
            e.sigma_major_m * 1e12,
            e.sigma_minor_m * 1e12,
            e.angle_rad.to_degrees(),
            region
                .local_ellipse
                .as_ref()
                .map(|l| format!(
                    "; local-cell 1σ ellipse {:.1} × {:.1} pm",
                    l.sigma_major_m * 1e12,
                    l.sigma_minor_m * 1e12
                ))
                .unwrap_or_default(),
            e.sigma_z_m.unwrap_or(f64::NAN) * 1e12
        ),
        &plot,
    )
}

/// Each indexed trace feature as a disc coloured by |deviation| over the dimmed corrected
/// image (paper Fig. S3).
fn deviation_map(geometry: &ScanGeometry, lattice: &dyn Lattice, analysis: &Analysis) -> Figure {
    let pass = &analysis.passes[0];
    let scale = upscale_for(geometry.rows(), geometry.columns(), 512);
    let mut canvas = Canvas::from_image(pass.corrected_image.view(), Colormap::Greys, None, scale);
    let mut magnitudes: Vec<f64> = pass
        .indices
        .iter()
        .flatten()
        .map(|i| i.deviation_m[0].hypot(i.deviation_m[1]))
        .collect();
    magnitudes.sort_by(f64::total_cmp);
    let top = magnitudes
        .get(((magnitudes.len() as f64 * 0.99) as usize).min(magnitudes.len().saturating_sub(1)))
        .copied()
        .unwrap_or(1e-12)
        .max(1e-15);
    let radius = 0.45 * lattice.nearest_neighbour_distance() / geometry.pitch_x() * scale as f64;
    for (feature, index) in pass.corrected.iter().zip(&pass.indices) {
        if let Some(index) = index {
            let d = index.deviation_m[0].hypot(index.deviation_m[1]);
            canvas.disc(
                [
                    (feature.x_px + 0.5) * scale as f64,
                    (feature.y_px + 0.5) * scale as f64,
                ],
                radius.max(1.0),
                heat_colour(d / top),
            );
        }
    }
    Figure::png_reduced(
        "deviation_map",
        "Deviation heat map (paper Fig. S3)",
        format!(
            "Each indexed {} feature at its corrected position, coloured by its distance from \
             its fitted lattice site: black 0 pm → yellow {:.1} pm (99th percentile; larger \
             values saturate). Median {:.1} pm.",
            pass.pass,
            top * 1e12,
            magnitudes
                .get(magnitudes.len() / 2)
                .copied()
                .unwrap_or(f64::NAN)
                * 1e12
        ),
        &canvas,
        REDUCED,
    )
}

/// A central detail of the corrected image with the fitted sites and local cells (paper
/// Fig. S4).
fn lattice_overlay(
    geometry: &ScanGeometry,
    lattice: &dyn Lattice,
    analysis: &Analysis,
    colormap: Colormap,
) -> Option<Figure> {
    let region = analysis.regions.first()?;
    let pass = analysis
        .passes
        .iter()
        .find(|p| p.pass == region.passes[0])?;
    // Centre the crop on the region's median feature.
    let mut xs: Vec<f64> = region.members[0]
        .iter()
        .map(|&i| pass.corrected[i].x_px)
        .collect();
    let mut ys: Vec<f64> = region.members[0]
        .iter()
        .map(|&i| pass.corrected[i].y_px)
        .collect();
    xs.sort_by(f64::total_cmp);
    ys.sort_by(f64::total_cmp);
    let (cx, cy) = (xs[xs.len() / 2], ys[ys.len() / 2]);
    let span_px =
        (12.0 * lattice.nearest_neighbour_distance() / geometry.pitch_x()).ceil() as usize;
    let half = span_px.clamp(16, 200) / 2;
    let (rows, columns) = (geometry.rows(), geometry.columns());
    let c0 = (cx.round() as usize)
        .saturating_sub(half)
        .min(columns.saturating_sub(2 * half));
    let r0 = (cy.round() as usize)
        .saturating_sub(half)
        .min(rows.saturating_sub(2 * half));
    let (c1, r1) = ((c0 + 2 * half).min(columns), (r0 + 2 * half).min(rows));
    let crop = pass.corrected_image.slice(s![r0..r1, c0..c1]);
    let scale = upscale_for(r1 - r0, c1 - c0, 640);
    let mut canvas = Canvas::from_image(crop, colormap, display_range(crop), scale);
    let to_px = |xm: f64, ym: f64| {
        [
            (xm / geometry.pitch_x() - c0 as f64 + 0.5) * scale as f64,
            (ym / geometry.pitch_y() - r0 as f64 + 0.5) * scale as f64,
        ]
    };
    // Local cells of this set whose origin lies in the crop.
    for cell in &region.local_cells[0] {
        let t = cell.transform();
        let [a1, a2] = lattice.primitive_vectors();
        let o = nalgebra::Vector2::from(cell.origin_m);
        let corners = [o, o + t * a1, o + t * (a1 + a2), o + t * a2];
        let px: Vec<[f64; 2]> = corners.iter().map(|p| to_px(p.x, p.y)).collect();
        if px.iter().all(|p| {
            p[0] >= 0.0 && p[1] >= 0.0 && p[0] < canvas.width as f64 && p[1] < canvas.height as f64
        }) {
            canvas.polygon(&px, 1.0, CYAN);
        }
    }
    for (k, &i) in region.members[0].iter().enumerate() {
        let point = &region.fit.points[0][k];
        let site = region
            .fit
            .site_position(lattice, point.n, point.m, point.site, 0);
        canvas.cross(to_px(site[0], site[1]), 0.6 * scale as f64, 1.5, WHITE);
        let f = &pass.corrected[i];
        canvas.disc(to_px(f.x_m, f.y_m), 0.35 * scale as f64, RED_PX);
    }
    Some(Figure::png(
        "lattice_overlay",
        "Lattice fit overlay (paper Fig. S4)",
        format!(
            "Detail of the corrected {} image ({}–{} × {}–{} px): fitted lattice sites (white +), \
             corrected feature positions (red dots) and the local unit cells fitted to their \
             four corner features (cyan).",
            pass.pass, c0, c1, r0, r1
        ),
        &canvas,
    ))
}

/// Periodic bilinear sample of a cell grid at fractional `(u, v)`.
fn sample_cell(values: &Array2<f64>, u: f64, v: f64) -> f64 {
    let r = values.nrows() as f64;
    let (x, y) = (u.rem_euclid(1.0) * r, v.rem_euclid(1.0) * r);
    let (j0, i0) = (
        x.floor() as usize % values.ncols(),
        y.floor() as usize % values.nrows(),
    );
    let (j1, i1) = ((j0 + 1) % values.ncols(), (i0 + 1) % values.nrows());
    let (fx, fy) = (x - x.floor(), y - y.floor());
    values[[i0, j0]] * (1.0 - fx) * (1.0 - fy)
        + values[[i0, j1]] * fx * (1.0 - fy)
        + values[[i1, j0]] * (1.0 - fx) * fy
        + values[[i1, j1]] * fx * fy
}

/// The averaged (or symmetrised) cell drawn in real space over a few cells, with the cell
/// outline, the asymmetric unit (symmetrised only) and the confidence ellipses at the motif
/// sites.
fn cell_picture(
    stem: &str,
    title: &str,
    lattice: &dyn Lattice,
    cell: &UnitCellAnalysis,
    symmetrized: bool,
    region: Option<&RegionFit>,
    colormap: Colormap,
) -> Figure {
    let values = if symmetrized {
        &cell.symmetrized.values
    } else {
        &cell.averaged.values
    };
    let [a1, a2] = lattice.primitive_vectors();
    let basis = nalgebra::Matrix2::from_columns(&[a1, a2]);
    let inverse = basis
        .try_inverse()
        .unwrap_or_else(nalgebra::Matrix2::identity);
    // A window 2.6 cells wide around the first cell.
    let corners = [a1 * 0.0, a1, a2, a1 + a2];
    let (mut x0, mut x1, mut y0, mut y1) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for c in corners {
        x0 = x0.min(c.x);
        x1 = x1.max(c.x);
        y0 = y0.min(c.y);
        y1 = y1.max(c.y);
    }
    let pad = 0.8 * lattice.nearest_neighbour_distance();
    let (x0, x1, y0, y1) = (x0 - pad, x1 + pad, y0 - pad, y1 + pad);
    let width = 480usize;
    let metres_per_px = (x1 - x0) / width as f64;
    let height = ((y1 - y0) / metres_per_px).ceil() as usize;
    let range = display_range(values.view()).unwrap_or((0.0, 1.0));
    // Picture y grows downwards like the images; lattice y is the image's y.
    let to_m =
        |px: f64, py: f64| nalgebra::Vector2::new(x0 + px * metres_per_px, y0 + py * metres_per_px);
    let to_px =
        |p: nalgebra::Vector2<f64>| [(p.x - x0) / metres_per_px, (p.y - y0) / metres_per_px];
    let mut canvas = Canvas::from_fn(width, height, colormap, range, |px, py| {
        let f = inverse * to_m(px, py);
        sample_cell(values, f.x, f.y)
    });
    let outline: Vec<[f64; 2]> = [a1 * 0.0, a1, a1 + a2, a2].into_iter().map(to_px).collect();
    canvas.polygon(&outline, 2.0, WHITE);
    if symmetrized {
        let asym: Vec<[f64; 2]> = cell
            .asymmetric_unit
            .iter()
            .map(|[u, v]| to_px(a1 * *u + a2 * *v))
            .collect();
        canvas.polygon(&asym, 2.0, CYAN);
    }
    // Ellipses at every motif site of the four corner cells, magnified to be visible.
    let mut note = String::new();
    if let Some(region) = region {
        let e = &region.whole_ellipse;
        let two_sigma_px = 2.0 * e.sigma_major_m / metres_per_px;
        let magnification = if two_sigma_px >= 4.0 {
            1.0
        } else {
            (4.0 / two_sigma_px.max(1e-6)).ceil().min(100.0)
        };
        for (n, m) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
            for site in 0..lattice.motif().len() {
                let centre = a1 * n as f64 + a2 * m as f64 + lattice.site_position(site);
                let c = to_px(centre);
                for (ellipse, colour) in
                    [(Some(e), RED_PX), (region.local_ellipse.as_ref(), GREEN_PX)]
                {
                    let Some(ellipse) = ellipse else { continue };
                    for k in [1.0, 2.0] {
                        let pts: Vec<[f64; 2]> = ellipse
                            .outline([0.0, 0.0], k * magnification, 72)
                            .into_iter()
                            .map(|[x, y]| [c[0] + x / metres_per_px, c[1] + y / metres_per_px])
                            .collect();
                        canvas.polygon(&pts, 1.2, colour);
                    }
                }
            }
        }
        note = format!(
            " Ellipses: 1σ and 2σ of the whole-image fit (red, {:.1} × {:.1} pm) and of the local \
             cells (green){}.",
            e.sigma_major_m * 1e12,
            e.sigma_minor_m * 1e12,
            if magnification > 1.0 {
                format!(", drawn ×{magnification:.0} to be visible")
            } else {
                ", to scale".into()
            }
        );
    }
    let caption = if symmetrized {
        let residual = cell
            .residuals
            .iter()
            .find(|r| r.group == cell.group)
            .map(|r| r.residual)
            .unwrap_or(f64::NAN);
        format!(
            "The averaged cell averaged over the {} operations of {} (symmetry residual of the \
             translational average {:.3}); white: the unit cell, cyan: the asymmetric unit.{note}",
            dhct_unitcell::operations(cell.group, lattice)
                .map(|o| o.len())
                .unwrap_or(0),
            cell.group,
            residual
        )
    } else {
        format!(
            "Average of {} local cells (of {} found), each resampled through its own fitted \
             linear map; drawn in real space over neighbouring cells to show that the \
             boundaries are seamless; white: the unit cell.{note}",
            cell.cells_selected, cell.cells_available
        )
    };
    Figure::png(stem, title, caption, &canvas)
}
