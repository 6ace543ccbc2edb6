//! Every picture and plot of a `dhct correct` run, made once and used both as files in the
//! output directory and inside the report. Pictures carry a scale bar (when the pixel size
//! is stated) and a colour bar with units; plots are SVG.

use dhct_lattice::Lattice;
use dhct_pipeline::{Analysis, PassOutput};
use dhct_scan::{ImageChannel, ScanGeometry, ScanPair, ValueSource};
use dhct_sm4_io::png_file::Colormap;
use ndarray::Array2;
use rayon::prelude::*;

use super::annotated_png::annotated;
use super::bars::{ColourBar, picture_svg};
use super::plots::Plot;
use super::render::{Canvas, display_range, upscale_for};
use super::scatter::EqualAspectPlot;
use super::{lattice_average, local_figure, model_plots, overlays};

/// A figure: a picture (PNG file plus an annotated SVG) or a plot (SVG), with its file
/// stem and caption.
pub struct Figure {
    /// File stem in the output directory (`stem.png` / `stem.svg`).
    pub stem: String,
    /// Its title (the bold start of its caption in the report).
    pub title: String,
    /// What it shows, for the report.
    pub caption: String,
    /// The picture or plot.
    pub content: FigureContent,
}

/// What a figure holds.
pub enum FigureContent {
    /// A picture: the PNG file (full resolution, or reduced for views whose full
    /// resolution is another output; scale and colour bars drawn in) and the SVG shown in
    /// the report (a preview of it with the same bars as vector graphics).
    Picture {
        /// The PNG file's bytes.
        png: Vec<u8>,
        /// The annotated SVG document.
        svg: String,
    },
    /// A plot, SVG only.
    Plot(String),
}

/// How a picture is annotated and kept.
pub struct PictureStyle {
    /// Metres per canvas pixel (x, y), or `None` when the pixel size is not stated.
    pub metres_per_px: Option<[f64; 2]>,
    /// The colour bar, if the colours stand for values.
    pub colour: Option<ColourBar>,
    /// Longest side of the PNG file, px (`None`: full resolution).
    pub max_side: Option<usize>,
}

/// Longest side of the pictures kept only as views (raw, NCC, deviation map), px.
pub const REDUCED: usize = 1100;

/// Longest side of the previews inside the report (and their SVG files), px: about the
/// width a report column shows them at, so their scale and colour bars' text is drawn near
/// its own size and a 2048² run's report stays a few megabytes (the full-resolution
/// pictures are the files beside it).
pub const PREVIEW: usize = 600;

impl Figure {
    pub(crate) fn picture(
        stem: &str,
        title: &str,
        caption: String,
        canvas: &Canvas,
        style: PictureStyle,
    ) -> Figure {
        // A reduced copy's pixel averages `factor × factor` canvas pixels.
        let reduced_pitch = |max_side: usize| {
            let factor = canvas.reduction(max_side) as f64;
            style.metres_per_px.map(|[x, y]| [x * factor, y * factor])
        };
        let preview = canvas.preview(PREVIEW);
        let shown = preview.as_ref().unwrap_or(canvas);
        let svg = picture_svg(
            &shown.for_page(),
            shown.width,
            shown.height,
            reduced_pitch(PREVIEW),
            style.colour.as_ref(),
        );
        let max_side = style.max_side.unwrap_or(usize::MAX);
        let reduced = canvas.preview(max_side);
        let file = reduced.as_ref().unwrap_or(canvas);
        let png = annotated(file, reduced_pitch(max_side), style.colour.as_ref()).png();
        Figure {
            stem: stem.into(),
            title: title.into(),
            caption,
            content: FigureContent::Picture { png, svg },
        }
    }

    pub(crate) fn plot(stem: &str, title: &str, caption: String, plot: &Plot) -> Figure {
        Figure::from_svg(stem, title, caption, plot.svg(560, 360))
    }

