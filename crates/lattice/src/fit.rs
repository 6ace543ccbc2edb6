//! Whole-image lattice fit with integer indices (DHCT paper §V; not in the authors' Matlab).
//!
//! Model: the feature of motif site `s` in cell `(n, m)` lies at
//! `p = o + Δ_k + D(s_x, s_y)·R(θ)·(n·a1 + m·a2 + f_s)` (metres), where `a1`, `a2`, `f_s` are
//! the lattice's primitive vectors and motif position, `R(θ)` a rotation by θ (from +x towards
//! +y), `D` the scales along the image x and y axes, `o` the origin and `Δ_k` the offset of
//! point set `k` (e.g. retrace relative to trace; `Δ_0 = 0`).
//!
//! Procedure: the angular distribution of nearest-neighbour bonds gives θ (modulo the
//! lattice's bond symmetry, [`Lattice::bond_direction_period`]; every candidate is tried),
//! the median NN distance the scale, and the feature nearest the centroid the origin (as
//! each motif site in turn). Indices are then assigned coarse-to-fine:
//! within a disc of a few lattice constants, an affine lattice is fitted by linear least
//! squares and the disc doubles until it covers every feature, each time checking that the
//! current model predicts the included features to better than half a lattice constant
//! (otherwise the fit stops with an error rather than mis-indexing). A final Gauss–Newton fit
//! of (o, θ, s_x, s_y, Δ_k) to all sets follows.

use dhct_scan::quantity::length;
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::{Matrix2, Vector2};
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::fit_refine::{refine, reindex};
use crate::fit_result::{IndexedPosition, LatticeFit, lattice_vector, nearest_site, transform};
use crate::{Lattice, estimate_rotation};

/// Why a lattice could not be fitted.
#[derive(Debug, Error)]
pub enum LatticeFitError {
    /// Too few points to fit.
    #[error("{found} features are too few for a lattice fit (at least {needed} are needed)")]
    TooFewPoints {
        /// Points given.
        found: usize,
        /// Points needed.
        needed: usize,
    },
    /// No bond lies within the nearest-neighbour window.
    #[error(
        "no nearest-neighbour bonds were found (median NN distance {}): the features do not \
         form a lattice, or the lattice does not match",
        length(*.median_nn_m)
    )]
    NoBonds {
        /// Median distance to the nearest point, metres.
        median_nn_m: f64,
    },
    /// The indexing lost the lattice: too few features near a site.
    #[error(
        "the lattice fit diverged: within {} of the seed only {fraction_ok:.0} % of the \
         features lie within half a lattice constant of a site. Check the lattice type and constant, \
         or fit one domain (mask region) at a time",
        length(*.radius_m)
    )]
    Diverged {
        /// Radius of the indexing disc, metres.
        radius_m: f64,
        /// Per cent of the features in the disc within the deviation limit.
        fraction_ok: f64,
    },
    /// Too few features near the seed to index: the disc the indexing starts from (a few
    /// median neighbour distances across) holds fewer than it needs, so the features are
    /// clustered rather than spread over a lattice.
    #[error(
        "within {} of the seed only {found} features lie (at least {needed} are needed), \
         although the features' median nearest-neighbour distance is {}: they are clustered \
         (pairs or groups found on one atom), not spread over a lattice. Check the feature \
         finding (its template and polarity) and that the image is atomically resolved",
        length(*.radius_m),
        length(*.median_nn_m)
    )]
    SparseSeed {
        /// Radius of the indexing disc, metres.
        radius_m: f64,
        /// Features in the disc.
        found: usize,
        /// Features needed.
        needed: usize,
        /// The features' median nearest-neighbour distance, metres.
        median_nn_m: f64,
    },
    /// The indexing lost the lattice: the features near a site are, together, farther
    /// from one affine lattice than a lattice's are.
    #[error(
        "the lattice fit diverged: within {} of the seed {fraction_ok:.0} % of the features \
         lie within half a lattice constant of a site, but {rms_percent:.1} % of a \
         nearest-neighbour distance from one affine lattice (rms; at most {limit_percent:.0} %): \
         the lattice there is distorted beyond an affine map, or the features are not all one \
         lattice's. Check the lattice type and constant, or fit one domain (mask region) at a \
         time",
        length(*.radius_m)
    )]
    TooScattered {
        /// Radius of the indexing disc, metres.
        radius_m: f64,
        /// Per cent of the features in the disc within the deviation limit.
        fraction_ok: f64,
        /// Their rms deviation from the fitted affine lattice, per cent of the NN distance.
        rms_percent: f64,
        /// The largest accepted, per cent.
        limit_percent: f64,
    },
    /// A point has a NaN or infinite coordinate.
    #[error("a point is not finite: set {set}, index {index}")]
    NotFinite {
        /// Point set.
        set: usize,
        /// Index in the set.
        index: usize,
    },
    /// An option is outside its range.
    #[error("lattice_fit.{key} = {value} is outside its range {range}")]
    BadOption {
        /// The option's key.
        key: &'static str,
        /// The value given.
        value: f64,
        /// Its range.
        range: &'static str,
    },
    /// The indexing disc never covered every feature.
    #[error(
        "the lattice fit did not converge: the indexing disc reached {} after {iterations} \
         doublings without covering every feature ({} from the seed)",
        length(*.radius_m),
        length(*.farthest_m)
    )]
    NotConverged {
        /// Radius reached, metres.
        radius_m: f64,
        /// Distance of the farthest feature from the seed, metres.
        farthest_m: f64,
        /// Doublings made.
        iterations: usize,
    },
}

