//! The whole-image lattice fit per mask region (each region one lattice domain), and each
//! feature's lattice index from those fits.

use dhct_distortion::CorrectedFeature;
use dhct_features::{Feature, FeatureSet};
use dhct_lattice::{Lattice, LatticeFit, LatticeFitError, angular_distribution, fit_lattice};
use dhct_scan::{ScanGeometry, ScanPair, ScanPass};
use dhct_unitcell::{ConfidenceEllipse, LocalCell, local_cells};
use ndarray::Array2;

use crate::{
    FeatureIndex, PipelineError, PipelineOptions, RegionFit, SkippedRegion, label_regions,
};

/// The features of one region that go into its lattice fit.
struct Selected {
    /// Slots (in the pass sets) of the passes fitted: the trace, and every other pass
    /// with enough features inside the region.
    usable: Vec<usize>,
    /// Per usable pass, the indices of its features inside the region.
    members: Vec<Vec<usize>>,
    /// Per usable pass, those features' corrected positions (sample frame, metres).
    points: Vec<Vec<[f64; 2]>>,
}

impl Selected {
    /// Keeps the trace (slot 0) and the passes with at least `min_features` of the
    /// region's `members` (per pass); retrace sets with too few are left out of the fit.
    fn new(
        sets: &[&FeatureSet],
        corrected: &[Vec<CorrectedFeature>],
        members: &[Vec<usize>],
        min_features: usize,
    ) -> Selected {
        let usable: Vec<usize> = (0..sets.len())
            .filter(|&k| k == 0 || members[k].len() >= min_features)
            .collect();
        let points: Vec<Vec<[f64; 2]>> = usable
            .iter()
            .map(|&k| {
                members[k]
                    .iter()
                    .map(|&i| [corrected[k][i].x_m, corrected[k][i].y_m])
                    .collect()
            })
            .collect();
        let members: Vec<Vec<usize>> = usable.iter().map(|&k| members[k].clone()).collect();
        Selected {
            usable,
            members,
            points,
        }
    }
}

/// Fits the lattice to the corrected features of each region of `mask` (the whole image
/// without a mask), largest region first. A region with too few features, or whose fit
/// fails, is skipped with the reason; an error when no region could be fitted.
pub(crate) fn fit_regions(
    pair: &ScanPair,
    lattice: &dyn Lattice,
    mask: Option<&Array2<bool>>,
    options: &PipelineOptions,
    sets: &[&FeatureSet],
    corrected: &[Vec<CorrectedFeature>],
) -> Result<(Vec<RegionFit>, Vec<SkippedRegion>), PipelineError> {
    let geometry = pair.geometry();
    let (labels, sizes) = region_labels(geometry, mask);
    let margin_px = edge_margin_px(geometry, lattice, mask, options);
    let min_features = options.regions.min_features;
    let mut fits = Vec::new();
    let mut skipped = Vec::new();
    let mut first_error = None;
    for (region, &pixels) in sizes.iter().enumerate() {
        let members = region_members(sets, corrected, &labels, region as u32, margin_px);
        let count = members[0].len();
        if count < min_features {
            skipped.push(SkippedRegion {
                region,
                pixels,
                features: count,
                reason: format!("{count} features inside (at least {min_features} needed)"),
            });
            continue;
        }
        let selected = Selected::new(sets, corrected, &members, min_features);
        let refs: Vec<&[[f64; 2]]> = selected.points.iter().map(|p| p.as_slice()).collect();
        let fit = match fit_lattice(lattice, &refs, &options.lattice_fit) {
            Ok(fit) => fit,
            Err(e) => {
                skipped.push(SkippedRegion {
                    region,
                    pixels,
                    features: count,
                    reason: e.to_string(),
                });
                first_error.get_or_insert(e);
                continue;
            }
        };
        fits.push(region_fit(
            lattice,
            options,
            sets,
            (region, pixels),
            fit,
            selected,
        )?);
    }
    if fits.is_empty() {
        return Err(no_region_error(
            first_error,
            mask.is_some(),
            &skipped,
            min_features,
        ));
    }
    Ok((fits, skipped))
}

/// The regions of `mask` (labels and pixel counts, largest first); without a mask the
/// whole image is region 0.
fn region_labels(
    geometry: &ScanGeometry,
    mask: Option<&Array2<bool>>,
) -> (Array2<Option<u32>>, Vec<usize>) {
    match mask {
        Some(mask) => label_regions(mask),
        None => (
            Array2::from_elem((geometry.rows(), geometry.columns()), Some(0)),
            vec![geometry.rows() * geometry.columns()],
        ),
    }
}

/// The margin (pixels along x and y) a feature must keep from a region's edge: the
/// options' multiple of the nearest-neighbour distance with a mask, none without.
fn edge_margin_px(
    geometry: &ScanGeometry,
    lattice: &dyn Lattice,
    mask: Option<&Array2<bool>>,
    options: &PipelineOptions,
) -> [f64; 2] {
    let nn = lattice.nearest_neighbour_distance();
    if mask.is_some() {
        let m = options.regions.edge_margin_nn * nn;
        [m / geometry.pitch_x(), m / geometry.pitch_y()]
    } else {
        [0.0, 0.0]
    }
}

