//! Pictures with drawn overlays: the deviation heat map, the lattice-fit detail and the
//! averaged and symmetrised unit cells.

use dhct_lattice::Lattice;
use dhct_pipeline::{RegionFit, UnitCellAnalysis};
use dhct_sm4_io::png_file::Colormap;
use nalgebra::{Matrix2, Vector2};
use ndarray::{Array2, s};

use super::bars::ColourBar;
use super::figures::{
    Figure, FigureInputs, PictureStyle, REDUCED, channel_colour_bar, metres_per_picture_px,
};
use super::render::{Canvas, display_range, heat_colour, upscale_for};

pub(crate) const WHITE: [u8; 3] = [255, 255, 255];
/// Outlines under the markers, so they show on bright atoms too.
pub(crate) const OUTLINE: [u8; 3] = [20, 20, 20];
/// Okabe–Ito sky blue, bluish green and vermilion as picture colours.
pub(crate) const SKY: [u8; 3] = [86, 180, 233];
pub(crate) const GREEN_PX: [u8; 3] = [0, 158, 115];
const VERMILION_PX: [u8; 3] = [213, 94, 0];

/// The `q` quantile of sorted values (`fallback` when empty).
fn quantile(sorted: &[f64], q: f64, fallback: f64) -> f64 {
    sorted
        .get(((sorted.len() as f64 * q) as usize).min(sorted.len().saturating_sub(1)))
        .copied()
        .unwrap_or(fallback)
}

/// Each indexed trace feature as a disc coloured by |deviation| over the dimmed corrected
/// image (paper Fig. S3).
pub fn deviation_map(inputs: &FigureInputs) -> Figure {
    let geometry = inputs.pair.geometry();
    let pass = &inputs.analysis.passes[0];
    let scale = upscale_for(geometry.rows(), geometry.columns(), 512);
    let mut canvas = Canvas::from_image(pass.corrected_image.view(), Colormap::Greys, None, scale);
    let mut magnitudes: Vec<f64> = pass
        .indices
        .iter()
        .flatten()
        .map(|i| i.deviation_m[0].hypot(i.deviation_m[1]))
        .collect();
    magnitudes.sort_by(f64::total_cmp);
    let top = quantile(&magnitudes, 0.99, 1e-12).max(1e-15);
    let radius =
        0.45 * inputs.lattice.nearest_neighbour_distance() / geometry.pitch_x() * scale as f64;
    for (feature, index) in pass.corrected.iter().zip(&pass.indices) {
        if let Some(index) = index {
            let d = index.deviation_m[0].hypot(index.deviation_m[1]);
            let centre = [
                (feature.x_px + 0.5) * scale as f64,
                (feature.y_px + 0.5) * scale as f64,
            ];
            canvas.disc(centre, radius.max(1.0), heat_colour(d / top));
        }
    }
    Figure::picture(
        "deviation_map",
        "Deviation heat map (paper Fig. S3)",
        format!(
            "Each indexed {} feature at its corrected position, coloured by its distance from \
             its fitted lattice site (colour bar; values above the 99th percentile, {:.1} pm, \
             saturate). Median {:.1} pm.",
            pass.pass,
            top * 1e12,
            quantile(&magnitudes, 0.5, f64::NAN) * 1e12
        ),
        &canvas,
        PictureStyle {
            metres_per_px: metres_per_picture_px(geometry, scale),
            colour: Some(ColourBar {
                colormap: Colormap::Inferno,
                low: 0.0,
                high: top,
                unit: "m".into(),
                label: "|deviation|".into(),
            }),
            max_side: Some(REDUCED),
        },
    )
}

