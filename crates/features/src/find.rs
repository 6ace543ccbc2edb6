//! The feature-finding pipeline: preprocess → NCC → watershed → area filter → Gaussian fits
//! → edge and duplicate checks → acquisition times.

use std::time::Instant;

use dhct_scan::{ImageChannel, ScanGeometry, ScanPair, ScanPass};
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use ndarray::{Array2, ArrayView2};
use rayon::prelude::*;

use crate::gaussian_fit::{FitLimits, FitShape, GaussianFit, fit_gaussian};
use crate::levelling::lattice_levels::{
    LineLevels, lattice_line_levels, levels_as_recorded, replace_line_levels, subtract_line_levels,
};
use crate::levelling::line_relevel::{WindowPixels, relevel, window_pixels};
use crate::levelling::preprocess::{correct_lines_in_place, sign_flattened_in_place};
use crate::levelling::removed_levels::{RemovedLevels, drop_on_steps};
use crate::ncc::NccPlan;
use crate::noise_correlation::measured_centre_variance_ratio;
use crate::watershed::{MAX_WATERSHED_PIXELS, Region, watershed_regions};
use crate::{
    Feature, FeatureError, FeatureOptions, FeatureSet, FitStatus, Kernel, KernelChoice,
    LineCorrection, LineLevelling, Polarity, RejectedCandidate, Rejection, RejectionCounts,
    StageTimings,
};

/// Minimum region area (px) counted when taking the median area (DHCT's 10 px).
const MIN_AREA_FOR_MEDIAN: usize = 10;

/// Finds and fits every feature of one image. `mask` (true = use), if given, restricts the
/// background fit only; features are found everywhere.
pub fn find_features(
    image: &ImageChannel,
    geometry: &ScanGeometry,
    pass: ScanPass,
    options: &FeatureOptions,
    mask: Option<&Array2<bool>>,
) -> Result<FeatureSet, FeatureError> {
    find_features_and_correlation(image, geometry, pass, options, mask).map(|(set, _)| set)
}

/// Finds features in every image of a pair, trace and retrace in parallel up to 4096² px
/// and one after the other above (sharing the kernel and the correlation plan).
pub fn find_features_in_pair(
    pair: &ScanPair,
    options: &FeatureOptions,
) -> Result<Vec<FeatureSet>, FeatureError> {
    find_features_in_pair_and_correlation(pair, options, None)
        .map(|sets| sets.into_iter().map(|(set, _)| set).collect())
}

/// Like [`find_features_in_pair`], also returning each image's normalised cross-correlation
/// map; `mask` (true = use), if given, restricts the background fit as in [`find_features`].
pub fn find_features_in_pair_and_correlation(
    pair: &ScanPair,
    options: &FeatureOptions,
    mask: Option<&Array2<bool>>,
) -> Result<Vec<(FeatureSet, Array2<f64>)>, FeatureError> {
    let geometry = pair.geometry();
    let prepared = Prepared::new(geometry, options)?;
    let run = |pass| {
        pair.image(pass)
            .map(|image| find_prepared(image, geometry, pass, options, mask, &prepared))
    };
    let (trace, retrace) = if geometry.rows() * geometry.columns() <= PARALLEL_PASSES_MAX_PIXELS {
        rayon::join(|| run(ScanPass::Trace), || run(ScanPass::Retrace))
    } else {
        // Each stage runs in parallel within an image; one image at a time halves the
        // working memory of a huge scan.
        (run(ScanPass::Trace), run(ScanPass::Retrace))
    };
    trace.into_iter().chain(retrace).collect()
}

/// Largest image (pixels) whose trace and retrace are processed at the same time (4096²):
/// above it, one image at a time (each stage still parallel within the image) bounds the
/// working memory of a huge scan.
pub const PARALLEL_PASSES_MAX_PIXELS: usize = 1 << 24;

/// Like [`find_features`], also returning the normalised cross-correlation map.
pub fn find_features_and_correlation(
    image: &ImageChannel,
    geometry: &ScanGeometry,
    pass: ScanPass,
    options: &FeatureOptions,
    mask: Option<&Array2<bool>>,
) -> Result<(FeatureSet, Array2<f64>), FeatureError> {
    let prepared = Prepared::new(geometry, options)?;
    find_prepared(image, geometry, pass, options, mask, &prepared)
}

/// What is the same for every image of one geometry: the checked options, the kernel, the
/// nearest-neighbour distance in pixels and the correlation plan.
struct Prepared {
    kernel: Kernel,
    kernel_sigma_px: f64,
    nn_px: f64,
    plan: NccPlan,
}

