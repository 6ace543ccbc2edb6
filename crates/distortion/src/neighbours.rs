//! Nearest neighbours: KD-tree search (kiddo), the radial distribution function and its
//! Gaussian fit at the lattice's shell distances, and the selection of features that have
//! their lattice's full nearest-neighbour count.
//!
//! All positions here are metres in one frame (controller or corrected sample frame),
//! display orientation (x right, y down).

use dhct_lattice::Lattice;
use dhct_scan::ScanGeometry;
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use ndarray::Array2;
use serde::{Deserialize, Serialize};

use crate::DistortionError;
use dhct_numerics::lm::{Bounds, LmOptions, fit_residuals_within};

/// Options of the neighbour search; [`NeighbourOptions::validate`] checks their ranges.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct NeighbourOptions {
    /// Half-width of the NN window as a fraction of each NN distance (DHCT: 0.35);
    /// 0.05..=0.5.
    pub window: f64,
    /// Number of RDF shells fitted (3 = a, √3a, 2a for trigonal); 1..=10 (the RDF's
    /// length and the fit's size grow with it).
    pub rdf_shells: usize,
    /// RDF bin width as a fraction of the nominal NN distance (DHCT: 0.01); 0.001..=0.1
    /// (the number of bins, and so memory, grows as its inverse).
    pub bin_fraction: f64,
}

impl NeighbourOptions {
    /// Checks every option against its documented range; the error names the key, the
    /// value and the range.
    pub fn validate(&self) -> Result<(), DistortionError> {
        for (key, value, low, high) in [
            ("window", self.window, 0.05, 0.5),
            ("rdf_shells", self.rdf_shells as f64, 1.0, 10.0),
            ("bin_fraction", self.bin_fraction, 0.001, 0.1),
        ] {
            if !(value.is_finite() && (low..=high).contains(&value)) {
                return Err(DistortionError::BadParameter(format!(
                    "neighbours.{key} = {value} is outside {low}..={high}"
                )));
            }
        }
        Ok(())
    }
}

impl Default for NeighbourOptions {
    fn default() -> Self {
        NeighbourOptions {
            window: 0.35,
            rdf_shells: 3,
            bin_fraction: 0.01,
        }
    }
}

/// A radial distribution function `g(r)`: pair counts per bin divided by those of an
/// ideal gas of the same density (so `g → 1` at large `r`, up to edge losses).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Rdf {
    /// Bin centres, metres.
    pub r_m: Vec<f64>,
    /// `g(r)`, dimensionless.
    pub g: Vec<f64>,
}

/// The fit `g(r) ≈ Σ_m A_m·exp(−(r − c_m·a)²/2w_m²)` at the lattice's shell ratios `c_m`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RdfFit {
    /// Refined nearest-neighbour distance `a` (first shell), metres.
    pub nn_distance_m: f64,
    /// Fitted shell positions `c_m·a`, metres.
    pub shells_m: Vec<f64>,
    /// Peak amplitudes `A_m`.
    pub amplitudes: Vec<f64>,
    /// Gaussian widths `w_m` (σ), metres.
    pub widths_m: Vec<f64>,
    /// Full widths at half maximum `2√(2 ln 2)·w_m`, metres.
    pub fwhm_m: Vec<f64>,
}

/// Why a feature was not selected for the local-distortion measurement.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct ExclusionCounts {
    /// The mask is false at the feature.
    pub outside_mask: usize,
    /// Closer to the image border than the NN search radius.
    pub near_edge: usize,
    /// Fewer neighbours in the window than the lattice's NN count.
    pub too_few_neighbours: usize,
    /// More neighbours in the window than the lattice's NN count.
    pub too_many_neighbours: usize,
}

/// One selected feature and its nearest neighbours (indices into the input positions).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SelectedFeature {
    /// Index of the feature.
    pub index: usize,
    /// Indices of its nearest neighbours.
    pub neighbours: Vec<usize>,
}