/// Most doublings of the indexing disc (from `initial_radius` NN distances, 40 doublings
/// cover 10^12 NN distances: any image).
pub const MAX_DISC_DOUBLINGS: usize = 40;

/// Largest RMS deviation of the features used in an indexing disc, as a fraction of the
/// nearest-neighbour distance: points scattered at random lie within half a lattice
/// constant of some site of a hexagonal lattice 90 % of the time, but with an RMS deviation
/// of about a third of it; a lattice's features deviate by a few per cent, a raw distorted
/// image's (the HOPG terrace before correction) by up to about a fifth.
pub const MAX_RMS_DEVIATION_FRACTION: f64 = 0.25;

/// Options of [`fit_lattice`]; [`LatticeFitOptions::validate`] checks each against its range.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LatticeFitOptions {
    /// Bonds count as nearest-neighbour bonds within `(1 ± window)` of the NN distance;
    /// 0.01 to 0.5.
    pub nn_window: f64,
    /// A feature farther than this fraction of the NN distance from its site is not used
    /// to fit (it is still indexed and reported); 0.01 to 1.
    pub max_deviation_fraction: f64,
    /// Radius of the first disc, in NN distances; 1 to 1000.
    pub initial_radius: f64,
    /// Minimum fraction of features within `max_deviation_fraction` at every stage; 0 to 1.
    pub min_fraction_ok: f64,
}

impl LatticeFitOptions {
    /// Checks every option against its documented range (finite; NaN is refused).
    pub fn validate(&self) -> Result<(), LatticeFitError> {
        let checks: [(&'static str, f64, f64, f64, &'static str); 4] = [
            ("nn_window", self.nn_window, 0.01, 0.5, "0.01..=0.5"),
            (
                "max_deviation_fraction",
                self.max_deviation_fraction,
                0.01,
                1.0,
                "0.01..=1",
            ),
            (
                "initial_radius",
                self.initial_radius,
                1.0,
                1000.0,
                "1..=1000 nearest-neighbour distances",
            ),
            ("min_fraction_ok", self.min_fraction_ok, 0.0, 1.0, "0..=1"),
        ];
        for (key, value, low, high, range) in checks {
            if !(value.is_finite() && (low..=high).contains(&value)) {
                return Err(LatticeFitError::BadOption { key, value, range });
            }
        }
        Ok(())
    }
}

