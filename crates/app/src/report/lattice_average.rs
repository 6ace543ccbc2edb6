//! The paper's Figs. 10a and 11a: the averaged (or symmetrised) unit cell placed at every
//! cell of the fitted lattice, over a detail of the corrected image, beside which the
//! corrected image itself shows what the averaging removed (noise, defects, drift left).

use nalgebra::{Matrix2, Vector2};

use super::detail::Detail;
use super::figures::{Figure, FigureInputs, PictureStyle, metres_per_picture_px};
use super::overlays::{cell_values, height_bar, sample_cell};
use super::render::{Canvas, display_range, upscale_for};

/// Side of the detail, nearest-neighbour distances.
const DETAIL_NN: f64 = 20.0;

/// The averaged (or symmetrised) cell tiled over the fitted lattice of region 0, on a
/// central detail of the corrected grid; pixels without corrected data stay blank.
pub fn lattice_average_picture(inputs: &FigureInputs, symmetrized: bool) -> Option<Figure> {
    let (lattice, cell) = (inputs.lattice, inputs.analysis.unit_cell.as_ref()?);
    let region = inputs.analysis.regions.first()?;
    let pass = inputs
        .analysis
        .passes
        .iter()
        .find(|p| p.pass == region.passes[0])?;
    let values = cell_values(cell, symmetrized);
    let [a1, a2] = lattice.primitive_vectors();
    let to_fraction = Matrix2::from_columns(&[a1, a2]).try_inverse()?;
    let fit = &region.fit;
    let to_ideal = fit.transform().try_inverse()?;
    let origin = Vector2::from(fit.origin_m) + Vector2::from(*fit.set_offsets_m.first()?);
    let geometry = inputs.pair.geometry();
    let (rows, columns) = pass.corrected_image.dim();
    let detail = Detail::central(geometry, DETAIL_NN * lattice.nearest_neighbour_distance());
    let (c0, r0, w, h) = (detail.c0, detail.r0, detail.width(), detail.height());
    let scale = upscale_for(h, w, 640);
    let range = display_range(values.view()).unwrap_or((0.0, 1.0));
    let canvas = Canvas::from_fn(w * scale, h * scale, inputs.colormap, range, |px, py| {
        let (x, y) = (
            px / scale as f64 - 0.5 + c0 as f64,
            py / scale as f64 - 0.5 + r0 as f64,
        );
        let measured = pass.corrected_image[[
            (y.round() as usize).min(rows - 1),
            (x.round() as usize).min(columns - 1),
        ]];
        if !measured.is_finite() {
            return f64::NAN;
        }
        let p = Vector2::new(x * geometry.pitch_x(), y * geometry.pitch_y());
        let f = to_fraction * (to_ideal * (p - origin));
        sample_cell(values, f.x, f.y)
    });
    let (stem, title, what) = if symmetrized {
        (
            "lattice_symmetrized",
            format!(
                "Symmetry-averaged cell over the lattice, {} (paper Fig. 11a)",
                cell.group
            ),
            "symmetry-averaged",
        )
    } else {
        (
            "lattice_averaged",
            "Averaged cell over the lattice (paper Fig. 10a)".to_string(),
            "translationally averaged",
        )
    };
    Some(Figure::picture(
        stem,
        &title,
        format!(
            "The {what} unit cell placed at every cell of the lattice fitted to the corrected \
             {} image (region 0), over its central detail (columns {c0}–{}, rows {r0}–{}): \
             compare with the corrected image to see what the average removes (noise, \
             defects, distortion left); white: no corrected data.",
            pass.pass,
            c0 + w,
            r0 + h
        ),
        &canvas,
        PictureStyle {
            metres_per_px: metres_per_picture_px(geometry, scale),
            colour: Some(height_bar(inputs.colormap, range)),
            max_side: None,
        },
    ))
}