impl Prepared {
    fn new(geometry: &ScanGeometry, options: &FeatureOptions) -> Result<Prepared, FeatureError> {
        if !(options.threshold.is_finite() && (-1.0..1.0).contains(&options.threshold)) {
            return Err(FeatureError::BadParameter(format!(
                "NCC threshold must lie in [-1, 1), got {}",
                options.threshold
            )));
        }
        if !(options.fit_radius_fraction.is_finite()
            && (0.1..=1.0).contains(&options.fit_radius_fraction))
        {
            return Err(FeatureError::BadParameter(format!(
                "fit radius fraction must lie in [0.1, 1] of the NN distance, got {}",
                options.fit_radius_fraction
            )));
        }
        if !(options.duplicate_fraction.is_finite() && options.duplicate_fraction >= 0.0) {
            return Err(FeatureError::BadParameter(
                "duplicate fraction must be ≥ 0".into(),
            ));
        }
        let d = options.neighbour_distance;
        if !(d.is_finite() && d > 0.0) {
            return Err(FeatureError::BadParameter(format!(
                "nearest-neighbour distance must be a positive length in metres, got {d}"
            )));
        }
        let pitch = (geometry.pitch_x() * geometry.pitch_y()).sqrt();
        let nn_px = d / pitch;
        let (kernel, kernel_sigma_px) = match &options.kernel {
            KernelChoice::FromNeighbourDistance {} => {
                let k = Kernel::for_neighbour_distance(nn_px)?;
                let s = (nn_px / 2.0).round().max(1.0) / 2.0;
                (k, s)
            }
            KernelChoice::GaussianSigma { sigma_px } => {
                (Kernel::gaussian(*sigma_px)?, (2.0 * sigma_px).round() / 2.0)
            }
            KernelChoice::FractionOfNeighbourDistance { fraction } => {
                let sigma_px = fraction * nn_px;
                (Kernel::gaussian(sigma_px)?, (2.0 * sigma_px).round() / 2.0)
            }
            KernelChoice::Custom { kernel } => (kernel.clone(), f64::NAN),
        };
        let (kh, kw) = kernel.values().dim();
        let (rows, columns) = (geometry.rows(), geometry.columns());
        if rows < kh || columns < kw {
            return Err(FeatureError::ImageTooSmall {
                columns,
                rows,
                kernel: kh.max(kw),
            });
        }
        let plan = NccPlan::with_strip_rows(rows, columns, &kernel, options.correlation_strip_rows);
        Ok(Prepared {
            kernel,
            kernel_sigma_px,
            nn_px,
            plan,
        })
    }
}

/// Wall clock for the stages of one search.
struct Stopwatch(Instant);

impl Stopwatch {
    fn start() -> Stopwatch {
        Stopwatch(Instant::now())
    }

    /// Stores the seconds since the previous lap (or the start) in `slot`.
    fn lap(&mut self, slot: &mut f64) {
        let now = Instant::now();
        *slot = (now - self.0).as_secs_f64();
        self.0 = now;
    }
}

/// The image made ready for the correlation and the fits.
struct Preprocessed {
    /// +1 for bright features, −1 for dark: the flattened image was multiplied by it.
    sign: f64,
    /// Lines corrected, background removed, times `sign` (NaN where data are missing).
    signed: Array2<f64>,
    /// `signed` with its missing pixels set to its median; `None` if none were missing.
    filled: Option<Array2<f64>>,
    /// For [`LineCorrection::Lattice`]: background removed and times `sign`, lines as
    /// recorded (`signed` is it median-levelled, for the correlation).
    unlevelled: Option<Array2<f64>>,
}

/// What every region's Gaussian fit shares (pixels).
struct FitWindow {
    /// Radius of the fit disc around a region's peak.
    radius: f64,
    /// `(row, column)` offsets of the pixels within `radius` of the peak.
    offsets: Vec<(i64, i64)>,
    /// Starting width σ of the Gaussian.
    sigma_start: f64,
    /// Nearest-neighbour distance (the upper width bound).
    nn_px: f64,
}

/// A fitted region that passed the status and edge checks.
struct Candidate {
    fit: GaussianFit,
    pixel_count: usize,
    ncc_peak: f64,
}