/// The crop of the corrected image around region 0's median feature: (r0, r1, c0, c1).
fn overlay_window(inputs: &FigureInputs, region: &RegionFit, pass: usize) -> [usize; 4] {
    let geometry = inputs.pair.geometry();
    let corrected = &inputs.analysis.passes[pass].corrected;
    let median = |f: &dyn Fn(usize) -> f64| {
        let mut v: Vec<f64> = region.members[0].iter().map(|&i| f(i)).collect();
        v.sort_by(f64::total_cmp);
        v.get(v.len() / 2).copied().unwrap_or(0.0)
    };
    let (cx, cy) = (
        median(&|i| corrected[i].x_px),
        median(&|i| corrected[i].y_px),
    );
    let span_px = (12.0 * inputs.lattice.nearest_neighbour_distance() / geometry.pitch_x()).ceil();
    let half = (span_px as usize).clamp(16, 200) / 2;
    let (rows, columns) = (geometry.rows(), geometry.columns());
    let c0 = (cx.round() as usize)
        .saturating_sub(half)
        .min(columns.saturating_sub(2 * half));
    let r0 = (cy.round() as usize)
        .saturating_sub(half)
        .min(rows.saturating_sub(2 * half));
    [
        r0,
        (r0 + 2 * half).min(rows),
        c0,
        (c0 + 2 * half).min(columns),
    ]
}

/// A central detail of the corrected image with the fitted sites and local cells (paper
/// Fig. S4).
pub fn lattice_overlay(inputs: &FigureInputs) -> Option<Figure> {
    let (geometry, lattice) = (inputs.pair.geometry(), inputs.lattice);
    let region = inputs.analysis.regions.first()?;
    let index = inputs
        .analysis
        .passes
        .iter()
        .position(|p| p.pass == region.passes[0])?;
    let pass = &inputs.analysis.passes[index];
    let [r0, r1, c0, c1] = overlay_window(inputs, region, index);
    let crop = pass.corrected_image.slice(s![r0..r1, c0..c1]);
    let scale = upscale_for(r1 - r0, c1 - c0, 640);
    let range = display_range(crop);
    let mut canvas = Canvas::from_image(crop, inputs.colormap, range, scale);
    let to_px = |xm: f64, ym: f64| {
        [
            (xm / geometry.pitch_x() - c0 as f64 + 0.5) * scale as f64,
            (ym / geometry.pitch_y() - r0 as f64 + 0.5) * scale as f64,
        ]
    };
    let [a1, a2] = lattice.primitive_vectors();
    let inside = |p: &[f64; 2], c: &Canvas| {
        p[0] >= 0.0 && p[1] >= 0.0 && p[0] < c.width as f64 && p[1] < c.height as f64
    };
    // Cells that do not touch each other (the cells tile the image: all of them make a mesh).
    let cell_side = a1.norm().max(a2.norm());
    let mut drawn: Vec<Vector2<f64>> = Vec::new();
    for cell in &region.local_cells[0] {
        let (t, o) = (cell.transform(), Vector2::from(cell.origin_m));
        if drawn.iter().any(|d| (d - o).norm() < 2.5 * cell_side) {
            continue;
        }
        let corners = [o, o + t * a1, o + t * (a1 + a2), o + t * a2];
        let px: Vec<[f64; 2]> = corners.iter().map(|p| to_px(p.x, p.y)).collect();
        if px.iter().all(|p| inside(p, &canvas)) {
            canvas.polygon(&px, 2.0, SKY);
            drawn.push(o);
        }
    }
    let marker = 0.6 * scale as f64;
    for (k, &i) in region.members[0].iter().enumerate() {
        let point = &region.fit.points[0][k];
        let site = region
            .fit
            .site_position(lattice, point.n, point.m, point.site, 0);
        let at = to_px(site[0], site[1]);
        canvas.cross(at, marker + 1.0, 4.0, OUTLINE);
        canvas.cross(at, marker, 1.8, WHITE);
        let f = to_px(pass.corrected[i].x_m, pass.corrected[i].y_m);
        canvas.disc(f, 0.35 * scale as f64 + 1.5, OUTLINE);
        canvas.disc(f, 0.35 * scale as f64, VERMILION_PX);
    }
    let channel = inputs.pair.image(pass.pass)?;
    Some(Figure::picture(
        "lattice_overlay",
        "Lattice fit overlay (paper Fig. S4)",
        format!(
            "Detail of the corrected {} image (columns {c0}–{c1}, rows {r0}–{r1}): fitted \
             lattice sites (white +), corrected feature positions (vermilion dots) and, \
             apart from one another, some of the local unit cells fitted to their four \
             corner features (sky blue; every cell enters the averages).",
            pass.pass
        ),
        &canvas,
        PictureStyle {
            metres_per_px: metres_per_picture_px(geometry, scale),
            colour: channel_colour_bar(channel, inputs.colormap, range),
            max_side: None,
        },
    ))
}

