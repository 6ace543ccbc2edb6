//! Pictures as SVG documents: the PNG embedded, a scale bar (when the picture has a
//! physical pixel size) and a colour bar with its unit, so every picture says how large it
//! is and what its colours mean.

use base64::Engine as _;
use dhct_sm4_io::png_file::Colormap;

use super::page::escape;
use super::render::EncodedPicture;
use crate::units;

/// What a picture's colours mean: `colormap` maps `low..=high` (in `unit`) to its ends.
#[derive(Clone)]
pub struct ColourBar {
    /// The colour map.
    pub colormap: Colormap,
    /// The value at the map's low end, `unit`.
    pub low: f64,
    /// The value at the map's high end, `unit`.
    pub high: f64,
    /// Unit of `low`/`high` as stored (e.g. `m`, or empty for dimensionless values).
    pub unit: String,
    /// What the colour shows (e.g. `height`, `NCC`).
    pub label: String,
}

/// Width added on the right for a colour bar, px.
const COLOUR_BAR_MARGIN: usize = 104;

/// `picture` (a `width × height` px picture, embedded once with SVG 2's `href`) as an SVG
/// document of the same pixel size plus a colour bar margin; `metres_per_px` (x, y of the
/// embedded picture) adds a scale bar.
pub fn picture_svg(
    picture: &EncodedPicture,
    width: usize,
    height: usize,
    metres_per_px: Option<[f64; 2]>,
    colour: Option<&ColourBar>,
) -> String {
    let total_width = width
        + if colour.is_some() {
            COLOUR_BAR_MARGIN
        } else {
            0
        };
    let data = base64::engine::general_purpose::STANDARD.encode(&picture.bytes);
    let mime = picture.mime;
    let mut svg = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{total_width}\" height=\"{height}\" viewBox=\"0 0 {total_width} {height}\" \
         font-family=\"sans-serif\"><rect width=\"100%\" height=\"100%\" fill=\"white\"/>\
         <image class=\"picture\" x=\"0\" y=\"0\" width=\"{width}\" height=\"{height}\" \
         preserveAspectRatio=\"none\" href=\"data:{mime};base64,{data}\"/>"
    );
    if let Some([x, _]) = metres_per_px.filter(|[x, y]| x.is_finite() && y.is_finite())
        && x > 0.0
    {
        svg.push_str(&scale_bar(width, height, x));
    }
    if let Some(colour) = colour {
        svg.push_str(&colour_bar(width, height, colour));
    }
    svg.push_str("</svg>");
    svg
}

/// A 1-, 2- or 5-times-a-power-of-ten length near a fifth of `span`.
pub fn nice_length(span: f64) -> f64 {
    let target = span / 5.0;
    let power = 10f64.powf(target.log10().floor());
    [5.0, 2.0, 1.0]
        .into_iter()
        .map(|m| m * power)
        .find(|&l| l <= target)
        .unwrap_or(power)
}

/// A white bar with a dark outline and its length at the bottom left.
fn scale_bar(width: usize, height: usize, metres_per_px: f64) -> String {
    let length_m = nice_length(width as f64 * metres_per_px);
    let bar_px = length_m / metres_per_px;
    let (x, y) = (12.0, height as f64 - 14.0);
    let label = escape(&units::length(length_m));
    format!(
        "<g class=\"scale-bar\" data-length-m=\"{length_m:e}\" data-length-px=\"{bar_px:.3}\">\
         <rect x=\"{x}\" y=\"{y}\" width=\"{bar_px:.2}\" height=\"5\" fill=\"white\" \
         stroke=\"black\" stroke-width=\"1\"/><text x=\"{tx:.1}\" y=\"{ty}\" \
         text-anchor=\"middle\" font-size=\"15\" fill=\"white\" stroke=\"black\" \
         stroke-width=\"3\" paint-order=\"stroke\">{label}</text></g>",
        tx = x + bar_px / 2.0,
        ty = y - 5.0,
    )
}