/// The result of [`select_features`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NeighbourSelection {
    /// The RDF of the features inside the mask.
    pub rdf: Rdf,
    /// Its fit.
    pub rdf_fit: RdfFit,
    /// The nearest-neighbour distances used for the window (metres), scaled to the fit.
    pub nn_distances_m: Vec<f64>,
    /// Features with exactly the lattice's NN count.
    pub selected: Vec<SelectedFeature>,
    /// Counts of why the others were excluded.
    pub exclusions: ExclusionCounts,
}

fn tree_of(points: &[[f64; 2]]) -> Result<ImmutableKdTree<f64, 2>, DistortionError> {
    ImmutableKdTree::new_from_slice(points)
        .map_err(|e| DistortionError::BadParameter(format!("cannot index positions: {e:?}")))
}

/// The RDF of `points` (metres) up to `r_max_m` in bins of `bin_m`; `area_m2` is the area
/// the points cover (for the density).
pub fn radial_distribution(
    points: &[[f64; 2]],
    area_m2: f64,
    r_max_m: f64,
    bin_m: f64,
) -> Result<Rdf, DistortionError> {
    if !(bin_m > 0.0 && r_max_m > bin_m && area_m2 > 0.0) {
        return Err(DistortionError::BadParameter(format!(
            "RDF needs 0 < bin < r_max and a positive area (bin {bin_m}, r_max {r_max_m}, area {area_m2})"
        )));
    }
    let bins = (r_max_m / bin_m).floor() as usize;
    let mut counts = vec![0.0; bins];
    if points.len() >= 2 {
        let tree = tree_of(points)?;
        for p in points {
            for n in tree
                .query(p)
                .within::<SquaredEuclidean<f64>>(r_max_m * r_max_m)
                .unsorted()
                .execute()
            {
                let r = n.distance.sqrt();
                if r > 0.0 {
                    let k = (r / bin_m).floor() as usize;
                    if k < bins {
                        counts[k] += 1.0;
                    }
                }
            }
        }
    }
    let n = points.len().max(1) as f64;
    let density = n / area_m2;
    let r_m: Vec<f64> = (0..bins).map(|k| (k as f64 + 0.5) * bin_m).collect();
    let g = counts
        .iter()
        .zip(&r_m)
        .map(|(c, r)| c / (n * density * 2.0 * std::f64::consts::PI * r * bin_m))
        .collect();
    Ok(Rdf { r_m, g })
}

impl RdfFit {
    /// Whether the fit describes shells: every amplitude positive and every width between
    /// 0.2 % and 30 % of its shell's distance (a degenerate fit gives widths of picometres
    /// with amplitudes of thousands, or shells wider than the lattice).
    pub fn is_plausible(&self) -> bool {
        self.amplitudes.iter().all(|a| a.is_finite() && *a > 0.0)
            && self
                .widths_m
                .iter()
                .zip(&self.shells_m)
                .all(|(w, r)| w.is_finite() && *w >= 0.002 * r && *w <= 0.3 * r)
    }
}