/// The averaged cell's values, or the symmetrised cell's.
pub(crate) fn cell_values(cell: &UnitCellAnalysis, symmetrized: bool) -> &Array2<f64> {
    if symmetrized {
        &cell.symmetrized.values
    } else {
        &cell.averaged.values
    }
}

/// The colour bar of a unit-cell picture: heights over `range`, metres.
pub(crate) fn height_bar(colormap: Colormap, range: (f64, f64)) -> ColourBar {
    ColourBar {
        colormap,
        low: range.0,
        high: range.1,
        unit: "m".into(),
        label: "height".into(),
    }
}

/// Periodic bilinear sample of a cell grid at fractional `(u, v)`.
pub(crate) fn sample_cell(values: &Array2<f64>, u: f64, v: f64) -> f64 {
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

/// The real-space window of a unit-cell picture: its origin (metres) and metres per px.
struct CellWindow {
    origin: Vector2<f64>,
    metres_per_px: f64,
    width: usize,
    height: usize,
}

impl CellWindow {
    /// The first cell padded by 0.8 NN distances, 480 px wide.
    fn around(lattice: &dyn Lattice) -> CellWindow {
        let [a1, a2] = lattice.primitive_vectors();
        let corners = [a1 * 0.0, a1, a2, a1 + a2];
        let low = corners
            .iter()
            .fold(Vector2::repeat(f64::INFINITY), |m, c| m.inf(c));
        let high = corners
            .iter()
            .fold(Vector2::repeat(f64::NEG_INFINITY), |m, c| m.sup(c));
        let pad = Vector2::repeat(0.8 * lattice.nearest_neighbour_distance());
        let (low, high) = (low - pad, high + pad);
        let width = 480usize;
        let metres_per_px = (high.x - low.x) / width as f64;
        let height = ((high.y - low.y) / metres_per_px).ceil().max(1.0) as usize;
        CellWindow {
            origin: low,
            metres_per_px,
            width,
            height,
        }
    }
    /// Picture y grows downwards like the images; lattice y is the image's y.
    fn to_px(&self, p: Vector2<f64>) -> [f64; 2] {
        let q = (p - self.origin) / self.metres_per_px;
        [q.x, q.y]
    }
    fn to_m(&self, px: f64, py: f64) -> Vector2<f64> {
        self.origin + Vector2::new(px, py) * self.metres_per_px
    }
}

/// The whole-image (vermilion) and local-cell (green) 1σ and 2σ ellipses at every motif
/// site of four cells, magnified to be at least 4 px; returns the caption note.
fn draw_cell_ellipses(
    canvas: &mut Canvas,
    window: &CellWindow,
    lattice: &dyn Lattice,
    region: &RegionFit,
) -> String {
    let [a1, a2] = lattice.primitive_vectors();
    let e = &region.whole_ellipse;
    let two_sigma_px = 2.0 * e.sigma_major_m / window.metres_per_px;
    let magnification = if two_sigma_px >= 4.0 {
        1.0
    } else {
        (4.0 / two_sigma_px.max(1e-6)).ceil().min(100.0)
    };
    for (n, m) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
        for site in 0..lattice.motif().len() {
            let c = window.to_px(a1 * n as f64 + a2 * m as f64 + lattice.site_position(site));
            for (ellipse, colour) in [
                (Some(e), VERMILION_PX),
                (region.local_ellipse.as_ref(), GREEN_PX),
            ] {
                let Some(ellipse) = ellipse else { continue };
                for k in [1.0, 2.0] {
                    let pts: Vec<[f64; 2]> = ellipse
                        .outline([0.0, 0.0], k * magnification, 72)
                        .into_iter()
                        .map(|[x, y]| {
                            [
                                c[0] + x / window.metres_per_px,
                                c[1] + y / window.metres_per_px,
                            ]
                        })
                        .collect();
                    canvas.polygon(&pts, 1.2, colour);
                }
            }
        }
    }
    format!(
        " Ellipses: 1σ and 2σ of the whole-image fit (vermilion, {:.1} × {:.1} pm) and of the \
         local cells (green){}.",
        e.sigma_major_m * 1e12,
        e.sigma_minor_m * 1e12,
        if magnification > 1.0 {
            format!(", drawn ×{magnification:.0} to be visible")
        } else {
            ", to scale".into()
        }
    )
}