impl Default for LatticeFitOptions {
    fn default() -> Self {
        LatticeFitOptions {
            nn_window: 0.35,
            max_deviation_fraction: 0.5,
            initial_radius: 4.0,
            min_fraction_ok: 0.8,
        }
    }
}

/// The angular distribution of nearest-neighbour bond directions.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AngularDistribution {
    /// Bin centres, radians in `[0, π)` (bonds are undirected).
    pub angles_rad: Vec<f64>,
    /// Bonds per bin.
    pub counts: Vec<usize>,
    /// Number of bonds.
    pub bonds: usize,
    /// Lattice rotation from the bond directions, radians, modulo `period_rad`.
    pub lattice_angle_rad: f64,
    /// Period of the lattice's bond directions (π/3 for hexagonal, π/2 for square).
    pub period_rad: f64,
    /// Median length of the nearest-neighbour bonds, metres (unbiased by noise, unlike the
    /// median distance to the nearest point, which is the minimum of several bonds).
    pub median_nn_m: f64,
}

/// The median (NaN for no values), the shared convention of [`dhct_numerics::robust`].
fn median(values: &mut [f64]) -> f64 {
    dhct_numerics::robust::median(values).unwrap_or(f64::NAN)
}

/// Distance from each point to its nearest other point (metres; infinite when alone).
fn nearest_distances(tree: &ImmutableKdTree<f64, 2>, points: &[[f64; 2]]) -> Vec<f64> {
    points
        .iter()
        .map(|p| {
            tree.query(p)
                .nearest_n::<SquaredEuclidean<f64>>(std::num::NonZeroUsize::new(2).expect("2 > 0"))
                .execute()
                .get(1)
                .map_or(f64::INFINITY, |n| n.distance.sqrt())
        })
        .collect()
}

/// Every bond (vector and length, metres) between points at a distance in `(lo, hi]`.
fn bonds_between(
    tree: &ImmutableKdTree<f64, 2>,
    points: &[[f64; 2]],
    lo: f64,
    hi: f64,
) -> Vec<([f64; 2], f64)> {
    let mut bonds = Vec::new();
    for (i, p) in points.iter().enumerate() {
        for neighbour in tree
            .query(p)
            .within::<SquaredEuclidean<f64>>(hi * hi)
            .unsorted()
            .execute()
        {
            let j = neighbour.item as usize;
            let d = neighbour.distance.sqrt();
            if j > i && d > lo {
                let q = points[j];
                bonds.push(([q[0] - p[0], q[1] - p[1]], d));
            }
        }
    }
    bonds
}

/// Bond-direction histogram of `points` (metres) and the lattice angle it implies. Bonds
/// count within `(1 ± w)` of the median nearest-point distance, with `w` the smaller of
/// `nn_window` and the lattice's [`Lattice::first_shell_window`]; the angle is measured
/// against [`Lattice::bond_directions`] modulo [`Lattice::bond_direction_period`].
pub fn angular_distribution(
    lattice: &dyn Lattice,
    points: &[[f64; 2]],
    nn_window: f64,
    bins: usize,
) -> Result<AngularDistribution, LatticeFitError> {
    let too_few = LatticeFitError::TooFewPoints {
        found: points.len(),
        needed: 3,
    };
    if points.len() < 3 {
        return Err(too_few);
    }
    let tree: ImmutableKdTree<f64, 2> =
        ImmutableKdTree::new_from_slice(points).map_err(|_| too_few)?;
    let median_nn = median(&mut nearest_distances(&tree, points));
    let window = nn_window.min(lattice.first_shell_window());
    let (lo, hi) = ((1.0 - window) * median_nn, (1.0 + window) * median_nn);
    let bonds = bonds_between(&tree, points, lo, hi);
    let mut counts = vec![0usize; bins.max(1)];
    let last = counts.len() - 1;
    for (bond, _) in &bonds {
        let angle = bond[1].atan2(bond[0]).rem_euclid(std::f64::consts::PI);
        let bin = ((angle / std::f64::consts::PI) * counts.len() as f64) as usize;
        counts[bin.min(last)] += 1;
    }
    let period = lattice.bond_direction_period();
    let rotation = estimate_rotation(
        bonds.iter().map(|(b, _)| *b),
        &lattice.bond_directions(),
        period,
    )
    .ok_or(LatticeFitError::NoBonds {
        median_nn_m: median_nn,
    })?;
    let width = std::f64::consts::PI / counts.len() as f64;
    let mut lengths: Vec<f64> = bonds.iter().map(|(_, d)| *d).collect();
    Ok(AngularDistribution {
        angles_rad: (0..counts.len())
            .map(|k| (k as f64 + 0.5) * width)
            .collect(),
        counts,
        bonds: bonds.len(),
        lattice_angle_rad: rotation.rem_euclid(period),
        period_rad: period,
        median_nn_m: median(&mut lengths),
    })
}