/// Per pass, the indices of the features with a finite corrected position whose raw
/// position lies in region `label`, `margin_px` from its edge.
fn region_members(
    sets: &[&FeatureSet],
    corrected: &[Vec<CorrectedFeature>],
    labels: &Array2<Option<u32>>,
    label: u32,
    margin_px: [f64; 2],
) -> Vec<Vec<usize>> {
    sets.iter()
        .zip(corrected)
        .map(|(set, corrected)| {
            (0..set.features.len())
                .filter(|&i| {
                    let f: &Feature = &set.features[i];
                    corrected[i].x_m.is_finite()
                        && corrected[i].y_m.is_finite()
                        && inside_region(labels, label, f.x_px, f.y_px, margin_px)
                })
                .collect()
        })
        .collect()
}

/// The fitted region `(region, pixels)` with its confidence ellipses (of the whole-image
/// fit's deviations, weighted by feature height, and of the local cells'), local cells
/// and angular distribution.
fn region_fit(
    lattice: &dyn Lattice,
    options: &PipelineOptions,
    sets: &[&FeatureSet],
    (region, pixels): (usize, usize),
    fit: LatticeFit,
    selected: Selected,
) -> Result<RegionFit, PipelineError> {
    let Selected {
        usable,
        members,
        points,
    } = selected;
    let passes: Vec<ScanPass> = usable.iter().map(|&k| sets[k].pass).collect();
    let mut deviations = Vec::new();
    let mut heights = Vec::new();
    for (k, set_members) in members.iter().enumerate() {
        for (point, &i) in fit.points[k].iter().zip(set_members) {
            deviations.push(point.deviation_m);
            heights.push(sets[usable[k]].features[i].height);
        }
    }
    let whole_ellipse = ConfidenceEllipse::from_deviations(&deviations, Some(&heights))?;
    let cells: Vec<Vec<LocalCell>> = (0..points.len())
        .map(|k| local_cells(lattice, &fit, &points[k], k))
        .collect();
    let local: Vec<[f64; 2]> = cells
        .iter()
        .flatten()
        .flat_map(|c| c.deviations_m)
        .collect();
    let local_ellipse = ConfidenceEllipse::from_deviations(&local, None).ok();
    let adf = angular_distribution(lattice, &points[0], options.lattice_fit.nn_window, 180).ok();
    Ok(RegionFit {
        region,
        pixels,
        fit,
        passes,
        members,
        whole_ellipse,
        local_cells: cells,
        local_ellipse,
        adf,
    })
}

/// Why no region could be fitted: the first lattice-fit error, or else too few features
/// (the most any region had against `needed`).
fn no_region_error(
    first_error: Option<LatticeFitError>,
    masked: bool,
    skipped: &[SkippedRegion],
    needed: usize,
) -> PipelineError {
    match first_error {
        Some(e) => PipelineError::LatticeFit(e),
        None => PipelineError::TooFewFeatures {
            pass: if masked {
                "largest mask region of the trace".into()
            } else {
                "trace".into()
            },
            found: skipped.iter().map(|s| s.features).max().unwrap_or(0),
            needed,
            opposite_polarity: None,
        },
    }
}

/// Each feature's lattice site and deviation from the region fit that indexed it (per
/// set, in feature order; `None` where no region did).
pub(crate) fn index_features(
    sets: &[&FeatureSet],
    regions: &[RegionFit],
) -> Vec<Vec<Option<FeatureIndex>>> {
    let mut indices: Vec<Vec<Option<FeatureIndex>>> =
        sets.iter().map(|s| vec![None; s.features.len()]).collect();
    for (r, region) in regions.iter().enumerate() {
        for (k, members) in region.members.iter().enumerate() {
            let pass_slot = sets
                .iter()
                .position(|s| s.pass == region.passes[k])
                .expect("region sets are passes of the pair");
            for (point, &feature) in region.fit.points[k].iter().zip(members) {
                indices[pass_slot][feature] = Some(FeatureIndex {
                    region: r,
                    n: point.n,
                    m: point.m,
                    site: point.site,
                    deviation_m: point.deviation_m,
                });
            }
        }
    }
    indices
}

/// Whether the raw-frame position `(x, y)` px lies in region `label` with every point at
/// `margin_px` around it too (8 directions).
fn inside_region(
    labels: &Array2<Option<u32>>,
    label: u32,
    x: f64,
    y: f64,
    margin_px: [f64; 2],
) -> bool {
    let (rows, columns) = labels.dim();
    let at = |x: f64, y: f64| {
        let (c, r) = (x.round(), y.round());
        c >= 0.0
            && r >= 0.0
            && (c as usize) < columns
            && (r as usize) < rows
            && labels[[r as usize, c as usize]] == Some(label)
    };
    const D: f64 = std::f64::consts::FRAC_1_SQRT_2;
    const DIRECTIONS: [(f64, f64); 9] = [
        (0.0, 0.0),
        (1.0, 0.0),
        (-1.0, 0.0),
        (0.0, 1.0),
        (0.0, -1.0),
        (D, D),
        (-D, D),
        (D, -D),
        (-D, -D),
    ];
    DIRECTIONS
        .iter()
        .all(|(dx, dy)| at(x + dx * margin_px[0], y + dy * margin_px[1]))
}