/// The caption of a unit-cell picture (before the ellipse note).
fn cell_caption(cell: &UnitCellAnalysis, lattice: &dyn Lattice, symmetrized: bool) -> String {
    if symmetrized {
        let residual = cell
            .residuals
            .iter()
            .find(|r| r.group == cell.group)
            .map(|r| r.residual)
            .unwrap_or(f64::NAN);
        format!(
            "The averaged cell averaged over the {} operations of {} (symmetry residual of the \
             translational average {:.3}); white: the unit cell, sky blue: the asymmetric unit.",
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
             boundaries are seamless; white: the unit cell.",
            cell.cells_selected, cell.cells_available
        )
    }
}

/// The averaged (or symmetrised) cell drawn in real space over a few cells, with the cell
/// outline, the asymmetric unit (symmetrised only) and the confidence ellipses.
pub fn cell_picture(inputs: &FigureInputs, symmetrized: bool) -> Option<Figure> {
    let (lattice, cell) = (inputs.lattice, inputs.analysis.unit_cell.as_ref()?);
    let values = cell_values(cell, symmetrized);
    let [a1, a2] = lattice.primitive_vectors();
    let inverse = Matrix2::from_columns(&[a1, a2]).try_inverse()?;
    let window = CellWindow::around(lattice);
    let range = display_range(values.view()).unwrap_or((0.0, 1.0));
    let mut canvas = Canvas::from_fn(
        window.width,
        window.height,
        inputs.colormap,
        range,
        |px, py| {
            let f = inverse * window.to_m(px, py);
            sample_cell(values, f.x, f.y)
        },
    );
    let outline: Vec<[f64; 2]> = [a1 * 0.0, a1, a1 + a2, a2]
        .into_iter()
        .map(|p| window.to_px(p))
        .collect();
    canvas.polygon(&outline, 2.0, WHITE);
    if symmetrized {
        let asym: Vec<[f64; 2]> = cell
            .asymmetric_unit
            .iter()
            .map(|[u, v]| window.to_px(a1 * *u + a2 * *v))
            .collect();
        canvas.polygon(&asym, 2.0, SKY);
    }
    let mut caption = cell_caption(cell, lattice, symmetrized);
    if let Some(region) = inputs.analysis.regions.first() {
        caption.push_str(&draw_cell_ellipses(&mut canvas, &window, lattice, region));
    }
    let (stem, title) = if symmetrized {
        (
            "unit_cell_symmetrized",
            format!(
                "Symmetry-averaged unit cell, {} (paper Fig. 11)",
                cell.group
            ),
        )
    } else {
        (
            "unit_cell_averaged",
            "Translationally averaged unit cell (paper Fig. 10)".to_string(),
        )
    };
    let colour = height_bar(inputs.colormap, range);
    Some(Figure::picture(
        stem,
        &title,
        caption,
        &canvas,
        PictureStyle {
            metres_per_px: Some([window.metres_per_px; 2]),
            colour: Some(colour),
            max_side: None,
        },
    ))
}
