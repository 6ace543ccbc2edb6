//! Text drawn into a [`Canvas`] with the 8 × 8 bitmap font of `font8x8` (public domain),
//! each font pixel drawn as `scale × scale` picture pixels: letters for the standalone PNGs,
//! which carry their scale and colour bars without a font renderer.

use font8x8::{BASIC_FONTS, LATIN_FONTS, UnicodeFonts};

use super::render::Canvas;

/// Width and height of one character cell, in font pixels.
const CELL: usize = 8;

/// The glyph of `c`: ASCII and Latin-1 (µ, Å, °, ±, ²) as they are; the typographic minus
/// as a hyphen; anything else as `?`.
fn glyph(c: char) -> [u8; 8] {
    let c = if c == '−' { '-' } else { c };
    BASIC_FONTS
        .get(c)
        .or_else(|| LATIN_FONTS.get(c))
        .or_else(|| BASIC_FONTS.get('?'))
        .unwrap_or([0; 8])
}

/// Width of `text` drawn at `scale`, px.
pub fn text_width(text: &str, scale: usize) -> usize {
    text.chars().count() * CELL * scale
}

/// Height of a line of text drawn at `scale`, px.
pub fn text_height(scale: usize) -> usize {
    CELL * scale
}

/// Draws `text` with its top-left corner at (`x`, `y`) in `colour`; with `outline`, a
/// one-font-pixel halo of that colour first, so the text reads on any picture.
pub fn draw_text(
    canvas: &mut Canvas,
    text: &str,
    [x, y]: [i64; 2],
    scale: usize,
    colour: [u8; 3],
    outline: Option<[u8; 3]>,
) {
    let s = scale.max(1) as i64;
    if let Some(halo) = outline {
        for (dx, dy) in [
            (-1, 0),
            (1, 0),
            (0, -1),
            (0, 1),
            (-1, -1),
            (1, 1),
            (-1, 1),
            (1, -1),
        ] {
            draw_glyphs(canvas, text, [x + dx * s, y + dy * s], s, halo);
        }
    }
    draw_glyphs(canvas, text, [x, y], s, colour);
}

fn draw_glyphs(canvas: &mut Canvas, text: &str, [x, y]: [i64; 2], s: i64, colour: [u8; 3]) {
    for (k, c) in text.chars().enumerate() {
        let left = x + k as i64 * CELL as i64 * s;
        for (row, bits) in glyph(c).iter().enumerate() {
            for column in 0..CELL {
                if bits & (1 << column) != 0 {
                    let (px, py) = (left + column as i64 * s, y + row as i64 * s);
                    canvas.fill_rect(px, py, s as usize, s as usize, colour);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn letters_are_drawn_where_asked_and_unknown_characters_are_visible() {
        let mut canvas = Canvas::filled(40, 12, [255, 255, 255]);
        draw_text(&mut canvas, "1µ", [2, 2], 1, [0, 0, 0], None);
        let inked = canvas.png();
        assert_ne!(inked, Canvas::filled(40, 12, [255, 255, 255]).png());
        assert_eq!(text_width("1µ", 3), 48);
        assert_ne!(
            glyph('Å'),
            glyph('?'),
            "Latin-1 letters have their own glyphs"
        );
        assert_eq!(glyph('−'), glyph('-'));
        assert_eq!(glyph('☃'), glyph('?'));
    }
}
