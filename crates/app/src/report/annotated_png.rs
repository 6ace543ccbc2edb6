//! The standalone PNG of a picture: the picture with its scale bar drawn on it (when the
//! pixel size is stated) and its colour bar beside it, lettered at a size that follows the
//! picture's, so a PNG taken into a paper or a slide still says how large it is and what its
//! colours mean. The report's SVG draws the same bars as vector graphics (`bars.rs`).

use super::bars::{ColourBar, nice_length, tick_label};
use super::raster_text::{draw_text, text_height, text_width};
use super::render::Canvas;
use crate::units;

const WHITE: [u8; 3] = [255, 255, 255];
const BLACK: [u8; 3] = [0, 0, 0];
const EDGE_GREY: [u8; 3] = [68, 68, 68];

/// Font scale for a picture whose longer side is `side` px: letters about 1/45 of the side
/// (16 px on a 700 px picture, 48 px on a 2048² one), at least 2 font pixels each.
fn font_scale(side: usize) -> usize {
    (side as f64 / 350.0).round().clamp(2.0, 12.0) as usize
}

/// `canvas` with its bars; `metres_per_px` (x, y) is the pixel size of `canvas` itself.
pub fn annotated(
    canvas: &Canvas,
    metres_per_px: Option<[f64; 2]>,
    colour: Option<&ColourBar>,
) -> Canvas {
    let scale = font_scale(canvas.width.max(canvas.height));
    let margin = colour.map_or(0, |bar| colour_bar_width(bar, scale));
    let mut out = Canvas::filled(canvas.width + margin, canvas.height, WHITE);
    out.paste(canvas, 0, 0);
    if let Some([x, _]) = metres_per_px.filter(|[x, y]| x.is_finite() && y.is_finite())
        && x > 0.0
    {
        draw_scale_bar(&mut out, canvas.width, canvas.height, x, scale);
    }
    if let Some(bar) = colour {
        draw_colour_bar(&mut out, canvas.width, bar, scale);
    }
    out
}

/// A white bar with a black outline and its length above it, at the bottom left.
fn draw_scale_bar(out: &mut Canvas, width: usize, height: usize, metres_per_px: f64, s: usize) {
    let length_m = nice_length(width as f64 * metres_per_px);
    let bar_px = (length_m / metres_per_px).round() as usize;
    let thickness = 3 * s;
    let (x, y) = (
        text_height(s) as i64,
        height as i64 - text_height(s) as i64 - thickness as i64,
    );
    out.fill_rect(x - 1, y - 1, bar_px + 2, thickness + 2, BLACK);
    out.fill_rect(x, y, bar_px, thickness, WHITE);
    let label = units::length(length_m);
    let label_x = x + bar_px as i64 / 2 - text_width(&label, s) as i64 / 2;
    let label_y = y - 2 * s as i64 - text_height(s) as i64;
    draw_text(
        out,
        &label,
        [label_x.max(x), label_y],
        s,
        WHITE,
        Some(BLACK),
    );
}

/// The three tick labels of a colour bar, low to high.
fn tick_labels(bar: &ColourBar) -> [(f64, String); 3] {
    let span = bar.high - bar.low;
    [
        (0.0, tick_label(bar.low, &bar.unit, span)),
        (0.5, tick_label(0.5 * (bar.low + bar.high), &bar.unit, span)),
        (1.0, tick_label(bar.high, &bar.unit, span)),
    ]
}

/// Width of the margin holding the colour bar, its ticks and labels, px.
fn colour_bar_width(bar: &ColourBar, s: usize) -> usize {
    let cell = text_height(s);
    let labels = tick_labels(bar)
        .iter()
        .map(|(_, label)| text_width(label, s))
        .max()
        .unwrap_or(0);
    let body = 2 * cell + cell / 2 + labels;
    cell + body.max(text_width(&bar.label, s)) + cell
}

/// The gradient (high at the top), three ticks with values, and what the colour shows.
fn draw_colour_bar(out: &mut Canvas, left: usize, bar: &ColourBar, s: usize) {
    let cell = text_height(s);
    let x = (left + cell) as i64;
    draw_text(out, &bar.label, [x, (cell / 2) as i64], s, BLACK, None);
    let (top, bottom) = (
        (2 * cell + cell / 2) as i64,
        out.height as i64 - cell as i64,
    );
    if bottom <= top {
        return;
    }
    let span = (bottom - top) as f64;
    for y in top..=bottom {
        let t = (bottom - y) as f64 / span;
        out.fill_rect(x, y, 2 * cell, 1, bar.colormap.rgb(t));
    }
    // Labels centred on their values' heights; no tick marks, which a bitmap font would
    // show as minus signs.
    for (t, label) in tick_labels(bar) {
        let y = bottom - (t * span).round() as i64;
        let text_y = (y - cell as i64 / 2).clamp(0, out.height as i64 - cell as i64);
        let text_x = x + 2 * cell as i64 + cell as i64 / 2;
        draw_text(out, &label, [text_x, text_y], s, BLACK, None);
    }
    out.fill_rect(
        x + 2 * cell as i64,
        top,
        1,
        (bottom - top + 1) as usize,
        EDGE_GREY,
    );
    out.fill_rect(x - 1, top, 1, (bottom - top + 1) as usize, EDGE_GREY);
}

#[cfg(test)]
mod tests {
    use dhct_sm4_io::png_file::Colormap;

    use super::*;

    #[test]
    fn the_png_gains_a_colour_bar_margin_and_a_scale_bar_only_with_a_pixel_size() {
        let picture = Canvas::filled(700, 500, [30, 60, 90]);
        let bar = ColourBar {
            colormap: Colormap::Viridis,
            low: -1e-10,
            high: 2e-10,
            unit: "m".into(),
            label: "height".into(),
        };
        let plain = annotated(&picture, None, None);
        assert_eq!((plain.width, plain.height), (700, 500));
        assert_eq!(
            plain.png(),
            picture.png(),
            "nothing to draw: the picture as it was"
        );
        let with_bars = annotated(&picture, Some([1e-11, 1e-11]), Some(&bar));
        assert!(with_bars.width > 700 + 100 && with_bars.height == 500);
        let scale_only = annotated(&picture, Some([1e-11, 1e-11]), None);
        assert_eq!(scale_only.width, 700);
        assert_ne!(scale_only.png(), picture.png(), "the scale bar is drawn");
    }
}