/// Fits Gaussians at the shell distances `shells_m` (nominal, metres; only their ratios
/// and the first as a start value are used) to `rdf`, refining the NN distance.
pub fn fit_rdf(rdf: &Rdf, shells_m: &[f64]) -> Result<RdfFit, DistortionError> {
    let Some(&a0) = shells_m.first() else {
        return Err(DistortionError::BadParameter("no shells to fit".into()));
    };
    let ratios: Vec<f64> = shells_m.iter().map(|s| s / a0).collect();
    let last = ratios.last().copied().unwrap_or(1.0);
    let keep: Vec<(f64, f64)> = rdf
        .r_m
        .iter()
        .zip(&rdf.g)
        .filter(|(r, _)| **r >= 0.5 * a0 && **r <= (last + 0.2) * a0)
        .map(|(r, g)| (*r, *g))
        .collect();
    let ns = ratios.len();
    if keep.len() < 2 * ns + 3 {
        return Err(DistortionError::TooFewFeatures {
            what: "RDF",
            found: keep.len(),
            needed: 2 * ns + 3,
        });
    }
    // Parameters in units of a0: [A_1..A_ns, w_1..w_ns, a].
    let mut p0 = Vec::with_capacity(2 * ns + 1);
    for c in &ratios {
        let peak = keep
            .iter()
            .filter(|(r, _)| (r / a0 - c).abs() < 0.1)
            .map(|(_, g)| *g)
            .fold(0.0, f64::max);
        p0.push(peak.max(1e-3));
    }
    p0.extend(std::iter::repeat_n(0.04, ns));
    p0.push(1.0);
    let m = keep.len();
    let residuals = |p: &[f64], r: &mut [f64]| {
        for (i, (x, g)) in keep.iter().enumerate() {
            let x = x / a0;
            let mut model = 0.0;
            for k in 0..ns {
                let w = p[ns + k];
                model += p[k] * (-(x - ratios[k] * p[2 * ns]).powi(2) / (2.0 * w * w)).exp();
            }
            r[i] = model - g;
        }
    };
    let fit = fit_residuals_within(
        &residuals,
        m,
        &p0,
        &vec![1.0; m],
        Some(rdf_bounds(ns)),
        &LmOptions {
            max_iterations: 300,
            ..LmOptions::default()
        },
    )
    .ok_or(DistortionError::FitFailed("RDF"))?;
    let p = fit.params;
    let a = p[2 * ns] * a0;
    if !(a > 0.5 * a0 && a < 1.5 * a0) || p[..ns].iter().all(|amp| *amp <= 0.0) {
        return Err(DistortionError::FitFailed("RDF"));
    }
    let widths_m: Vec<f64> = (0..ns).map(|k| p[ns + k].abs() * a0).collect();
    Ok(RdfFit {
        nn_distance_m: a,
        shells_m: ratios.iter().map(|c| c * a).collect(),
        amplitudes: p[..ns].to_vec(),
        fwhm_m: widths_m
            .iter()
            .map(|w| 2.0 * (2.0 * std::f64::consts::LN_2).sqrt() * w)
            .collect(),
        widths_m,
    })
}

/// Where the RDF fit may look (units of the nominal NN distance): peaks of non-negative
/// height, widths between 0.1 % and 30 % of the NN distance, the NN distance itself within
/// the ±50 % that [`fit_rdf`] accepts. Without them a shell can run off to a huge width or
/// a negative height and drag the fit to nonsense.
fn rdf_bounds(ns: usize) -> Bounds {
    let mut lower = vec![0.0; ns];
    lower.extend(std::iter::repeat_n(1e-3, ns));
    lower.push(0.5);
    let mut upper = vec![f64::INFINITY; ns];
    upper.extend(std::iter::repeat_n(0.3, ns));
    upper.push(1.5);
    Bounds { lower, upper }
}

/// The distinct nearest-neighbour distances of `lattice` (metres), ascending
/// ([`Lattice::nearest_neighbour_distances`]).
pub fn nn_distances(lattice: &dyn Lattice) -> Vec<f64> {
    lattice.nearest_neighbour_distances()
}

/// Whether each point (pixels, x = column, y = row) lies where `mask` is true.
pub fn inside_mask(points_px: &[[f64; 2]], mask: Option<&Array2<bool>>) -> Vec<bool> {
    let Some(mask) = mask else {
        return vec![true; points_px.len()];
    };
    let (rows, columns) = mask.dim();
    points_px
        .iter()
        .map(|&[x, y]| {
            let (c, r) = (x.round(), y.round());
            c >= 0.0
                && r >= 0.0
                && (c as usize) < columns
                && (r as usize) < rows
                && mask[[r as usize, c as usize]]
        })
        .collect()
}