/// Linear least-squares affine lattice `p ≈ o + B·v` from indexed points.
fn fit_affine(
    lattice: &dyn Lattice,
    pairs: &[IndexedPosition],
) -> Option<(Vector2<f64>, Matrix2<f64>)> {
    // Unknowns per axis: [o, B_row0, B_row1]; the two axes decouple.
    let mut normal = nalgebra::Matrix3::<f64>::zeros();
    let mut rhs_x = nalgebra::Vector3::<f64>::zeros();
    let mut rhs_y = nalgebra::Vector3::<f64>::zeros();
    for (p, (n, m, site)) in pairs {
        let v = lattice_vector(lattice, *n, *m, *site);
        let basis = nalgebra::Vector3::new(1.0, v.x, v.y);
        normal += basis * basis.transpose();
        rhs_x += basis * p.x;
        rhs_y += basis * p.y;
    }
    let cholesky = normal.cholesky()?;
    let (cx, cy) = (cholesky.solve(&rhs_x), cholesky.solve(&rhs_y));
    Some((
        Vector2::new(cx[0], cy[0]),
        Matrix2::new(cx[1], cx[2], cy[1], cy[2]),
    ))
}

/// What the coarse-to-fine indexing of the seed set works with.
struct Indexing<'a> {
    lattice: &'a dyn Lattice,
    points: &'a [[f64; 2]],
    options: &'a LatticeFitOptions,
    /// The feature nearest the centroid, metres.
    seed: Vector2<f64>,
    /// Its distance to the farthest feature, metres.
    farthest: f64,
    /// Measured nearest-neighbour distance, metres.
    nn: f64,
    /// Features needed in every disc.
    needed: usize,
}

/// An affine lattice `p ≈ o + B·v`: origin (metres) and map.
type Affine = (Vector2<f64>, Matrix2<f64>);