/// Finds and fits the features of one image with the kernel and correlation plan of
/// `prepared`: checks, preprocessing, correlation, segmentation, Gaussian fits, screening
/// and bookkeeping (each stage timed). Also returns the correlation map.
fn find_prepared(
    image: &ImageChannel,
    geometry: &ScanGeometry,
    pass: ScanPass,
    options: &FeatureOptions,
    mask: Option<&Array2<bool>>,
    prepared: &Prepared,
) -> Result<(FeatureSet, Array2<f64>), FeatureError> {
    check_sizes(image, geometry, mask)?;
    let (rows, columns) = image.z.dim();
    let (kh, kw) = prepared.kernel.values().dim();
    let finite = count_finite(image, kh * kw)?;
    let mut timings = StageTimings::default();
    let mut clock = Stopwatch::start();
    let mut pre = preprocess(image, geometry, options, mask, finite)?;
    clock.lap(&mut timings.preprocess_s);
    let mut ncc = prepared
        .plan
        .apply(pre.filled.as_ref().unwrap_or(&pre.signed).view());
    clock.lap(&mut timings.correlation_s);

    // `signed`: the image the features' heights are read from (polarity applied).
    let segment =
        |ncc: &Array2<f64>, signed: &Array2<f64>, rejected: &mut Vec<RejectedCandidate>| {
            let regions = watershed_regions(ncc, options.threshold);
            let candidates = regions.len();
            let tracked = (options.min_relative_height > 0.0 && signed.dim() == ncc.dim())
                .then(|| tracked_kind(&regions, signed, options.min_relative_height));
            (
                area_filter(
                    regions,
                    options.area_filter,
                    columns,
                    tracked.as_deref(),
                    rejected,
                ),
                candidates,
            )
        };
    let mut rejected = Vec::new();
    let (mut kept, mut candidates) = segment(&ncc, &pre.signed, &mut rejected);
    clock.lap(&mut timings.segmentation_s);

    let window = fit_window(options, prepared);
    let (mut fits, removed) = if options.line_correction == LineCorrection::Lattice {
        // The median-levelled image served the correlation; the fits see another.
        drop(std::mem::take(&mut pre.signed));
        let unlevelled = pre.unlevelled.take().unwrap_or_default();
        let first = match levelled_across_steps(&unlevelled, geometry, &kept, &ncc, &window) {
            AcrossSteps::Levelled(levelled) => {
                // Medians across a step level neighbouring lines to different terraces, and
                // the correlation with them: it is taken again on the lines cut at the steps.
                ncc = prepared.plan.apply(filled_for_correlation(levelled).view());
                rejected.clear();
                (kept, candidates) = segment(&ncc, &unlevelled, &mut rejected);
                None
            }
            AcrossSteps::NoStep(first) => Some(first),
        };
        let fit = RegionFit {
            kept: &kept,
            ncc: &ncc,
            window: &window,
        };
        let (signed, fits, removed) = level_against_lattice(unlevelled, geometry, &fit, first);
        pre.signed = signed;
        (fits, removed)
    } else {
        let removed = RemovedLevels::none(geometry.fast_axis(), f64::NAN);
        (fit_regions(&kept, &pre.signed, &ncc, &window), removed)
    };
    if options.line_levels_from_fits {
        relevel_fits(&kept, &mut fits, &pre.signed, &window, geometry.fast_axis());
    }
    clock.lap(&mut timings.fitting_s);

    let noise_factor = raise_for_correlated_noise(&mut fits, &pre.signed, &window, geometry);
    let edge_margin = (kh.max(kw) / 2) as f64;
    let accepted = screen_fits(
        &kept,
        fits,
        (rows, columns),
        edge_margin,
        &ncc,
        &mut rejected,
    );
    let duplicates = mark_duplicates(&accepted, options.duplicate_fraction * prepared.nn_px)?;
    let mut features = assemble_features(
        accepted,
        duplicates,
        geometry,
        (pass, pre.sign),
        &removed,
        &mut rejected,
    );
    drop_shallow(&mut features, options.min_relative_height, &mut rejected);
    drop_on_steps(&mut features, &removed, window.radius, &mut rejected);
    features.sort_by(|a, b| a.time_s.total_cmp(&b.time_s));
    for (id, f) in features.iter_mut().enumerate() {
        f.id = id;
    }
    check_found(&features, pass, candidates, options, &rejected)?;
    let line_levelling = match options.line_correction {
        LineCorrection::Lattice => removed.levelling(OFFSET_EVIDENCE),
        other => LineLevelling::as_requested(other),
    };
    clock.lap(&mut timings.bookkeeping_s);
    Ok((
        FeatureSet {
            pass,
            features,
            rejected,
            candidates,
            kernel_sigma_px: prepared.kernel_sigma_px,
            correlated_noise_factor: noise_factor,
            line_levelling,
            timings,
        },
        ncc,
    ))
}

/// Checks that the image has its geometry's size and the mask, if any, the image's.
fn check_sizes(
    image: &ImageChannel,
    geometry: &ScanGeometry,
    mask: Option<&Array2<bool>>,
) -> Result<(), FeatureError> {
    let (rows, columns) = image.z.dim();
    if rows != geometry.rows() || columns != geometry.columns() {
        return Err(FeatureError::BadParameter(format!(
            "image is {columns} x {rows} px but its geometry says {} x {} px",
            geometry.columns(),
            geometry.rows()
        )));
    }
    if rows * columns >= MAX_WATERSHED_PIXELS {
        return Err(FeatureError::BadParameter(format!(
            "image is {columns} x {rows} px; feature finding takes fewer than \
             {MAX_WATERSHED_PIXELS} px"
        )));
    }
    if mask.is_some_and(|m| m.dim() != image.z.dim()) {
        return Err(FeatureError::BadParameter(
            "mask size differs from the image size".into(),
        ));
    }
    Ok(())
}

/// The number of finite pixels; an error if fewer than half the image or four kernels'
/// worth (`kernel_len` pixels each) are finite, or if the image is flat.
fn count_finite(image: &ImageChannel, kernel_len: usize) -> Result<usize, FeatureError> {
    let (rows, columns) = image.z.dim();
    // Missing data: NaN pixels are excluded from fits and filled for the correlation.
    let (finite, low, high) = image.z.iter().filter(|v| v.is_finite()).fold(
        (0usize, f64::INFINITY, f64::NEG_INFINITY),
        |(n, lo, hi), &v| (n + 1, lo.min(v), hi.max(v)),
    );
    if finite < (rows * columns) / 2 || finite < 4 * kernel_len {
        return Err(FeatureError::MissingData {
            finite,
            total: rows * columns,
        });
    }
    if low == high {
        return Err(FeatureError::FlatImage);
    }
    Ok(finite)
}