/// Finds every feature's nearest neighbours and selects those with the lattice's full NN
/// count. `points_px` are positions in pixels of `geometry` (x = column, y = row); the
/// mask (rows × columns, true = use) removes features before anything else.
pub fn select_features(
    points_px: &[[f64; 2]],
    geometry: &ScanGeometry,
    mask: Option<&Array2<bool>>,
    lattice: &dyn Lattice,
    options: &NeighbourOptions,
) -> Result<NeighbourSelection, DistortionError> {
    options.validate()?;
    if let Some(mask) = mask {
        let (rows, columns) = mask.dim();
        if rows != geometry.rows() || columns != geometry.columns() {
            return Err(DistortionError::ShapeMismatch {
                what: "mask",
                columns,
                rows,
                geometry_columns: geometry.columns(),
                geometry_rows: geometry.rows(),
            });
        }
    }
    let (px, py) = (geometry.pitch_x(), geometry.pitch_y());
    let inside = inside_mask(points_px, mask);
    let used: Vec<usize> = (0..points_px.len()).filter(|&i| inside[i]).collect();
    let points_m: Vec<[f64; 2]> = used
        .iter()
        .map(|&i| [points_px[i][0] * px, points_px[i][1] * py])
        .collect();
    let mask_pixels = mask.map_or(geometry.rows() * geometry.columns(), |m| {
        m.iter().filter(|v| **v).count()
    });
    let area = mask_pixels as f64 * px * py;
    let shells = lattice.neighbour_shells(options.rdf_shells.max(1));
    let a_nominal = shells[0];
    let last = shells.last().copied().unwrap_or(a_nominal);
    let rdf = radial_distribution(
        &points_m,
        area,
        last + 0.25 * a_nominal,
        options.bin_fraction * a_nominal,
    )?;
    let rdf_fit = fit_rdf(&rdf, &shells)?;
    // A degenerate fit (a needle or a shell as wide as the lattice) says nothing about
    // the spacing: the window stays at the nominal one.
    let scale = if rdf_fit.is_plausible() {
        rdf_fit.nn_distance_m / a_nominal
    } else {
        1.0
    };
    let nn_distances_m: Vec<f64> = nn_distances(lattice).iter().map(|d| d * scale).collect();
    // The window never reaches another shell of this lattice.
    let window = options.window.min(lattice.neighbour_window());
    let reach = nn_distances_m.last().copied().unwrap_or(a_nominal) * (1.0 + window);
    // Motif sites may differ in neighbour count: a feature with any site's count is kept.
    let counts = lattice.neighbour_counts();
    let (width, height) = (
        (geometry.columns() as f64 - 1.0) * px,
        (geometry.rows() as f64 - 1.0) * py,
    );
    let mut exclusions = ExclusionCounts {
        outside_mask: points_px.len() - used.len(),
        ..ExclusionCounts::default()
    };
    let mut selected = Vec::new();
    if points_m.is_empty() {
        return Ok(NeighbourSelection {
            rdf,
            rdf_fit,
            nn_distances_m,
            selected,
            exclusions,
        });
    }
    let tree = tree_of(&points_m)?;
    for (k, p) in points_m.iter().enumerate() {
        if p[0] < reach || p[1] < reach || p[0] > width - reach || p[1] > height - reach {
            exclusions.near_edge += 1;
            continue;
        }
        let neighbours: Vec<usize> = tree
            .query(p)
            .within::<SquaredEuclidean<f64>>(reach * reach)
            .unsorted()
            .execute()
            .into_iter()
            .filter(|n| {
                let d = n.distance.sqrt();
                n.item as usize != k && nn_distances_m.iter().any(|r| (d - r).abs() < window * r)
            })
            .map(|n| used[n.item as usize])
            .collect();
        if counts.contains(&neighbours.len()) {
            selected.push(SelectedFeature {
                index: used[k],
                neighbours,
            });
        } else if counts.last().is_some_and(|&most| neighbours.len() > most) {
            exclusions.too_many_neighbours += 1;
        } else {
            exclusions.too_few_neighbours += 1;
        }
    }
    Ok(NeighbourSelection {
        rdf,
        rdf_fit,
        nn_distances_m,
        selected,
        exclusions,
    })
}