    pub(crate) fn equal_aspect(
        stem: &str,
        title: &str,
        caption: String,
        plot: &EqualAspectPlot,
    ) -> Figure {
        Figure::from_svg(stem, title, caption, plot.svg(380.0, 380.0))
    }

    fn from_svg(stem: &str, title: &str, caption: String, svg: String) -> Figure {
        Figure {
            stem: stem.into(),
            title: title.into(),
            caption,
            content: FigureContent::Plot(svg),
        }
    }

    /// The SVG shown in the report.
    pub fn svg(&self) -> &str {
        match &self.content {
            FigureContent::Picture { svg, .. } | FigureContent::Plot(svg) => svg,
        }
    }

    /// The files of this figure: (name, bytes).
    pub fn files(&self) -> Vec<(String, &[u8])> {
        let svg = (format!("{}.svg", self.stem), self.svg().as_bytes());
        match &self.content {
            FigureContent::Picture { png, .. } => {
                vec![(format!("{}.png", self.stem), png.as_slice()), svg]
            }
            FigureContent::Plot(_) => vec![svg],
        }
    }
}

/// Metres per picture pixel of an image drawn at `scale` picture px per image pixel, or
/// `None` when the file states no pixel size (no scale bar is drawn then).
pub fn metres_per_picture_px(geometry: &ScanGeometry, scale: usize) -> Option<[f64; 2]> {
    (geometry.scale_source() == ValueSource::Stated).then(|| {
        let s = scale.max(1) as f64;
        [geometry.pitch_x() / s, geometry.pitch_y() / s]
    })
}

/// The colour bar of an image channel over `range`.
pub fn channel_colour_bar(
    channel: &ImageChannel,
    colormap: Colormap,
    range: Option<(f64, f64)>,
) -> Option<ColourBar> {
    let (low, high) = range?;
    Some(ColourBar {
        colormap,
        low,
        high,
        unit: channel.unit.clone(),
        label: if channel.unit == "m" {
            "height".into()
        } else {
            channel.name.clone()
        },
    })
}

/// What every figure job needs.
pub struct FigureInputs<'a> {
    /// The scan pair analysed.
    pub pair: &'a ScanPair,
    /// The lattice the run used.
    pub lattice: &'a (dyn Lattice + Sync),
    /// Every result of the run.
    pub analysis: &'a Analysis,
    /// The analysed area (true = used), raw-image pixels, if a mask was given.
    pub mask: Option<&'a Array2<bool>>,
    /// The colour map of the image pictures.
    pub colormap: Colormap,
}

/// One job makes one or more figures.
type Job<'a> = Box<dyn Fn() -> Vec<Figure> + Send + Sync + 'a>;

/// All figures, in report order; made in parallel (PNG encoding dominates).
pub fn make_figures(inputs: &FigureInputs) -> Vec<Figure> {
    let mut jobs: Vec<Job> = Vec::new();
    for pass in &inputs.analysis.passes {
        jobs.push(Box::new(move || image_figures(inputs, pass)));
    }
    for pass in &inputs.analysis.passes {
        jobs.push(Box::new(move || {
            ncc_figure(inputs, pass).into_iter().collect()
        }));
    }
    let analysis = inputs.analysis;
    let geometry = inputs.pair.geometry();
    jobs.push(Box::new(move || vec![model_plots::rdf_plot(analysis)]));
    jobs.push(Box::new(move || {
        model_plots::adf_plot(analysis).into_iter().collect()
    }));
    jobs.push(Box::new(move || {
        local_figure::local_distortion_figure(inputs)
            .into_iter()
            .collect()
    }));
    jobs.push(Box::new(move || {
        vec![model_plots::hysteresis_plot(geometry, analysis)]
    }));
    jobs.push(Box::new(move || model_plots::drift_plots(analysis)));
    jobs.push(Box::new(move || {
        analysis
            .regions
            .first()
            .map(model_plots::deviation_scatter)
            .into_iter()
            .collect()
    }));
    jobs.push(Box::new(move || vec![overlays::deviation_map(inputs)]));
    jobs.push(Box::new(move || {
        overlays::lattice_overlay(inputs).into_iter().collect()
    }));
    if analysis.unit_cell.is_some() {
        for symmetrized in [false, true] {
            jobs.push(Box::new(move || {
                overlays::cell_picture(inputs, symmetrized)
                    .into_iter()
                    .chain(lattice_average::lattice_average_picture(
                        inputs,
                        symmetrized,
                    ))
                    .collect()
            }));
        }
    }
    jobs.par_iter().flat_map_iter(|job| job()).collect()
}