impl Indexing<'_> {
    /// Indexes the features within `radius` of the seed with the model `(origin, b)` and
    /// refits it to those within the deviation limit.
    fn disc_step(
        &self,
        (origin, b): Affine,
        radius: f64,
    ) -> Result<(Affine, f64), LatticeFitError> {
        let diverged = |fraction: f64| LatticeFitError::Diverged {
            radius_m: radius,
            fraction_ok: 100.0 * fraction,
        };
        let inverse = b.try_inverse().ok_or(diverged(0.0))?;
        let max_deviation = self.options.max_deviation_fraction * self.nn;
        let mut pairs = Vec::new();
        let mut included = 0usize;
        for p in self.points.iter().map(|p| Vector2::from(*p)) {
            if (p - self.seed).norm() > radius {
                continue;
            }
            included += 1;
            let (n, m, site, error) = nearest_site(self.lattice, origin, &b, &inverse, p);
            if error.sqrt() <= max_deviation {
                pairs.push((p, (n, m, site)));
            }
        }
        let fraction = pairs.len() as f64 / included.max(1) as f64;
        if included < self.needed {
            return Err(LatticeFitError::SparseSeed {
                radius_m: radius,
                found: included,
                needed: self.needed,
                median_nn_m: self.nn,
            });
        }
        if fraction < self.options.min_fraction_ok {
            return Err(diverged(fraction));
        }
        let (origin, b) = fit_affine(self.lattice, &pairs).ok_or(diverged(fraction))?;
        let mean_square = pairs
            .iter()
            .map(|(p, (n, m, s))| {
                (p - origin - b * lattice_vector(self.lattice, *n, *m, *s)).norm_squared()
            })
            .sum::<f64>()
            / pairs.len() as f64;
        if mean_square.sqrt() > MAX_RMS_DEVIATION_FRACTION * self.nn {
            return Err(LatticeFitError::TooScattered {
                radius_m: radius,
                fraction_ok: 100.0 * fraction,
                rms_percent: 100.0 * mean_square.sqrt() / self.nn,
                limit_percent: 100.0 * MAX_RMS_DEVIATION_FRACTION,
            });
        }
        // Prefer more points at equal cost.
        Ok(((origin, b), mean_square - pairs.len() as f64 * 1e-30))
    }

    /// Coarse-to-fine indexing from the seed taken as motif site `site`, the lattice
    /// rotated by `angle` and scaled by `scale`: the final affine model and its mean
    /// squared deviation.
    fn index_from_seed(
        &self,
        angle: f64,
        scale: f64,
        site: usize,
    ) -> Result<(f64, Affine), LatticeFitError> {
        let b = transform(angle, [scale, scale]);
        let mut model = (self.seed - b * self.lattice.site_position(site), b);
        let mut radius = self.options.initial_radius * self.nn;
        for doublings in 0.. {
            let (refitted, cost) = self.disc_step(model, radius)?;
            model = refitted;
            if radius >= self.farthest {
                return Ok((cost, model));
            }
            if doublings >= MAX_DISC_DOUBLINGS || !radius.is_finite() {
                return Err(LatticeFitError::NotConverged {
                    radius_m: radius,
                    farthest_m: self.farthest,
                    iterations: doublings,
                });
            }
            radius *= 2.0;
        }
        unreachable!("the loop returns")
    }

    /// The best affine model over every candidate rotation (one per bond-direction period
    /// in a full turn) and every motif site the seed may be.
    fn best(&self, adf: &AngularDistribution, scale: f64) -> Result<Affine, LatticeFitError> {
        let candidates = (2.0 * std::f64::consts::PI / adf.period_rad)
            .round()
            .max(1.0) as usize;
        let mut best: Option<(f64, Affine)> = None;
        let mut last_error = None;
        for k in 0..candidates {
            let angle = adf.lattice_angle_rad + k as f64 * adf.period_rad;
            for site in 0..self.lattice.motif().len() {
                match self.index_from_seed(angle, scale, site) {
                    Ok((cost, model))
                        if best.as_ref().is_none_or(|(c, _)| cost < *c * (1.0 - 1e-9)) =>
                    {
                        best = Some((cost, model));
                    }
                    Ok(_) => {}
                    Err(error) => last_error = Some(error),
                }
            }
        }
        best.map(|(_, model)| model).ok_or_else(|| {
            last_error.unwrap_or(LatticeFitError::Diverged {
                radius_m: 0.0,
                fraction_ok: 0.0,
            })
        })
    }
}

/// Checks the options and that every point is finite.
fn check_inputs(sets: &[&[[f64; 2]]], options: &LatticeFitOptions) -> Result<(), LatticeFitError> {
    options.validate()?;
    for (set, points) in sets.iter().enumerate() {
        if let Some(index) = points
            .iter()
            .position(|p| !(p[0].is_finite() && p[1].is_finite()))
        {
            return Err(LatticeFitError::NotFinite { set, index });
        }
    }
    Ok(())
}

