//! Line and scatter plots as SVG (plotters' SVG backend: text needs no font files), embedded
//! directly in the report. Colours are Okabe–Ito (distinguishable with colour-vision
//! deficiency); raw and corrected versions of one curve differ by dash, not only hue.

use plotters::prelude::*;

/// How a series is drawn.
#[derive(Clone, Copy)]
pub enum Style {
    /// A solid line through the points.
    Line,
    /// A dashed line (e.g. the raw version of a curve drawn solid when corrected).
    Dashed,
    /// A marker at each point, no line.
    Points,
    /// Vertical bars from zero (histograms).
    Bars,
}

/// One data series.
pub struct Series {
    /// The legend entry.
    pub label: String,
    /// (x, y) in the axes' units.
    pub points: Vec<(f64, f64)>,
    /// How it is drawn.
    pub style: Style,
    /// Its colour.
    pub colour: RGBColor,
}

impl Series {
    /// A series of the finite ones of `points`.
    pub fn new(
        label: impl Into<String>,
        points: Vec<(f64, f64)>,
        style: Style,
        colour: RGBColor,
    ) -> Series {
        Series {
            label: label.into(),
            points: points
                .into_iter()
                .filter(|(x, y)| x.is_finite() && y.is_finite())
                .collect(),
            style,
            colour,
        }
    }
}

/// A plot: axes, series, optional vertical marker lines.
pub struct Plot {
    /// The title above the plot.
    pub title: String,
    /// The x axis label, with its unit.
    pub x_label: String,
    /// The y axis label, with its unit.
    pub y_label: String,
    /// The series, drawn in order.
    pub series: Vec<Series>,
    /// x positions of grey vertical marker lines (e.g. fitted RDF shells), x axis units.
    pub vertical_lines: Vec<f64>,
}

/// Colours that stay distinguishable for colour-blind readers (Okabe–Ito).
pub const BLUE: RGBColor = RGBColor(0, 114, 178);
/// Okabe–Ito orange.
pub const ORANGE: RGBColor = RGBColor(230, 159, 0);
/// Okabe–Ito bluish green.
pub const GREEN: RGBColor = RGBColor(0, 158, 115);
/// Okabe–Ito vermilion.
pub const VERMILION: RGBColor = RGBColor(213, 94, 0);
/// Okabe–Ito sky blue.
pub const SKY_BLUE: RGBColor = RGBColor(86, 180, 233);
/// Okabe–Ito reddish purple.
pub const REDDISH_PURPLE: RGBColor = RGBColor(204, 121, 167);
/// Fitted curves over measured points.
pub const INK: RGBColor = RGBColor(0, 0, 0);
/// Vertical marker lines.
pub const GREY: RGBColor = RGBColor(120, 120, 120);

/// A tick label: at most four decimals, trailing zeros dropped, a true minus sign.
pub fn tick_text(value: f64) -> String {
    let text = format!("{:.4}", if value.abs() < 1e-12 { 0.0 } else { value });
    let text = text.trim_end_matches('0').trim_end_matches('.');
    text.replace('-', "−")
}

/// About `n` round tick values (1, 2 or 5 × 10^k apart) inside `low..=high`.
pub fn nice_ticks(low: f64, high: f64, n: usize) -> Vec<f64> {
    if !(low.is_finite() && high.is_finite() && high > low) || n == 0 {
        return Vec::new();
    }
    let raw = (high - low) / n as f64;
    let power = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * power)
        .find(|&s| s >= raw)
        .unwrap_or(10.0 * power);
    let first = (low / step).ceil() as i64;
    let last = (high / step).floor() as i64;
    (first..=last).map(|k| k as f64 * step).collect()
}

/// At most `n` evenly spaced points (scatter plots of tens of thousands of features stay
/// small in the report).
pub fn thin(points: Vec<(f64, f64)>, n: usize) -> Vec<(f64, f64)> {
    if points.len() <= n {
        return points;
    }
    let step = points.len() as f64 / n as f64;
    (0..n).map(|i| points[(i as f64 * step) as usize]).collect()
}

fn padded(low: f64, high: f64) -> (f64, f64) {
    if !(low.is_finite() && high.is_finite()) {
        return (0.0, 1.0);
    }
    if high > low {
        let pad = 0.04 * (high - low);
        (low - pad, high + pad)
    } else {
        let pad = if low == 0.0 { 1.0 } else { 0.05 * low.abs() };
        (low - pad, high + pad)
    }
}

impl Plot {
    /// An empty plot with its title and axis labels.
    pub fn new(title: &str, x_label: &str, y_label: &str) -> Plot {
        Plot {
            title: title.into(),
            x_label: x_label.into(),
            y_label: y_label.into(),
            series: Vec::new(),
            vertical_lines: Vec::new(),
        }
    }

    /// The plot with `series` added.
    pub fn with(mut self, series: Series) -> Plot {
        self.series.push(series);
        self
    }

    /// The plot as an SVG document (`width × height` px), or a short SVG saying why not.
    pub fn svg(&self, width: u32, height: u32) -> String {
        let mut out = String::new();
        if let Err(e) = self.draw(&mut out, width, height) {
            return format!(
                "<svg xmlns='http://www.w3.org/2000/svg' width='{width}' height='40'><text x='4' y='20'>plot failed: {}</text></svg>",
                super::page::escape(&e)
            );
        }
        out
    }

