//! Plots whose x and y share a unit, drawn at equal aspect: one data unit is the same
//! number of pixels along both axes. The data area is a nested `<svg>` whose `viewBox` is
//! the data range and whose size is that range times one scale, so a circle of the data is
//! a circle on screen (checkable from the SVG alone). +y points down, as in the images
//! (x = column, y = row), so a shape has the orientation it has in the pictures.

use plotters::style::RGBColor;

use super::page::escape;
use super::plots::{nice_ticks, tick_text};

/// A curve drawn over the points (e.g. a confidence ellipse).
pub struct Curve {
    /// The legend entry.
    pub label: String,
    /// (x, y) along the curve, data units.
    pub points: Vec<(f64, f64)>,
    /// Its colour.
    pub colour: RGBColor,
    /// Dashed instead of solid.
    pub dashed: bool,
}

/// A scatter plot at equal aspect.
pub struct EqualAspectPlot {
    /// The title above the plot.
    pub title: String,
    /// The x axis label, with the shared unit.
    pub x_label: String,
    /// The y axis label, with the shared unit.
    pub y_label: String,
    /// The legend entry of the points.
    pub points_label: String,
    /// (x, y) of each point, data units (+y down).
    pub points: Vec<(f64, f64)>,
    /// The points' colour.
    pub points_colour: RGBColor,
    /// Curves drawn over the points.
    pub curves: Vec<Curve>,
}

/// Margins around the data area, px: left (y ticks and label), top (title), right
/// (legend), bottom (x ticks and label).
const LEFT: f64 = 70.0;
const TOP: f64 = 30.0;
const RIGHT: f64 = 150.0;
const BOTTOM: f64 = 46.0;

/// The data range (x0, x1, y0, y1) of every finite point, padded by 6 %, never empty.
fn data_range(plot: &EqualAspectPlot) -> [f64; 4] {
    let all = plot
        .points
        .iter()
        .chain(plot.curves.iter().flat_map(|c| c.points.iter()))
        .filter(|(x, y)| x.is_finite() && y.is_finite());
    let mut r = [
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    ];
    for &(x, y) in all {
        r = [r[0].min(x), r[1].max(x), r[2].min(y), r[3].max(y)];
    }
    if !r.iter().all(|v| v.is_finite()) {
        return [-1.0, 1.0, -1.0, 1.0];
    }
    let pad = 0.06 * (r[1] - r[0]).max(r[3] - r[2]).max(1e-12);
    [r[0] - pad, r[1] + pad, r[2] - pad, r[3] + pad]
}

impl EqualAspectPlot {
    /// The plot as an SVG document whose data area fits `max_width × max_height` px.
    pub fn svg(&self, max_width: f64, max_height: f64) -> String {
        let [x0, x1, y0, y1] = data_range(self);
        // One scale for both axes: data units per pixel.
        let per_px = ((x1 - x0) / max_width).max((y1 - y0) / max_height);
        let (w, h) = ((x1 - x0) / per_px, (y1 - y0) / per_px);
        let (total_w, total_h) = (LEFT + w + RIGHT, TOP + h + BOTTOM);
        let to_px = |x: f64, y: f64| (LEFT + (x - x0) / per_px, TOP + (y - y0) / per_px);
        let mut svg = format!(
            "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{total_w:.0}\" height=\"{total_h:.0}\" \
             viewBox=\"0 0 {total_w:.0} {total_h:.0}\" font-family=\"sans-serif\">\
             <rect width=\"100%\" height=\"100%\" fill=\"white\"/>\
             <text x=\"{:.1}\" y=\"18\" text-anchor=\"middle\" font-size=\"15\">{}</text>",
            LEFT + w / 2.0,
            escape(&self.title)
        );
        svg.push_str(&self.axes([x0, x1, y0, y1], (w, h), &to_px));
        // The data area: viewBox in data units (+y down, like SVG and the images), one scale.
        svg.push_str(&format!(
            "<svg class=\"data-area\" x=\"{LEFT}\" y=\"{TOP}\" width=\"{w:.4}\" height=\"{h:.4}\" \
             viewBox=\"{x0:e} {y0:e} {sx:e} {sy:e}\" preserveAspectRatio=\"none\" overflow=\"hidden\">",
            sx = x1 - x0,
            sy = y1 - y0,
        ));
        let [r, g, b] = [
            self.points_colour.0,
            self.points_colour.1,
            self.points_colour.2,
        ];
        svg.push_str(&format!(
            "<g fill=\"rgb({r},{g},{b})\" fill-opacity=\"0.5\">"
        ));
        for &(x, y) in self
            .points
            .iter()
            .filter(|(x, y)| x.is_finite() && y.is_finite())
        {
            svg.push_str(&format!(
                "<circle cx=\"{x:e}\" cy=\"{y:e}\" r=\"{:e}\"/>",
                2.0 * per_px
            ));
        }
        svg.push_str("</g>");
        for curve in &self.curves {
            svg.push_str(&curve_path(curve));
        }
        svg.push_str("</svg>");
        svg.push_str(&self.legend(LEFT + w + 12.0));
        svg.push_str("</svg>");
        svg
    }