/// Fallback for raw positions too distorted for the NN window of [`select_features`] (a
/// drift of more than ~30 % of the slow-scan speed): each feature's `k` nearest features
/// are its neighbours (`k` = the smallest neighbour count of the lattice's sites), without
/// a distance window. A feature is kept if its `k`-th neighbour is at most `1.6 ×` (or
/// 1.2 × the lattice's own spread of nearest-neighbour distances, if larger) as far as
/// its nearest (vacancies and borders give a second-shell neighbour) and it is farther
/// than twice that from the image border. Good enough to fit a first model, whose corrected frame then gives the windowed
/// selection (see [`crate::analyse`]).
pub fn select_nearest(
    points_px: &[[f64; 2]],
    geometry: &ScanGeometry,
    mask: Option<&Array2<bool>>,
    lattice: &dyn Lattice,
) -> Result<Vec<SelectedFeature>, DistortionError> {
    let (px, py) = (geometry.pitch_x(), geometry.pitch_y());
    let inside = inside_mask(points_px, mask);
    let used: Vec<usize> = (0..points_px.len()).filter(|&i| inside[i]).collect();
    let k = lattice.neighbour_counts().first().copied().unwrap_or(0);
    let distances = lattice.nearest_neighbour_distances();
    let spread = match (distances.first(), distances.last()) {
        (Some(first), Some(last)) if *first > 0.0 => last / first,
        _ => 1.0,
    };
    let max_ratio = (1.2 * spread).max(1.6);
    if k == 0 || used.len() <= k {
        return Ok(Vec::new());
    }
    let points_m: Vec<[f64; 2]> = used
        .iter()
        .map(|&i| [points_px[i][0] * px, points_px[i][1] * py])
        .collect();
    let (width, height) = (
        (geometry.columns() as f64 - 1.0) * px,
        (geometry.rows() as f64 - 1.0) * py,
    );
    let tree = tree_of(&points_m)?;
    let k_with_self = std::num::NonZeroUsize::new(k + 1).expect("k + 1 > 0");
    let mut selected = Vec::new();
    for (i, p) in points_m.iter().enumerate() {
        let nearest = tree
            .query(p)
            .nearest_n::<SquaredEuclidean<f64>>(k_with_self)
            .execute();
        let mut neighbours: Vec<(f64, usize)> = nearest
            .iter()
            .filter(|n| n.item as usize != i)
            .map(|n| (n.distance.sqrt(), n.item as usize))
            .collect();
        neighbours.sort_by(|a, b| a.0.total_cmp(&b.0));
        if neighbours.len() != k {
            continue;
        }
        let (first, last) = (neighbours[0].0, neighbours[k - 1].0);
        let margin = 2.0 * last;
        if !(first > 0.0 && last <= max_ratio * first)
            || p[0] < margin
            || p[1] < margin
            || p[0] > width - margin
            || p[1] > height - margin
        {
            continue;
        }
        selected.push(SelectedFeature {
            index: used[i],
            neighbours: neighbours.iter().map(|&(_, j)| used[j]).collect(),
        });
    }
    Ok(selected)
}

/// Statistics of the angles between angularly adjacent nearest neighbours.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct AngleStats {
    /// The ideal angle `360°/NN count`, degrees.
    pub ideal_deg: f64,
    /// RMS deviation of the angles from the ideal, degrees.
    pub rms_deviation_deg: f64,
    /// Mean absolute deviation, degrees.
    pub mean_abs_deviation_deg: f64,
    /// Number of angles.
    pub count: usize,
}