/// Line correction, background removal (fitted where `mask` is true) and the polarity
/// sign; fills missing pixels with the median for the correlation when fewer than all
/// pixels are `finite`.
fn preprocess(
    image: &ImageChannel,
    geometry: &ScanGeometry,
    options: &FeatureOptions,
    mask: Option<&Array2<bool>>,
    finite: usize,
) -> Result<Preprocessed, FeatureError> {
    let (rows, columns) = image.z.dim();
    let mut signed = image.z.clone();
    let unlevelled = if options.line_correction == LineCorrection::Lattice {
        sign_flattened_in_place(&mut signed, options, mask)?;
        let unlevelled = signed.clone();
        correct_lines_in_place(&mut signed, geometry.fast_axis(), LineCorrection::Median);
        Some(unlevelled)
    } else {
        correct_lines_in_place(&mut signed, geometry.fast_axis(), options.line_correction);
        sign_flattened_in_place(&mut signed, options, mask)?;
        None
    };
    let sign = match options.polarity {
        Polarity::Bright => 1.0,
        Polarity::Dark => -1.0,
    };
    // The correlation needs every pixel: fill missing ones (only if any).
    let filled = (finite < rows * columns).then(|| filled_for_correlation(signed.clone()));
    Ok(Preprocessed {
        sign,
        signed,
        filled,
        unlevelled,
    })
}

/// `image` with its missing pixels set to the median of the others (the correlation needs
/// every pixel).
fn filled_for_correlation(mut image: Array2<f64>) -> Array2<f64> {
    let mut values: Vec<f64> = image.iter().copied().filter(|v| v.is_finite()).collect();
    if values.len() == image.len() || values.is_empty() {
        return image;
    }
    let middle = values.len() / 2;
    let fill = *values.select_nth_unstable_by(middle, f64::total_cmp).1;
    image.mapv_inplace(|v| if v.is_finite() { v } else { fill });
    image
}

/// What the first levels of the lines as recorded found.
enum AcrossSteps {
    /// A height step within some line (and line offsets to level): the image with its
    /// lines levelled, cut at the steps.
    Levelled(Array2<f64>),
    /// No step, or no line offsets to level: the levels, which are the first levels
    /// [`level_against_lattice`] takes (the same image and peaks).
    NoStep(LineLevels),
}

/// The lines of `unlevelled` levelled against the lattice around the correlation's peaks
/// of the `kept` regions.
fn levelled_across_steps(
    unlevelled: &Array2<f64>,
    geometry: &ScanGeometry,
    kept: &[Region],
    ncc: &Array2<f64>,
    window: &FitWindow,
) -> AcrossSteps {
    let fast_axis = geometry.fast_axis();
    let peaks = correlation_peaks(kept, ncc);
    let first = lattice_line_levels(unlevelled.view(), &peaks, window.nn_px, fast_axis);
    if first.offsets_over_noise < OFFSET_EVIDENCE || first.levels.iter().all(|l| l.steps() == 0) {
        return AcrossSteps::NoStep(first);
    }
    let mut levelled = unlevelled.clone();
    subtract_line_levels(&mut levelled, &first.levels, fast_axis);
    AcrossSteps::Levelled(levelled)
}

/// The sub-pixel correlation peak `(x, y)` px of each region.
fn correlation_peaks(kept: &[Region], ncc: &Array2<f64>) -> Vec<[f64; 2]> {
    let columns = ncc.dim().1;
    kept.iter()
        .map(|region| {
            let (x, y) = subpixel_peak(ncc, region.peak / columns, region.peak % columns);
            [x, y]
        })
        .collect()
}

/// The fit disc and starting width for this search.
fn fit_window(options: &FeatureOptions, prepared: &Prepared) -> FitWindow {
    let nn_px = prepared.nn_px;
    let sigma_start = if prepared.kernel_sigma_px.is_finite() {
        prepared.kernel_sigma_px
    } else {
        nn_px / 4.0
    };
    // Each region identifies one feature; the fit uses a disc of radius 0.4·NN (by default) around the
    // region's peak, so the pixel set is symmetric about the feature (a watershed basin's
    // shape depends on tie-breaking at saddles and would bias the centre).
    let radius = (options.fit_radius_fraction * nn_px).max(2.0);
    let offsets: Vec<(i64, i64)> = {
        let reach = radius.ceil() as i64;
        (-reach..=reach)
            .flat_map(|dr| (-reach..=reach).map(move |dc| (dr, dc)))
            .filter(|&(dr, dc)| ((dr * dr + dc * dc) as f64) <= radius * radius)
            .collect()
    };
    FitWindow {
        radius,
        offsets,
        sigma_start,
        nn_px,
    }
}

/// Fits a Gaussian to each region's disc of `signed` (in parallel, in region order),
/// returning each fit with the number of finite pixels it used.
fn fit_regions(
    kept: &[Region],
    signed: &Array2<f64>,
    ncc: &Array2<f64>,
    window: &FitWindow,
) -> Vec<RegionFitResult> {
    fit_regions_from(kept, signed, ncc, window, None)
}

/// [`fit_regions`] started from `previous` fits of the same regions where those are
/// usable (a refit after a small change of the image converges in fewer steps).
fn refit_regions(
    kept: &[Region],
    signed: &Array2<f64>,
    ncc: &Array2<f64>,
    window: &FitWindow,
    previous: &[RegionFitResult],
) -> Vec<RegionFitResult> {
    fit_regions_from(kept, signed, ncc, window, Some(previous))
}

/// [`fit_regions`], each region started from its `previous` fit when there is a usable one.
fn fit_regions_from(
    kept: &[Region],
    signed: &Array2<f64>,
    ncc: &Array2<f64>,
    window: &FitWindow,
    previous: Option<&[RegionFitResult]>,
) -> Vec<RegionFitResult> {
    let z_values = signed.as_standard_layout();
    let z_values = z_values.view();
    kept.par_iter()
        .enumerate()
        .map(|(i, region)| {
            let warm = previous
                .map(|p| &p[i].0)
                .filter(|fit| is_usable(fit.status));
            fit_region(region, z_values, ncc, window, warm)
        })
        .collect()
}