    /// Frame, ticks, tick labels and axis labels in page pixels.
    fn axes(
        &self,
        [x0, x1, y0, y1]: [f64; 4],
        (w, h): (f64, f64),
        to_px: &dyn Fn(f64, f64) -> (f64, f64),
    ) -> String {
        let mut svg = format!(
            "<rect x=\"{LEFT}\" y=\"{TOP}\" width=\"{w:.2}\" height=\"{h:.2}\" fill=\"none\" stroke=\"#333\"/>"
        );
        for x in nice_ticks(x0, x1, 6) {
            let (px, _) = to_px(x, y0);
            svg.push_str(&format!(
                "<line x1=\"{px:.2}\" y1=\"{TOP}\" x2=\"{px:.2}\" y2=\"{b:.2}\" stroke=\"#eee\"/>\
                 <line x1=\"{px:.2}\" y1=\"{b:.2}\" x2=\"{px:.2}\" y2=\"{b5:.2}\" stroke=\"#333\"/>\
                 <text x=\"{px:.2}\" y=\"{t:.2}\" text-anchor=\"middle\" font-size=\"11\">{}</text>",
                tick_text(x),
                b = TOP + h,
                b5 = TOP + h + 5.0,
                t = TOP + h + 18.0,
            ));
        }
        for y in nice_ticks(y0, y1, 6) {
            let (_, py) = to_px(x0, y);
            svg.push_str(&format!(
                "<line x1=\"{LEFT}\" y1=\"{py:.2}\" x2=\"{r:.2}\" y2=\"{py:.2}\" stroke=\"#eee\"/>\
                 <line x1=\"{l5}\" y1=\"{py:.2}\" x2=\"{LEFT}\" y2=\"{py:.2}\" stroke=\"#333\"/>\
                 <text x=\"{t}\" y=\"{ty:.2}\" text-anchor=\"end\" font-size=\"11\">{}</text>",
                tick_text(y),
                r = LEFT + w,
                l5 = LEFT - 5.0,
                t = LEFT - 8.0,
                ty = py + 4.0,
            ));
        }
        svg.push_str(&format!(
            "<text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"middle\" font-size=\"13\">{}</text>\
             <text transform=\"translate(16 {:.1}) rotate(-90)\" text-anchor=\"middle\" font-size=\"13\">{}</text>",
            LEFT + w / 2.0,
            TOP + h + 38.0,
            escape(&self.x_label),
            TOP + h / 2.0,
            escape(&self.y_label)
        ));
        svg
    }

    fn legend(&self, x: f64) -> String {
        let mut svg = String::from("<g class=\"legend\" font-size=\"12\">");
        let c = self.points_colour;
        svg.push_str(&format!(
            "<circle cx=\"{:.1}\" cy=\"{:.1}\" r=\"3\" fill=\"rgb({},{},{})\"/><text x=\"{:.1}\" y=\"{:.1}\">{}</text>",
            x + 10.0,
            TOP + 10.0,
            c.0,
            c.1,
            c.2,
            x + 26.0,
            TOP + 14.0,
            escape(&self.points_label)
        ));
        for (k, curve) in self.curves.iter().enumerate() {
            let y = TOP + 30.0 + 20.0 * k as f64;
            let c = curve.colour;
            svg.push_str(&format!(
                "<line x1=\"{x:.1}\" y1=\"{y:.1}\" x2=\"{:.1}\" y2=\"{y:.1}\" stroke=\"rgb({},{},{})\" \
                 stroke-width=\"2\"{}/><text x=\"{:.1}\" y=\"{:.1}\">{}</text>",
                x + 20.0,
                c.0,
                c.1,
                c.2,
                if curve.dashed { " stroke-dasharray=\"5 3\"" } else { "" },
                x + 26.0,
                y + 4.0,
                escape(&curve.label)
            ));
        }
        svg.push_str("</g>");
        svg
    }
}

/// A curve as a polyline in data units, drawn 2 px wide at any scale.
fn curve_path(curve: &Curve) -> String {
    let points: Vec<String> = curve
        .points
        .iter()
        .filter(|(x, y)| x.is_finite() && y.is_finite())
        .map(|(x, y)| format!("{x:e},{y:e}"))
        .collect();
    let c = curve.colour;
    format!(
        "<polyline points=\"{}\" fill=\"none\" stroke=\"rgb({},{},{})\" stroke-width=\"2\" \
         vector-effect=\"non-scaling-stroke\"{}/>",
        points.join(" "),
        c.0,
        c.1,
        c.2,
        if curve.dashed {
            " stroke-dasharray=\"5 3\""
        } else {
            ""
        }
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The attribute `name` of the first element that has class `class`.
    fn attribute(svg: &str, class: &str, name: &str) -> String {
        let start = svg.find(&format!("class=\"{class}\"")).unwrap();
        let element = &svg[svg[..start].rfind('<').unwrap()..];
        let element = &element[..element.find('>').unwrap()];
        let key = format!(" {name}=\"");
        let from = element.find(&key).unwrap() + key.len();
        element[from..from + element[from..].find('"').unwrap()].to_string()
    }

    #[test]
    fn one_data_unit_is_the_same_length_along_x_and_y() {
        // A wide cloud: 100 × 10 data units.
        let plot = EqualAspectPlot {
            title: "t".into(),
            x_label: "Δx (pm)".into(),
            y_label: "Δy (pm)".into(),
            points_label: "p".into(),
            points: vec![(-50.0, -5.0), (50.0, 5.0)],
            points_colour: RGBColor(0, 0, 0),
            curves: vec![],
        };
        let svg = plot.svg(400.0, 400.0);
        let view_box: Vec<f64> = attribute(&svg, "data-area", "viewBox")
            .split(' ')
            .map(|v| v.parse().unwrap())
            .collect();
        let width: f64 = attribute(&svg, "data-area", "width").parse().unwrap();
        let height: f64 = attribute(&svg, "data-area", "height").parse().unwrap();
        let (x_scale, y_scale) = (view_box[2] / width, view_box[3] / height);
        assert!(
            (x_scale / y_scale - 1.0).abs() < 1e-6,
            "{x_scale} vs {y_scale}"
        );
        assert!(width > 5.0 * height, "{width} x {height}");
    }
}