/// A vertical gradient right of the picture with the values of its ends and middle.
fn colour_bar(width: usize, height: usize, bar: &ColourBar) -> String {
    let (x, top, bottom) = (width as f64 + 12.0, 22.0, height as f64 - 10.0);
    let stops: String = (0..=16)
        .map(|k| {
            let t = k as f64 / 16.0;
            let [r, g, b] = bar.colormap.rgb(t);
            // Offsets run top (high) to bottom (low).
            format!(
                "<stop offset=\"{:.4}\" stop-color=\"rgb({r},{g},{b})\"/>",
                1.0 - t
            )
        })
        .rev()
        .collect();
    let mut svg = format!(
        "<g class=\"colour-bar\"><defs><linearGradient id=\"cb-{id}\" x1=\"0\" y1=\"0\" x2=\"0\" \
         y2=\"1\">{stops}</linearGradient></defs><text x=\"{x}\" y=\"15\" font-size=\"14\">{label}</text>\
         <rect x=\"{x}\" y=\"{top}\" width=\"14\" height=\"{h:.1}\" fill=\"url(#cb-{id})\" \
         stroke=\"#444\" stroke-width=\"0.8\"/>",
        id = gradient_id(bar),
        label = escape(&bar.label),
        h = bottom - top,
    );
    for (t, value) in [
        (0.0, bar.low),
        (0.5, 0.5 * (bar.low + bar.high)),
        (1.0, bar.high),
    ] {
        let y = bottom - t * (bottom - top);
        svg.push_str(&format!(
            "<line x1=\"{x2:.1}\" y1=\"{y:.1}\" x2=\"{x3:.1}\" y2=\"{y:.1}\" stroke=\"#444\"/>\
             <text x=\"{tx:.1}\" y=\"{ty:.1}\" font-size=\"13\">{}</text>",
            escape(&tick_label(value, &bar.unit, bar.high - bar.low)),
            x2 = x + 14.0,
            x3 = x + 18.0,
            tx = x + 21.0,
            ty = y + 4.0,
        ));
    }
    svg.push_str("</g>");
    svg
}

/// A value for a colour-bar tick on a bar spanning `span`: lengths in pm (or nm), other
/// units with an SI prefix, values without a unit by [`plain_tick`].
pub(super) fn tick_label(value: f64, unit: &str, span: f64) -> String {
    let text = match unit {
        "m" if value.abs() < 1e-9 => units::picometres(value),
        "m" => units::length(value),
        "" | "1" => plain_tick(value, span),
        other => units::si(value, other),
    };
    text.replace('-', "−")
}

/// A value without a unit on a bar spanning `span`: two decimals where they tell the ticks
/// apart, else in scientific notation with the digits that do (heights saved in metres
/// without a unit, e.g. an NPY array, span ~1e-9: two decimals printed them all 0.00).
fn plain_tick(value: f64, span: f64) -> String {
    let span = span.abs();
    if (span >= 0.05 && value.abs() < 1e5) || !(span > 0.0 && span.is_finite()) {
        return format!("{value:.2}");
    }
    // Enough significant digits that a tenth of the span shows.
    let digits = ((value.abs().max(span) / span).log10().floor() + 1.0).clamp(2.0, 8.0) as usize;
    format!("{value:.digits$e}")
}

/// A gradient id unique to the bar's appearance (pages hold several SVGs).
fn gradient_id(bar: &ColourBar) -> String {
    format!(
        "{}-{:x}",
        bar.colormap.name(),
        (bar.low.to_bits() ^ bar.high.to_bits().rotate_left(17)) & 0xffff_ffff
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scale_bars_are_round_lengths_and_colour_bars_carry_units() {
        assert_eq!(nice_length(10e-9), 2e-9);
        assert_eq!(nice_length(30e-9), 5e-9);
        assert!((nice_length(4e-9) - 5e-10).abs() < 1e-24);
        let bar = ColourBar {
            colormap: Colormap::Viridis,
            low: -1e-10,
            high: 2e-10,
            unit: "m".into(),
            label: "height".into(),
        };
        let png = |bytes: &[u8]| EncodedPicture {
            bytes: bytes.to_vec(),
            mime: "image/png",
        };
        let svg = picture_svg(&png(b"png"), 400, 300, Some([2.5e-11, 2.5e-11]), Some(&bar));
        assert!(
            svg.contains("class=\"scale-bar\"") && svg.contains("2 nm"),
            "{svg}"
        );
        assert!(
            svg.contains("class=\"colour-bar\"") && svg.contains("200.0 pm"),
            "{svg}"
        );
        assert!(svg.contains("−100.0 pm"), "{svg}");
        // No physical size: no scale bar.
        assert!(!picture_svg(&png(b"png"), 40, 30, None, None).contains("scale-bar"));
    }

    /// Values without a unit keep what tells the ticks apart: heights of an array saved in
    /// metres (no unit) printed 0.00 at every tick.
    #[test]
    fn ticks_without_a_unit_show_what_tells_them_apart() {
        let (low, high) = (-1.957e-9, 2.469e-9);
        let labels: Vec<String> = [low, 0.5 * (low + high), high]
            .iter()
            .map(|v| tick_label(*v, "", high - low))
            .collect();
        assert_eq!(labels, ["−1.96e−9", "2.56e−10", "2.47e−9"]);
        assert_eq!(tick_label(0.25, "", 1.0), "0.25");
        assert_eq!(tick_label(-3.5, "1", 10.0), "−3.50");
        // A small span around a large value: the digits that show a tenth of it.
        assert_eq!(tick_label(1000.25, "", 0.01), "1.000250e3");
        assert_eq!(tick_label(1.0, "", 0.0), "1.00");
    }
}
