//! The paper's Fig. 7: how the local distortion is measured. A detail of the raw image
//! (controller frame) with, at features apart from one another, the bonds to their nearest
//! neighbours, the local ellipse (the true nearest-neighbour circle as the measured local
//! map `J` shows it in the image, through the neighbours) and the local drift velocity as
//! an arrow.

use dhct_distortion::model::scan_basis;
use dhct_distortion::{LocalDistortion, PassAnalysis};
use dhct_scan::ScanGeometry;
use ndarray::s;

use super::detail::Detail;
use super::figures::{
    Figure, FigureInputs, PictureStyle, channel_colour_bar, metres_per_picture_px,
};
use super::overlays::{GREEN_PX as GREEN, OUTLINE, SKY, WHITE};
use super::render::{Canvas, display_range, upscale_for};

/// Side of the detail, nearest-neighbour distances.
const DETAIL_NN: f64 = 14.0;

/// Marked features stay this many nearest-neighbour distances apart.
const SPACING_NN: f64 = 3.0;

/// Fig. 7 for the first pass with local distortions, or `None` without any.
pub fn local_distortion_figure(inputs: &FigureInputs) -> Option<Figure> {
    let analysed = inputs
        .analysis
        .dhct
        .passes
        .iter()
        .find(|p| !p.local.is_empty())?;
    let geometry = inputs.pair.geometry();
    let raw = inputs.pair.image(analysed.pass)?;
    let nn_m = inputs.lattice.nearest_neighbour_distance();
    let window = Detail::central(geometry, DETAIL_NN * nn_m);
    let crop = raw.z.slice(s![window.r0..window.r1, window.c0..window.c1]);
    let scale = upscale_for(window.height(), window.width(), 640);
    let range = display_range(crop);
    let mut canvas = Canvas::from_image(crop, inputs.colormap, range, scale);
    let shown = marked_features(analysed, &window, nn_m / geometry.pitch_x());
    let arrow_per_speed = arrow_scale(&shown, nn_m / geometry.pitch_x());
    let to_canvas = |x: f64, y: f64| {
        [
            (x - window.c0 as f64 + 0.5) * scale as f64,
            (y - window.r0 as f64 + 0.5) * scale as f64,
        ]
    };
    let features = &inputs
        .analysis
        .passes
        .iter()
        .find(|p| p.pass == analysed.pass)?
        .features;
    for l in &shown {
        let centre = to_canvas(l.x_px, l.y_px);
        for &n in neighbours_of(analysed, l.index) {
            if let Some(f) = features.features.get(n) {
                canvas.line(centre, to_canvas(f.x_px, f.y_px), 2.0, WHITE);
            }
        }
        let ellipse = local_ellipse(l, geometry, analysed, nn_m);
        let points: Vec<[f64; 2]> = ellipse
            .iter()
            .map(|[x, y]| to_canvas(l.x_px + x, l.y_px + y))
            .collect();
        canvas.polygon(&points, 3.5, OUTLINE);
        canvas.polygon(&points, 2.0, SKY);
        let tip = [
            l.x_px + l.drift_m_per_s[0] * arrow_per_speed,
            l.y_px + l.drift_m_per_s[1] * arrow_per_speed,
        ];
        canvas.line(centre, to_canvas(tip[0], tip[1]), 4.0, OUTLINE);
        canvas.line(centre, to_canvas(tip[0], tip[1]), 2.5, GREEN);
        canvas.disc(to_canvas(tip[0], tip[1]), 4.0, GREEN);
    }
    let nn_speed_pm_s = (nn_m / geometry.pitch_x()) / arrow_per_speed * 1e12;
    Some(Figure::picture(
        "local_distortion",
        "Local distortion (paper Fig. 7)",
        format!(
            "Detail of the raw {} image (controller frame, columns {}–{}, rows {}–{}). At \
             features {SPACING_NN:.0} neighbour distances apart ({} of the {} measured): the \
             bonds to their nearest neighbours (white), the local ellipse — the true \
             neighbour circle as the local map measured there shows it in the image — \
             (sky blue), and the local drift velocity (green arrow; an arrow one \
             neighbour distance long is {:.2} pm/s).",
            analysed.pass,
            window.c0,
            window.c1,
            window.r0,
            window.r1,
            shown.len(),
            analysed.local.len(),
            nn_speed_pm_s
        ),
        &canvas,
        PictureStyle {
            metres_per_px: metres_per_picture_px(geometry, scale),
            colour: channel_colour_bar(raw, inputs.colormap, range),
            max_side: None,
        },
    ))
}

/// Local distortions inside `window` (a neighbour distance from its edge), greedily kept
/// [`SPACING_NN`] neighbour distances (`nn_px`) apart.
fn marked_features<'a>(
    pass: &'a PassAnalysis,
    window: &Detail,
    nn_px: f64,
) -> Vec<&'a LocalDistortion> {
    let mut kept: Vec<&LocalDistortion> = Vec::new();
    for l in &pass.local {
        let far = kept
            .iter()
            .all(|k| (k.x_px - l.x_px).hypot(k.y_px - l.y_px) >= SPACING_NN * nn_px);
        if far && window.contains(l.x_px, l.y_px, 1.2 * nn_px) {
            kept.push(l);
        }
    }
    kept
}

/// Pixels per (m/s) of the drift arrows: the largest shown speed is 1.5 neighbour
/// distances long.
fn arrow_scale(shown: &[&LocalDistortion], nn_px: f64) -> f64 {
    let fastest = shown
        .iter()
        .map(|l| l.drift_m_per_s[0].hypot(l.drift_m_per_s[1]))
        .filter(|v| v.is_finite())
        .fold(0.0, f64::max);
    if fastest > 0.0 {
        1.5 * nn_px / fastest
    } else {
        0.0
    }
}

/// The neighbours the local distortion of feature `index` was measured with.
fn neighbours_of(pass: &PassAnalysis, index: usize) -> &[usize] {
    let selection = pass.refined_selection.as_ref().unwrap_or(&pass.selection);
    selection
        .selected
        .iter()
        .find(|s| s.index == index)
        .map_or(&[], |s| s.neighbours.as_slice())
}

/// The true neighbour circle (radius `nn_m`) mapped into the image by the inverse of the
/// local map `J` (sample per controller, scan basis): offsets in image pixels.
fn local_ellipse(
    l: &LocalDistortion,
    geometry: &ScanGeometry,
    pass: &PassAnalysis,
    nn_m: f64,
) -> Vec<[f64; 2]> {
    let (fast, slow) = scan_basis(geometry, pass.pass);
    let j = nalgebra::Matrix2::new(
        l.jacobian[0][0],
        l.jacobian[0][1],
        l.jacobian[1][0],
        l.jacobian[1][1],
    );
    let Some(inverse) = j.try_inverse() else {
        return Vec::new();
    };
    (0..48)
        .map(|k| {
            let angle = k as f64 / 48.0 * std::f64::consts::TAU;
            let (dx, dy) = (nn_m * angle.cos(), nn_m * angle.sin());
            let sample =
                nalgebra::Vector2::new(dx * fast[0] + dy * fast[1], dx * slow[0] + dy * slow[1]);
            let c = inverse * sample;
            let x = c.x * fast[0] + c.y * slow[0];
            let y = c.x * fast[1] + c.y * slow[1];
            [x / geometry.pitch_x(), y / geometry.pitch_y()]
        })
        .collect()
}