/// Angles between adjacent NN vectors of the selected features, positions in metres.
pub fn nn_angle_stats(points_m: &[[f64; 2]], selected: &[SelectedFeature]) -> AngleStats {
    let mut deviations = Vec::new();
    let mut ideal = 0.0;
    for s in selected {
        let c = points_m[s.index];
        let mut angles: Vec<f64> = s
            .neighbours
            .iter()
            .map(|&j| (points_m[j][1] - c[1]).atan2(points_m[j][0] - c[0]))
            .collect();
        if angles.len() < 2 {
            continue;
        }
        angles.sort_by(f64::total_cmp);
        ideal = 360.0 / angles.len() as f64;
        for k in 0..angles.len() {
            let next = if k + 1 < angles.len() {
                angles[k + 1]
            } else {
                angles[0] + 2.0 * std::f64::consts::PI
            };
            deviations.push((next - angles[k]).to_degrees() - ideal);
        }
    }
    let n = deviations.len().max(1) as f64;
    AngleStats {
        ideal_deg: ideal,
        rms_deviation_deg: (deviations.iter().map(|d| d * d).sum::<f64>() / n).sqrt(),
        mean_abs_deviation_deg: deviations.iter().map(|d| d.abs()).sum::<f64>() / n,
        count: deviations.len(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use dhct_lattice::Hexagonal;
    use dhct_scan::ScanDirection;

    /// A perfect graphite lattice on a 200 × 150 px grid of 20 pm pixels.
    fn perfect() -> (ScanGeometry, Vec<[f64; 2]>) {
        let geometry = ScanGeometry::new(
            200,
            150,
            2e-11,
            2e-11,
            1e-3,
            ScanDirection::Right,
            ScanDirection::Down,
        )
        .expect("geometry");
        let a = 2.46e-10 / 2e-11;
        let mut points = Vec::new();
        for j in -20i32..40 {
            for i in -20i32..40 {
                let x = 3.3 + a * (i as f64 + 0.5 * j as f64);
                let y = 2.1 + a * 0.75f64.sqrt() * j as f64;
                if (0.0..199.0).contains(&x) && (0.0..149.0).contains(&y) {
                    points.push([x, y]);
                }
            }
        }
        (geometry, points)
    }

    #[test]
    fn perfect_lattice_rdf_and_selection() {
        let (geometry, points) = perfect();
        let lattice = Hexagonal::graphite();
        let selection = select_features(
            &points,
            &geometry,
            None,
            &lattice,
            &NeighbourOptions::default(),
        )
        .expect("selection");
        let fit = &selection.rdf_fit;
        assert!((fit.nn_distance_m / 2.46e-10 - 1.0).abs() < 1e-3, "{fit:?}");
        assert!(fit.fwhm_m[0] < 0.05 * 2.46e-10);
        assert_eq!(selection.exclusions.too_many_neighbours, 0);
        assert!(selection.selected.iter().all(|s| s.neighbours.len() == 6));
        assert_eq!(
            selection.selected.len()
                + selection.exclusions.near_edge
                + selection.exclusions.too_few_neighbours,
            points.len()
        );
        let points_m: Vec<[f64; 2]> = points
            .iter()
            .map(|p| [p[0] * 2e-11, p[1] * 2e-11])
            .collect();
        let angles = nn_angle_stats(&points_m, &selection.selected);
        assert!(angles.rms_deviation_deg < 1e-6 && (angles.ideal_deg - 60.0).abs() < 1e-9);
        // A mask over the left half removes the right half first.
        let mask = Array2::from_shape_fn((150, 200), |(_, c)| c < 100);
        let masked = select_features(
            &points,
            &geometry,
            Some(&mask),
            &lattice,
            &NeighbourOptions::default(),
        )
        .expect("selection");
        assert!(masked.exclusions.outside_mask > points.len() / 3);
        assert!(masked.selected.iter().all(|s| points[s.index][0] < 100.0));
        let wrong = Array2::from_elem((3, 3), true);
        assert!(
            select_features(
                &points,
                &geometry,
                Some(&wrong),
                &lattice,
                &NeighbourOptions::default()
            )
            .is_err()
        );
    }
}

#[cfg(test)]
mod rdf_plausibility {
    use super::RdfFit;

    fn fit(amplitudes: Vec<f64>, widths_m: Vec<f64>) -> RdfFit {
        RdfFit {
            nn_distance_m: 2.46e-10,
            shells_m: vec![2.46e-10, 4.26e-10],
            amplitudes,
            fwhm_m: widths_m.iter().map(|w| 2.355 * w).collect(),
            widths_m,
        }
    }

    #[test]
    fn needles_and_shells_wider_than_the_lattice_are_implausible() {
        assert!(fit(vec![3.0, 2.0], vec![10e-12, 15e-12]).is_plausible());
        // A needle (the field finding: amplitude 4187, width 2.9 pm) and a 7 cm shell.
        assert!(!fit(vec![4187.0, 2.0], vec![2.9e-13, 15e-12]).is_plausible());
        assert!(!fit(vec![3.0, 2.0], vec![10e-12, 0.07]).is_plausible());
        assert!(!fit(vec![-1.0, 2.0], vec![10e-12, 15e-12]).is_plausible());
    }
}