/// The point nearest the centroid of `points` (not empty) and its distance to the farthest.
fn central_point(points: &[[f64; 2]]) -> (Vector2<f64>, f64) {
    let centroid = points
        .iter()
        .fold(Vector2::zeros(), |acc, p| acc + Vector2::from(*p))
        / points.len() as f64;
    let seed = points
        .iter()
        .map(|p| Vector2::from(*p))
        .min_by(|a, b| (a - centroid).norm().total_cmp(&(b - centroid).norm()))
        .unwrap_or(centroid);
    let farthest = points
        .iter()
        .map(|p| (Vector2::from(*p) - seed).norm())
        .fold(0.0, f64::max);
    (seed, farthest)
}

/// Fits one lattice to one or more point sets (metres; e.g. trace and retrace features in
/// the sample frame) and indexes every point.
pub fn fit_lattice(
    lattice: &dyn Lattice,
    sets: &[&[[f64; 2]]],
    options: &LatticeFitOptions,
) -> Result<LatticeFit, LatticeFitError> {
    fit_lattice_from(lattice, sets, options, None)
}

/// [`fit_lattice`] of positions already at the lattice's own scale (corrected into the
/// sample frame against its constant): the indexing starts from the lattice's
/// nearest-neighbour distance instead of the features' median one. On noisy positions the
/// median is short (each feature's nearest of about six noisy neighbours), and an indexing
/// started short can slip a row over a few cells and settle on a lattice compressed by one
/// row in eight, as the features of a small noisy frame around a defect did (h-BN, 8
/// periods: 0.87 of the constant along x, against 1.00 by the atoms' minima).
pub fn fit_calibrated_lattice(
    lattice: &dyn Lattice,
    sets: &[&[[f64; 2]]],
    options: &LatticeFitOptions,
) -> Result<LatticeFit, LatticeFitError> {
    fit_lattice_from(lattice, sets, options, Some(1.0))
}

/// [`fit_lattice`], starting the indexing at `known_scale` × the lattice's constant when
/// given, else at the features' median neighbour distance.
fn fit_lattice_from(
    lattice: &dyn Lattice,
    sets: &[&[[f64; 2]]],
    options: &LatticeFitOptions,
    known_scale: Option<f64>,
) -> Result<LatticeFit, LatticeFitError> {
    check_inputs(sets, options)?;
    let seed_set = sets.first().copied().unwrap_or_default();
    let needed = 4 * lattice.motif().len() + 3;
    if seed_set.len() < needed {
        return Err(LatticeFitError::TooFewPoints {
            found: seed_set.len(),
            needed,
        });
    }
    let adf = angular_distribution(lattice, seed_set, options.nn_window, 180)?;
    let (seed, farthest) = central_point(seed_set);
    let scale0 = known_scale.unwrap_or(adf.median_nn_m / lattice.nearest_neighbour_distance());
    let nn = scale0 * lattice.nearest_neighbour_distance();
    let indexing = Indexing {
        lattice,
        points: seed_set,
        options,
        seed,
        farthest,
        nn,
        needed,
    };
    let (origin, b) = indexing.best(&adf, scale0)?;
    let diverged = LatticeFitError::Diverged {
        radius_m: farthest,
        fraction_ok: 0.0,
    };
    let inverse = b.try_inverse().ok_or(diverged)?;
    // Index every set with the affine model, then refine (o, θ, sx, sy, Δ_k).
    let indexed: Vec<Vec<IndexedPosition>> = sets
        .iter()
        .map(|points| {
            points
                .iter()
                .map(|p| {
                    let p = Vector2::from(*p);
                    let (n, m, site, _) = nearest_site(lattice, origin, &b, &inverse, p);
                    (p, (n, m, site))
                })
                .collect()
        })
        .collect();
    let max_deviation = options.max_deviation_fraction * nn;
    let fit = refine(lattice, &indexed, (origin, b), max_deviation, nn);
    reindex(lattice, fit, &indexed).ok_or(LatticeFitError::Diverged {
        radius_m: farthest,
        fraction_ok: 0.0,
    })
}