/// Fits one region: an elliptical Gaussian to the finite pixels of the disc around its
/// peak, started at the correlation's sub-pixel peak (or at `warm`'s centre and width),
/// retried as circular if the ellipse came out of shape.
fn fit_region(
    region: &Region,
    z_values: ArrayView2<f64>,
    ncc: &Array2<f64>,
    window: &FitWindow,
    warm: Option<&GaussianFit>,
) -> (GaussianFit, usize) {
    let columns = z_values.dim().1;
    let (peak_row, peak_col) = (
        (region.peak / columns) as i64,
        (region.peak % columns) as i64,
    );
    let WindowPixels { xs, ys, zs } = window_pixels(z_values, region.peak, &window.offsets);
    let (x, y) = (peak_col as f64, peak_row as f64);
    let start = warm.map_or_else(
        || subpixel_peak(ncc, peak_row as usize, peak_col as usize),
        |f| (f.x0, f.y0),
    );
    let limits = FitLimits {
        x_range: (x - window.radius, x + window.radius),
        y_range: (y - window.radius, y + window.radius),
        sigma_range: (0.25, window.nn_px.max(1.0)),
        max_iterations: 100,
        shape: FitShape::Elliptical,
    };
    let sigma_start = warm.map_or(window.sigma_start, |f| {
        (f.sigma_major * f.sigma_minor).sqrt()
    });
    let mut fit = fit_gaussian(&xs, &ys, &zs, start, sigma_start, &limits);
    if fit.status == FitStatus::BadShape {
        // Noise (e.g. scan-line streaks) can pull a free ellipse out of shape; a
        // round atom is still well described by a circular Gaussian.
        let circular = FitLimits {
            shape: FitShape::Circular,
            ..limits
        };
        let retry = fit_gaussian(&xs, &ys, &zs, start, sigma_start, &circular);
        if matches!(
            retry.status,
            FitStatus::Converged | FitStatus::IterationLimit
        ) {
            fit = GaussianFit {
                status: FitStatus::ConvergedCircular,
                ..retry
            };
        }
    }
    (fit, xs.len())
}

/// A region's fit and the number of finite pixels it used.
type RegionFitResult = (GaussianFit, usize);

/// What refitting the regions needs.
struct RegionFit<'a> {
    kept: &'a [Region],
    ncc: &'a Array2<f64>,
    window: &'a FitWindow,
}

/// Lattice levelling has converged when the levels taken around the fitted centres move
/// by less than this fraction of the fits' median residual (their pixel noise). A level
/// shared along a whole line moves the centres across the lines far more than its size
/// next to pixel noise suggests. Measured on the effect-free `rendered-dev` scans (384²,
/// 2–8 pm line offsets, 20 scans): the second levels moved by 0.04–0.09, the third by
/// 0.01–0.03, the fourth by ≤ 0.01; refitting until below 0.04 brought the centres' y
/// scatter about the truth from 1.424 to 1.404 pm on average and the diagnosis's
/// effect-free gaps from at most 1.20 to at most 1.10 (at 0.1, the earlier tolerance, no
/// refit followed the second levels there; at 0.02, 1.403 pm). The 2048² headline's second
/// levels move by 0.03: refitting there changed its corrected rms vs truth by 0.8 %
/// (1.925 → 1.910 pm) for 0.3 s.
const LEVEL_TOLERANCE: f64 = 0.04;

/// Rounds of "level around the fitted centres, refit" at most.
const MAX_LEVEL_ROUNDS: usize = 3;

/// The lines are levelled only when their levels vary from line to line by more than this
/// many times what pixel noise alone gives ([`crate::levelling::lattice_levels::LineLevels`]).
/// Measured: 0.9–1.6 on clean simulations, 18–111 on the real HOPG, Pb/Pt(111) and TiSe₂
/// files.
const OFFSET_EVIDENCE: f64 = 4.0;