/// The raw and the corrected image of one pass, on one colour scale.
fn image_figures(inputs: &FigureInputs, pass: &PassOutput) -> Vec<Figure> {
    let Some(raw) = inputs.pair.image(pass.pass) else {
        return Vec::new();
    };
    let geometry = inputs.pair.geometry();
    let scale = upscale_for(geometry.rows(), geometry.columns(), 512);
    let range = display_range(raw.z.view());
    let style = |max_side| PictureStyle {
        metres_per_px: metres_per_picture_px(geometry, scale),
        colour: channel_colour_bar(raw, inputs.colormap, range),
        max_side,
    };
    let mut canvas = Canvas::from_image(raw.z.view(), inputs.colormap, range, scale);
    if let Some(mask) = inputs.mask {
        canvas.dim_outside(mask, scale);
    }
    let size_note = match geometry.scale_source() {
        ValueSource::Stated => format!(
            "{} × {}",
            crate::units::length(geometry.width()),
            crate::units::length(geometry.height())
        ),
        ValueSource::Assumed => "pixel size not stated by the file (no scale bar)".into(),
    };
    let raw_figure = Figure::picture(
        &format!("raw_{}", pass.pass),
        &format!("Raw {} image", pass.pass),
        format!(
            "As acquired (controller frame), {} × {} px, {size_note}{}.",
            geometry.columns(),
            geometry.rows(),
            if inputs.mask.is_some() {
                "; greyed: outside the mask (not analysed)"
            } else {
                ""
            }
        ),
        &canvas,
        style(Some(REDUCED)),
    );
    let corrected = Figure::picture(
        &format!("corrected_{}", pass.pass),
        &format!("Corrected {} image", pass.pass),
        "Resampled onto the sample-frame grid with the fitted drift/creep/hysteresis model \
         (same pixel grid and colour scale as the raw image; z values are not altered; \
         magenta = no data)."
            .into(),
        &Canvas::from_image(pass.corrected_image.view(), inputs.colormap, range, scale),
        style(None),
    );
    vec![raw_figure, corrected]
}

/// The normalised cross-correlation map of one pass.
fn ncc_figure(inputs: &FigureInputs, pass: &PassOutput) -> Option<Figure> {
    let ncc = pass.correlation.as_ref()?;
    let geometry = inputs.pair.geometry();
    let scale = upscale_for(geometry.rows(), geometry.columns(), 512);
    Some(Figure::picture(
        &format!("ncc_{}", pass.pass),
        &format!("Normalised cross-correlation ({})", pass.pass),
        format!(
            "NCC with the Gaussian kernel (σ = {:.2} px); {} features found of {} candidates; \
             their fitted 1σ × {:.2} × {:.2} (x × y) for correlated pixel noise.",
            pass.features.kernel_sigma_px,
            pass.features.features.len(),
            pass.features.candidates,
            pass.features.correlated_noise_factor[0],
            pass.features.correlated_noise_factor[1]
        ),
        &Canvas::from_image(ncc.view(), Colormap::Viridis, Some((-1.0, 1.0)), scale),
        PictureStyle {
            metres_per_px: metres_per_picture_px(geometry, scale),
            colour: Some(ColourBar {
                colormap: Colormap::Viridis,
                low: -1.0,
                high: 1.0,
                unit: String::new(),
                label: "NCC".into(),
            }),
            max_side: Some(REDUCED),
        },
    ))
}