    /// The padded data range (x0, x1, y0, y1); bars start at zero.
    fn ranges(&self) -> (f64, f64, f64, f64) {
        let (mut x0, mut x1, mut y0, mut y1) = (
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        );
        for &(x, y) in self.series.iter().flat_map(|s| s.points.iter()) {
            x0 = x0.min(x);
            x1 = x1.max(x);
            y0 = y0.min(y);
            y1 = y1.max(y);
        }
        if self.series.iter().any(|s| matches!(s.style, Style::Bars)) {
            y0 = y0.min(0.0);
        }
        let (x0, x1) = padded(x0, x1);
        let (y0, y1) = padded(y0, y1);
        (x0, x1, y0, y1)
    }

    fn draw(&self, out: &mut String, width: u32, height: u32) -> Result<(), String> {
        let (x0, x1, y0, y1) = self.ranges();
        let e = |e: &dyn std::fmt::Display| e.to_string();
        let root = SVGBackend::with_string(out, (width, height)).into_drawing_area();
        root.fill(&WHITE).map_err(|x| e(&x))?;
        let mut chart = ChartBuilder::on(&root)
            .caption(&self.title, ("sans-serif", 16))
            .margin(8)
            .x_label_area_size(38)
            .y_label_area_size(64)
            .build_cartesian_2d(x0..x1, y0..y1)
            .map_err(|x| e(&x))?;
        chart
            .configure_mesh()
            .x_desc(&self.x_label)
            .y_desc(&self.y_label)
            .light_line_style(WHITE.mix(0.0))
            .label_style(("sans-serif", 12))
            .x_label_formatter(&|v| tick_text(*v))
            .y_label_formatter(&|v| tick_text(*v))
            .draw()
            .map_err(|x| e(&x))?;
        for &x in &self.vertical_lines {
            chart
                .draw_series(LineSeries::new(
                    vec![(x, y0), (x, y1)],
                    GREY.mix(0.6).stroke_width(1),
                ))
                .map_err(|x| e(&x))?;
        }
        for series in &self.series {
            draw_series(&mut chart, series)?;
        }
        if self.series.len() > 1 {
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK.mix(0.3))
                .label_font(("sans-serif", 12))
                .position(SeriesLabelPosition::UpperRight)
                .draw()
                .map_err(|x| e(&x))?;
        }
        root.present().map_err(|x| e(&x))?;
        Ok(())
    }
}

type Chart<'a, 'b> = ChartContext<
    'a,
    SVGBackend<'b>,
    Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
>;

/// One series in its style, with its legend entry.
fn draw_series(chart: &mut Chart, s: &Series) -> Result<(), String> {
    let e = |e: &dyn std::fmt::Display| e.to_string();
    let colour = s.colour;
    let legend = move |(x, y): (i32, i32)| {
        PathElement::new(vec![(x, y), (x + 16, y)], colour.stroke_width(2))
    };
    match s.style {
        Style::Line => chart
            .draw_series(LineSeries::new(
                s.points.iter().copied(),
                colour.stroke_width(2),
            ))
            .map_err(|x| e(&x))?
            .label(&s.label)
            .legend(legend),
        Style::Dashed => chart
            .draw_series(DashedLineSeries::new(
                s.points.iter().copied(),
                6,
                4,
                colour.stroke_width(2),
            ))
            .map_err(|x| e(&x))?
            .label(&s.label)
            .legend(move |(x, y): (i32, i32)| {
                PathElement::new(vec![(x, y), (x + 6, y)], colour.stroke_width(2))
            }),
        Style::Points => chart
            .draw_series(
                s.points
                    .iter()
                    .map(|&(x, y)| Circle::new((x, y), 2, colour.mix(0.5).filled())),
            )
            .map_err(|x| e(&x))?
            .label(&s.label)
            .legend(legend),
        Style::Bars => {
            let half = if s.points.len() > 1 {
                0.5 * (s.points[1].0 - s.points[0].0).abs()
            } else {
                0.5
            };
            chart
                .draw_series(s.points.iter().map(|&(x, y)| {
                    Rectangle::new([(x - half, 0.0), (x + half, y)], colour.mix(0.8).filled())
                }))
                .map_err(|x| e(&x))?
                .label(&s.label)
                .legend(legend)
        }
    };
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn svg_has_title_series_and_survives_nan() {
        let plot = Plot::new("RDF <test>", "r (Å)", "g(r)")
            .with(Series::new(
                "raw",
                vec![(0.0, 0.0), (1.0, 2.0), (f64::NAN, 1.0)],
                Style::Line,
                BLUE,
            ))
            .with(Series::new(
                "corrected",
                vec![(0.5, 1.0)],
                Style::Points,
                ORANGE,
            ));
        let svg = plot.svg(400, 300);
        assert!(svg.starts_with("<svg"), "{}", &svg[..50.min(svg.len())]);
        assert!(svg.contains("corrected"));
        assert_eq!(tick_text(35.0), "35");
        assert_eq!(tick_text(-0.25), "−0.25");
        assert_eq!(nice_ticks(0.0, 10.0, 5), [0.0, 2.0, 4.0, 6.0, 8.0, 10.0]);
        assert_eq!(nice_ticks(-0.3, 0.3, 3), [-0.2, 0.0, 0.2]);
        assert!(nice_ticks(1.0, 1.0, 4).is_empty());
        // An empty plot still renders.
        assert!(Plot::new("empty", "x", "y").svg(200, 100).contains("<svg"));
    }
}