/// Levels the lines of `signed` (background removed, sign applied, lines as recorded)
/// against the lattice modelled around the correlation's peaks, fits the regions, then
/// levels again around the fitted centres and refits until those levels move by less than
/// [`LEVEL_TOLERANCE`] of the pixel noise (at most [`MAX_LEVEL_ROUNDS`] times;
/// [`crate::levelling::lattice_levels`]). When the first
/// levels show no line offsets beyond pixel noise ([`OFFSET_EVIDENCE`]) the lines are
/// left as recorded. `first`: those first levels when already taken (of `signed` around
/// the same peaks, [`levelled_across_steps`]). Returns the image the final fits saw and
/// the fits.
fn level_against_lattice(
    mut signed: Array2<f64>,
    geometry: &ScanGeometry,
    fit: &RegionFit,
    first: Option<LineLevels>,
) -> (Array2<f64>, Vec<RegionFitResult>, RemovedLevels) {
    let (nn_px, fast_axis) = (fit.window.nn_px, geometry.fast_axis());
    let first = first.unwrap_or_else(|| {
        let peaks = correlation_peaks(fit.kept, fit.ncc);
        lattice_line_levels(signed.view(), &peaks, nn_px, fast_axis)
    });
    if first.offsets_over_noise < OFFSET_EVIDENCE {
        // No line offsets beyond what pixel noise gives: levelling would only add noise
        // shared along each line, so the lines stay as they were recorded.
        let fits = fit_regions(fit.kept, &signed, fit.ncc, fit.window);
        let removed = RemovedLevels::none(fast_axis, first.offsets_over_noise);
        return (signed, fits, removed);
    }
    subtract_line_levels(&mut signed, &first.levels, fast_axis);
    let first_evidence = first.offsets_over_noise;
    let mut levels = first;
    let mut fits = fit_regions(fit.kept, &signed, fit.ncc, fit.window);
    for _ in 0..MAX_LEVEL_ROUNDS {
        let centres: Vec<[f64; 2]> = fits
            .iter()
            .filter(|(f, _)| is_usable(f.status))
            .map(|(f, _)| [f.x0, f.y0])
            .collect();
        // Every round levels the lines as recorded, so each finds the whole of every step.
        let again = levels_as_recorded(signed.view(), &levels.levels, &centres, nn_px, fast_axis);
        let moved: Vec<f64> = (again.typical().iter().zip(levels.typical()))
            .map(|(a, b)| a - b)
            .collect();
        let change = dhct_numerics::moments::rms_about_mean_1d(&moved);
        replace_line_levels(&mut signed, &levels.levels, &again.levels, fast_axis);
        levels = again;
        let noise = dhct_numerics::robust::finite_median(fits.iter().map(|(f, _)| f.residual_rms));
        if noise.is_some_and(|noise| change <= LEVEL_TOLERANCE * noise) {
            break;
        }
        fits = refit_regions(fit.kept, &signed, fit.ncc, fit.window, &fits);
    }
    let removed = RemovedLevels {
        fast_axis,
        levels: levels.levels,
        offsets_over_noise: first_evidence,
    };
    (signed, fits, removed)
}

/// Multiplies the usable fits' centre uncertainties by how much more their centres
/// scatter under the image's correlated pixel noise than white noise gives
/// ([`crate::noise_correlation`]), per axis and never below 1. Returns the factors
/// `[x, y]` applied (1 when they cannot be measured).
fn raise_for_correlated_noise(
    fits: &mut [RegionFitResult],
    signed: &Array2<f64>,
    window: &FitWindow,
    geometry: &ScanGeometry,
) -> [f64; 2] {
    let usable: Vec<GaussianFit> = fits
        .iter()
        .map(|f| f.0)
        .filter(|f| is_usable(f.status))
        .collect();
    let lines_along_rows = geometry.fast_axis() == dhct_scan::Axis::Horizontal;
    let ratio = measured_centre_variance_ratio(
        signed.view(),
        &usable,
        &window.offsets,
        window.nn_px,
        lines_along_rows,
    );
    let factor = ratio.map_or([1.0; 2], |r| r.map(|v| v.sqrt().max(1.0)));
    for (fit, _) in fits.iter_mut().filter(|f| is_usable(f.0.status)) {
        fit.x0_sigma *= factor[0];
        fit.y0_sigma *= factor[1];
    }
    factor
}

/// Whether a fit's centre can be used (converged, or stopped at the iteration limit).
fn is_usable(status: FitStatus) -> bool {
    matches!(
        status,
        FitStatus::Converged | FitStatus::IterationLimit | FitStatus::ConvergedCircular
    )
}

/// Moves the usable fits' centres for the scan-line levels fitted jointly with them
/// ([`crate::levelling::line_relevel`]).
fn relevel_fits(
    kept: &[Region],
    fits: &mut [(GaussianFit, usize)],
    signed: &Array2<f64>,
    window: &FitWindow,
    fast_axis: dhct_scan::Axis,
) {
    let z = signed.as_standard_layout();
    let usable: Vec<usize> = (0..fits.len())
        .filter(|&i| is_usable(fits[i].0.status))
        .collect();
    let mut peaked: Vec<(GaussianFit, usize)> =
        usable.iter().map(|&i| (fits[i].0, kept[i].peak)).collect();
    relevel(z.view(), &mut peaked, &window.offsets, fast_axis);
    for (&i, (fit, _)) in usable.iter().zip(peaked) {
        fits[i].0.x0 = fit.x0;
        fits[i].0.y0 = fit.y0;
    }
}

/// Rejects the fits that failed, hit a bound, came out of shape or whose centre lies
/// within `edge_margin` px of the border of an image of `(rows, columns)`; the rest become
/// candidates carrying their region's correlation peak.
fn screen_fits(
    kept: &[Region],
    fits: Vec<(GaussianFit, usize)>,
    (rows, columns): (usize, usize),
    edge_margin: f64,
    ncc: &Array2<f64>,
    rejected: &mut Vec<RejectedCandidate>,
) -> Vec<Candidate> {
    let mut accepted = Vec::new();
    for (region, (fit, pixel_count)) in kept.iter().zip(fits) {
        let reason = match fit.status {
            FitStatus::Failed => Some(Rejection::FitFailed),
            FitStatus::CentreOnBound => Some(Rejection::CentreOnBound),
            FitStatus::BadShape => Some(Rejection::BadShape),
            FitStatus::Converged | FitStatus::IterationLimit | FitStatus::ConvergedCircular => {
                let inside = fit.x0 >= edge_margin
                    && fit.y0 >= edge_margin
                    && fit.x0 <= (columns - 1) as f64 - edge_margin
                    && fit.y0 <= (rows - 1) as f64 - edge_margin;
                (!inside).then_some(Rejection::EdgeCut)
            }
        };
        match reason {
            Some(reason) => rejected.push(RejectedCandidate {
                x_px: fit.x0,
                y_px: fit.y0,
                reason,
            }),
            None => accepted.push(Candidate {
                fit,
                pixel_count,
                ncc_peak: ncc.as_slice().map_or(f64::NAN, |s| s[region.peak]),
            }),
        }
    }
    accepted
}

/// Which candidates are duplicates: of fits closer than `duplicate_px`, all but the
/// best-correlated (the first on ties). Nothing is a duplicate if `duplicate_px` is 0.
fn mark_duplicates(accepted: &[Candidate], duplicate_px: f64) -> Result<Vec<bool>, FeatureError> {
    let mut is_duplicate = vec![false; accepted.len()];
    if duplicate_px > 0.0 && accepted.len() > 1 {
        let points: Vec<[f64; 2]> = accepted.iter().map(|c| [c.fit.x0, c.fit.y0]).collect();
        let tree: ImmutableKdTree<f64, 2> =
            ImmutableKdTree::new_from_slice(&points).map_err(|e| {
                FeatureError::BadParameter(format!("cannot index feature positions: {e:?}"))
            })?;
        for (i, point) in points.iter().enumerate() {
            let close = tree
                .query(point)
                .within::<SquaredEuclidean<f64>>(duplicate_px * duplicate_px)
                .unsorted()
                .execute();
            for neighbour in close {
                let j = neighbour.item as usize;
                if j == i {
                    continue;
                }
                let better = accepted[j].ncc_peak > accepted[i].ncc_peak
                    || (accepted[j].ncc_peak == accepted[i].ncc_peak && j < i);
                if better {
                    is_duplicate[i] = true;
                    break;
                }
            }
        }
    }
    Ok(is_duplicate)
}

/// Turns the non-duplicate candidates into features (positions in pixels and metres,
/// heights back in the image's sign, acquisition times in seconds); duplicates are
/// rejected.
fn assemble_features(
    accepted: Vec<Candidate>,
    is_duplicate: Vec<bool>,
    geometry: &ScanGeometry,
    (pass, sign): (ScanPass, f64),
    removed: &RemovedLevels,
    rejected: &mut Vec<RejectedCandidate>,
) -> Vec<Feature> {
    let mut features = Vec::with_capacity(accepted.len());
    for (candidate, duplicate) in accepted.into_iter().zip(is_duplicate) {
        let fit = candidate.fit;
        if duplicate {
            rejected.push(RejectedCandidate {
                x_px: fit.x0,
                y_px: fit.y0,
                reason: Rejection::Duplicate,
            });
            continue;
        }
        let time = geometry.acquisition_time(pass, fit.x0, fit.y0);
        features.push(Feature {
            id: 0,
            pass,
            x_px: fit.x0,
            y_px: fit.y0,
            x_m: fit.x0 * geometry.pitch_x(),
            y_m: fit.y0 * geometry.pitch_y(),
            x_sigma_px: fit.x0_sigma,
            y_sigma_px: fit.y0_sigma,
            sigma_major_px: fit.sigma_major,
            sigma_minor_px: fit.sigma_minor,
            theta_rad: fit.theta,
            amplitude: fit.amplitude,
            height: sign * fit.amplitude,
            z0: sign * fit.offset,
            removed_level: sign * removed.at(fit.x0, fit.y0),
            residual_rms: fit.residual_rms,
            pixel_count: candidate.pixel_count,
            ncc_peak: candidate.ncc_peak,
            status: fit.status,
            fit_iterations: fit.iterations,
            time_s: time.since_frame_start,
            line_time_s: time.since_line_start,
        });
    }
    features
}

/// An error if no feature survived or if their median correlation peak is below
/// `options.min_median_ncc` (the image looks like noise).
fn check_found(
    features: &[Feature],
    pass: ScanPass,
    candidates: usize,
    options: &FeatureOptions,
    rejected: &[RejectedCandidate],
) -> Result<(), FeatureError> {
    let pass_name = pass.name();
    if features.is_empty() {
        return Err(FeatureError::NoFeatures {
            pass: pass_name,
            candidates,
            threshold: options.threshold,
            rejected: RejectionCounts::of(rejected).to_string(),
        });
    }
    let mut peaks: Vec<f64> = features.iter().map(|f| f.ncc_peak).collect();
    let middle = peaks.len() / 2;
    let median_ncc = *peaks.select_nth_unstable_by(middle, f64::total_cmp).1;
    if median_ncc < options.min_median_ncc {
        return Err(FeatureError::NoiseLike {
            pass: pass_name,
            count: features.len(),
            median_ncc,
            limit: options.min_median_ncc,
        });
    }
    Ok(())
}

/// Sub-pixel position `(x, y)` of the correlation peak at `(row, col)` from a parabola
/// through it and its two neighbours along each axis (the peak itself at the border).
fn subpixel_peak(map: &Array2<f64>, row: usize, col: usize) -> (f64, f64) {
    let (rows, cols) = map.dim();
    let vertex = dhct_numerics::peak::vertex;
    let dx = if col > 0 && col + 1 < cols {
        vertex(map[[row, col - 1]], map[[row, col]], map[[row, col + 1]])
    } else {
        0.0
    };
    let dy = if row > 0 && row + 1 < rows {
        vertex(map[[row - 1, col]], map[[row, col]], map[[row + 1, col]])
    } else {
        0.0
    };
    (col as f64 + dx, row as f64 + dy)
}

/// Drops the features whose amplitude is below `fraction` × the 90th percentile of all
/// amplitudes (the deepest or brightest kind is kept; `fraction` 0 keeps everything).
fn drop_shallow(features: &mut Vec<Feature>, fraction: f64, rejected: &mut Vec<RejectedCandidate>) {
    if fraction <= 0.0 || features.is_empty() {
        return;
    }
    let mut amplitudes: Vec<f64> = features.iter().map(|f| f.amplitude).collect();
    let rank = ((amplitudes.len() - 1) as f64 * 0.9).round() as usize;
    let reference = *amplitudes.select_nth_unstable_by(rank, f64::total_cmp).1;
    features.retain(|f| {
        let keep = f.amplitude >= fraction * reference;
        if !keep {
            rejected.push(RejectedCandidate {
                x_px: f.x_px,
                y_px: f.y_px,
                reason: Rejection::TooShallow,
            });
        }
        keep
    });
}

/// Which regions belong to the tracked kind of feature when the lattice tracks only the
/// deepest (or brightest) of several (`min_relative_height` > 0, e.g. the corner holes of
/// Si(111)-7×7): those whose signed height at their peak is at least `fraction` × the 90th
/// percentile of all regions' (the rule [`drop_shallow`] applies to the fits later).
fn tracked_kind(regions: &[Region], signed: &Array2<f64>, fraction: f64) -> Vec<bool> {
    let columns = signed.ncols();
    let height = |r: &Region| {
        let v = signed[[r.peak / columns, r.peak % columns]];
        if v.is_finite() { v } else { f64::NEG_INFINITY }
    };
    let mut heights: Vec<f64> = regions.iter().map(height).collect();
    if heights.is_empty() {
        return Vec::new();
    }
    let rank = ((heights.len() - 1) as f64 * 0.9).round() as usize;
    let reference = *heights.select_nth_unstable_by(rank, f64::total_cmp).1;
    regions
        .iter()
        .map(|r| height(r) >= fraction * reference)
        .collect()
}

/// The DHCT area filter: keep regions with median/√10 < area < median·√10, the median taken
/// over regions larger than 10 px (of the tracked kind only, when `tracked` says which: a
/// drift-stretched Si(111)-7×7 image resolves twice as many shallow minima as corner holes,
/// whose median area would otherwise reject the corner holes as too large).
fn area_filter(
    regions: Vec<Region>,
    enabled: bool,
    columns: usize,
    tracked: Option<&[bool]>,
    rejected: &mut Vec<RejectedCandidate>,
) -> Vec<Region> {
    let mut areas: Vec<usize> = regions
        .iter()
        .enumerate()
        .filter(|(i, _)| tracked.is_none_or(|t| t.get(*i).copied().unwrap_or(true)))
        .map(|(_, r)| r.area)
        .filter(|&a| a > MIN_AREA_FOR_MEDIAN)
        .collect();
    if !enabled || areas.is_empty() {
        return regions;
    }
    areas.sort_unstable();
    let median = areas[areas.len() / 2] as f64;
    let factor = 10f64.sqrt();
    let (low, high) = (median / factor, median * factor);
    let mut kept = Vec::with_capacity(regions.len());
    for region in regions {
        let area = region.area as f64;
        let reason = if area <= low {
            Some(Rejection::AreaTooSmall)
        } else if area >= high {
            Some(Rejection::AreaTooLarge)
        } else {
            None
        };
        match reason {
            Some(reason) => rejected.push(RejectedCandidate {
                x_px: (region.peak % columns) as f64,
                y_px: (region.peak / columns) as f64,
                reason,
            }),
            None => kept.push(region),
        }
    }
    kept
}

#[cfg(test)]
mod tests {
    use super::*;

    fn feature(amplitude: f64) -> Feature {
        Feature {
            id: 0,
            pass: ScanPass::Trace,
            x_px: amplitude,
            y_px: 0.0,
            x_m: 0.0,
            y_m: 0.0,
            x_sigma_px: 0.1,
            y_sigma_px: 0.1,
            sigma_major_px: 2.0,
            sigma_minor_px: 2.0,
            theta_rad: 0.0,
            amplitude,
            height: -amplitude,
            z0: 0.0,
            removed_level: 0.0,
            residual_rms: 0.0,
            pixel_count: 10,
            ncc_peak: 0.9,
            status: FitStatus::Converged,
            fit_iterations: 5,
            time_s: 0.0,
            line_time_s: 0.0,
        }
    }

    #[test]
    fn shallow_features_of_another_kind_are_dropped_and_counted() {
        // One deep corner hole per cell among three shallower minima (half as deep).
        let mut features: Vec<Feature> = (0..40)
            .map(|i| {
                feature(if i % 4 == 0 {
                    1.5 + 0.01 * i as f64
                } else {
                    0.75
                })
            })
            .collect();
        let mut rejected = Vec::new();
        drop_shallow(&mut features, 0.6, &mut rejected);
        assert_eq!(features.len(), 10);
        assert!(features.iter().all(|f| f.amplitude >= 1.5));
        assert_eq!(RejectionCounts::of(&rejected).too_shallow, 30);
        // 0 keeps everything.
        let mut all: Vec<Feature> = (0..5).map(|i| feature(0.1 + i as f64)).collect();
        drop_shallow(&mut all, 0.0, &mut rejected);
        assert_eq!(all.len(), 5);
    }
}
