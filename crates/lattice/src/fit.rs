//! Whole-image lattice fit with integer indices (DHCT paper §V; not in the authors' Matlab).
//!
//! Model: the feature of motif site `s` in cell `(n, m)` lies at
//! `p = o + Δ_k + D(s_x, s_y)·R(θ)·(n·a1 + m·a2 + f_s)` (metres), where `a1`, `a2`, `f_s` are
//! the lattice's primitive vectors and motif position, `R(θ)` a rotation by θ (from +x towards
//! +y), `D` the scales along the image x and y axes, `o` the origin and `Δ_k` the offset of
//! point set `k` (e.g. retrace relative to trace; `Δ_0 = 0`).
//!
//! Procedure: the angular distribution of nearest-neighbour bonds gives θ (modulo the
//! lattice's bond symmetry; every candidate is tried), the median NN distance the scale, and
//! the feature nearest the centroid the origin. Indices are then assigned coarse-to-fine:
//! within a disc of a few lattice constants, an affine lattice is fitted by linear least
//! squares and the disc doubles until it covers every feature, each time checking that the
//! current model predicts the included features to better than half a lattice constant
//! (otherwise the fit stops with an error rather than mis-indexing). A final Gauss–Newton fit
//! of (o, θ, s_x, s_y, Δ_k) to all sets follows.

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::{DMatrix, DVector, Matrix2, Vector2};
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::{Lattice, mean_bond_rotation};

/// Why a lattice could not be fitted.
#[derive(Debug, Error)]
pub enum LatticeFitError {
    #[error("{found} features are too few for a lattice fit (at least {needed} are needed)")]
    TooFewPoints { found: usize, needed: usize },
    #[error(
        "no nearest-neighbour bonds were found (median NN distance {median_nn_m:e} m): the features \
         do not form a lattice, or the lattice does not match"
    )]
    NoBonds { median_nn_m: f64 },
    #[error(
        "the lattice fit diverged: within {radius_m:e} m of the seed only {fraction_ok:.0} % of the \
         features lie within half a lattice constant of a site. Check the lattice type and constant, \
         or fit one domain (mask region) at a time"
    )]
    Diverged { radius_m: f64, fraction_ok: f64 },
    #[error("a point is not finite: set {set}, index {index}")]
    NotFinite { set: usize, index: usize },
    #[error("lattice_fit.{key} = {value} is outside its range {range}")]
    BadOption {
        key: &'static str,
        value: f64,
        range: &'static str,
    },
    #[error(
        "the lattice fit did not converge: the indexing disc reached {radius_m:e} m after \
         {iterations} doublings without covering every feature ({farthest_m:e} m from the seed)"
    )]
    NotConverged {
        radius_m: f64,
        farthest_m: f64,
        iterations: usize,
    },
}

/// Most doublings of the indexing disc (from `initial_radius` NN distances, 40 doublings
/// cover 10^12 NN distances: any image).
pub const MAX_DISC_DOUBLINGS: usize = 40;

/// Gauss–Newton iterations of the final fit.
pub const MAX_GAUSS_NEWTON_ITERATIONS: usize = 20;

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

/// A feature's lattice site and its deviation from it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct IndexedPoint {
    /// Cell index along a1.
    pub n: i64,
    /// Cell index along a2.
    pub m: i64,
    /// Motif site.
    pub site: usize,
    /// Observed minus fitted position, metres.
    pub deviation_m: [f64; 2],
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

/// The fitted lattice.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LatticeFit {
    /// Origin `o`, metres.
    pub origin_m: [f64; 2],
    /// Rotation θ, radians (from +x towards +y).
    pub angle_rad: f64,
    /// Scales `s_x`, `s_y` along the image axes (1 = the lattice's nominal size).
    pub scale: [f64; 2],
    /// Offset `Δ_k` of each point set relative to set 0, metres.
    pub set_offsets_m: Vec<[f64; 2]>,
    /// Every input point indexed, per set, in input order.
    pub points: Vec<Vec<IndexedPoint>>,
    /// RMS deviation of the points used in the final fit, metres.
    pub rms_deviation_m: f64,
    /// Points used in the final fit.
    pub used: usize,
    /// Whether the final Gauss–Newton fit met its step tolerance within
    /// [`MAX_GAUSS_NEWTON_ITERATIONS`]; false means the parameters are those of the last
    /// iteration (reported, not an error).
    #[serde(default = "converged_default")]
    pub converged: bool,
}

fn converged_default() -> bool {
    true
}

impl LatticeFit {
    /// The linear map `D·R` from lattice-frame to image-frame vectors.
    pub fn transform(&self) -> Matrix2<f64> {
        transform(self.angle_rad, self.scale)
    }

    /// Fitted position of site `(n, m, site)` in point set `set`, metres.
    pub fn site_position(
        &self,
        lattice: &dyn Lattice,
        n: i64,
        m: i64,
        site: usize,
        set: usize,
    ) -> [f64; 2] {
        let p = Vector2::from(self.origin_m)
            + Vector2::from(self.set_offsets_m[set])
            + self.transform() * lattice_vector(lattice, n, m, site);
        [p.x, p.y]
    }
}

/// Cell indices `(n, m)` and motif site of a feature.
type SiteIndex = (i64, i64, usize);

/// A position (metres) with its site.
type IndexedPosition = (Vector2<f64>, SiteIndex);

fn transform(angle: f64, scale: [f64; 2]) -> Matrix2<f64> {
    let (sin, cos) = angle.sin_cos();
    Matrix2::new(
        scale[0] * cos,
        -scale[0] * sin,
        scale[1] * sin,
        scale[1] * cos,
    )
}

fn lattice_vector(lattice: &dyn Lattice, n: i64, m: i64, site: usize) -> Vector2<f64> {
    let [a1, a2] = lattice.primitive_vectors();
    a1 * n as f64 + a2 * m as f64 + lattice.site_position(site)
}

fn median(values: &mut [f64]) -> f64 {
    let middle = values.len() / 2;
    *values.select_nth_unstable_by(middle, f64::total_cmp).1
}

/// Bond-direction histogram of `points` (metres) and the lattice angle it implies.
pub fn angular_distribution(
    lattice: &dyn Lattice,
    points: &[[f64; 2]],
    nn_window: f64,
    bins: usize,
) -> Result<AngularDistribution, LatticeFitError> {
    if points.len() < 3 {
        return Err(LatticeFitError::TooFewPoints {
            found: points.len(),
            needed: 3,
        });
    }
    let tree: ImmutableKdTree<f64, 2> =
        ImmutableKdTree::new_from_slice(points).map_err(|_| LatticeFitError::TooFewPoints {
            found: points.len(),
            needed: 3,
        })?;
    let mut nearest: Vec<f64> = points
        .iter()
        .map(|p| {
            tree.query(p)
                .nearest_n::<SquaredEuclidean<f64>>(std::num::NonZeroUsize::new(2).expect("2 > 0"))
                .execute()
                .get(1)
                .map_or(f64::INFINITY, |n| n.distance.sqrt())
        })
        .collect();
    let median_nn = median(&mut nearest);
    // Ideal bond directions modulo π and their period.
    let mut ideal: Vec<f64> = (0..lattice.motif().len())
        .flat_map(|s| lattice.nearest_neighbours(s))
        .filter(|v| (v.norm() - lattice.nearest_neighbour_distance()).abs() < 1e-6 * v.norm())
        .map(|v| v.y.atan2(v.x).rem_euclid(std::f64::consts::PI))
        .collect();
    ideal.sort_by(f64::total_cmp);
    ideal.dedup_by(|a, b| (*a - *b).abs() < 1e-6);
    let period = std::f64::consts::PI / ideal.len().max(1) as f64;
    let reference = ideal.first().copied().unwrap_or(0.0);
    let (lo, hi) = ((1.0 - nn_window) * median_nn, (1.0 + nn_window) * median_nn);
    let mut counts = vec![0usize; bins.max(1)];
    let mut bond_vectors = Vec::new();
    let mut lengths = Vec::new();
    for (i, p) in points.iter().enumerate() {
        for neighbour in tree
            .query(p)
            .within::<SquaredEuclidean<f64>>(hi * hi)
            .unsorted()
            .execute()
        {
            let j = neighbour.item as usize;
            let d = neighbour.distance.sqrt();
            if j <= i || d <= lo {
                continue;
            }
            let q = points[j];
            let bond = [q[0] - p[0], q[1] - p[1]];
            let angle = bond[1].atan2(bond[0]).rem_euclid(std::f64::consts::PI);
            let last = counts.len() - 1;
            let bin = ((angle / std::f64::consts::PI) * counts.len() as f64) as usize;
            counts[bin.min(last)] += 1;
            bond_vectors.push(bond);
            lengths.push(d);
        }
    }
    let bonds = bond_vectors.len();
    let Some(rotation) = mean_bond_rotation(bond_vectors, reference, period) else {
        return Err(LatticeFitError::NoBonds {
            median_nn_m: median_nn,
        });
    };
    let lattice_angle = rotation.rem_euclid(period);
    let width = std::f64::consts::PI / counts.len() as f64;
    Ok(AngularDistribution {
        angles_rad: (0..counts.len())
            .map(|k| (k as f64 + 0.5) * width)
            .collect(),
        counts,
        bonds,
        lattice_angle_rad: lattice_angle,
        period_rad: period,
        median_nn_m: median(&mut lengths),
    })
}

/// The site nearest to `p` under the affine model `p ≈ o + B·v`: indices and squared error.
fn nearest_site(
    lattice: &dyn Lattice,
    origin: Vector2<f64>,
    b: &Matrix2<f64>,
    inverse: &Matrix2<f64>,
    p: Vector2<f64>,
) -> (i64, i64, usize, f64) {
    let [a1, a2] = lattice.primitive_vectors();
    let cell = Matrix2::from_columns(&[a1, a2]);
    let cell_inverse = cell.try_inverse().unwrap_or_else(Matrix2::identity);
    let lattice_frame = inverse * (p - origin);
    let mut best = (0, 0, 0, f64::INFINITY);
    for site in 0..lattice.motif().len() {
        let f = cell_inverse * (lattice_frame - lattice.site_position(site));
        let (n, m) = (f.x.round() as i64, f.y.round() as i64);
        let fitted = origin + b * lattice_vector(lattice, n, m, site);
        let error = (p - fitted).norm_squared();
        if error < best.3 {
            best = (n, m, site, error);
        }
    }
    best
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

/// Fits one lattice to one or more point sets (metres; e.g. trace and retrace features in
/// the sample frame) and indexes every point.
pub fn fit_lattice(
    lattice: &dyn Lattice,
    sets: &[&[[f64; 2]]],
    options: &LatticeFitOptions,
) -> Result<LatticeFit, LatticeFitError> {
    options.validate()?;
    for (set, points) in sets.iter().enumerate() {
        if let Some(index) = points
            .iter()
            .position(|p| !(p[0].is_finite() && p[1].is_finite()))
        {
            return Err(LatticeFitError::NotFinite { set, index });
        }
    }
    let seed_set = sets.first().copied().unwrap_or_default();
    let needed = 4 * lattice.motif().len() + 3;
    if seed_set.len() < needed {
        return Err(LatticeFitError::TooFewPoints {
            found: seed_set.len(),
            needed,
        });
    }
    let adf = angular_distribution(lattice, seed_set, options.nn_window, 180)?;
    let scale0 = adf.median_nn_m / lattice.nearest_neighbour_distance();
    let centroid = seed_set
        .iter()
        .fold(Vector2::zeros(), |acc, p| acc + Vector2::from(*p))
        / seed_set.len() as f64;
    let seed = seed_set
        .iter()
        .map(|p| Vector2::from(*p))
        .min_by(|a, b| (a - centroid).norm().total_cmp(&(b - centroid).norm()))
        .expect("the seed set is not empty");
    let nn = adf.median_nn_m;
    let max_deviation = options.max_deviation_fraction * nn;
    let farthest = seed_set
        .iter()
        .map(|p| (Vector2::from(*p) - seed).norm())
        .fold(0.0, f64::max);

    // Coarse-to-fine indexing for every candidate angle; keep the best.
    let candidates = (2.0 * std::f64::consts::PI / adf.period_rad)
        .round()
        .max(1.0) as usize;
    let mut best: Option<(f64, Vector2<f64>, Matrix2<f64>)> = None;
    let mut last_error = None;
    for k in 0..candidates {
        let angle = adf.lattice_angle_rad + k as f64 * adf.period_rad;
        let mut b = transform(angle, [scale0, scale0]);
        let mut origin = seed - b * lattice.site_position(0);
        let mut radius = options.initial_radius * nn;
        let mut doublings = 0;
        let outcome = loop {
            let Some(inverse) = b.try_inverse() else {
                break Err(LatticeFitError::Diverged {
                    radius_m: radius,
                    fraction_ok: 0.0,
                });
            };
            let mut pairs = Vec::new();
            let mut included = 0usize;
            for p in seed_set.iter().map(|p| Vector2::from(*p)) {
                if (p - seed).norm() > radius {
                    continue;
                }
                included += 1;
                let (n, m, site, error) = nearest_site(lattice, origin, &b, &inverse, p);
                if error.sqrt() <= max_deviation {
                    pairs.push((p, (n, m, site)));
                }
            }
            let fraction = pairs.len() as f64 / included.max(1) as f64;
            if included < needed || fraction < options.min_fraction_ok {
                break Err(LatticeFitError::Diverged {
                    radius_m: radius,
                    fraction_ok: 100.0 * fraction,
                });
            }
            match fit_affine(lattice, &pairs) {
                Some((o, new_b)) => {
                    origin = o;
                    b = new_b;
                }
                None => {
                    break Err(LatticeFitError::Diverged {
                        radius_m: radius,
                        fraction_ok: 100.0 * fraction,
                    });
                }
            }
            if radius >= farthest {
                let cost: f64 = pairs
                    .iter()
                    .map(|(p, (n, m, s))| {
                        (p - origin - b * lattice_vector(lattice, *n, *m, *s)).norm_squared()
                    })
                    .sum::<f64>()
                    / pairs.len() as f64
                    - pairs.len() as f64 * 1e-30; // prefer more points at equal cost
                break Ok(cost);
            }
            if doublings >= MAX_DISC_DOUBLINGS || !radius.is_finite() {
                break Err(LatticeFitError::NotConverged {
                    radius_m: radius,
                    farthest_m: farthest,
                    iterations: doublings,
                });
            }
            radius *= 2.0;
            doublings += 1;
        };
        match outcome {
            Ok(cost)
                if best
                    .as_ref()
                    .is_none_or(|(c, _, _)| cost < *c * (1.0 - 1e-9)) =>
            {
                best = Some((cost, origin, b));
            }
            Ok(_) => {}
            Err(error) => last_error = Some(error),
        }
    }
    let Some((_, origin, b)) = best else {
        return Err(last_error.unwrap_or(LatticeFitError::Diverged {
            radius_m: 0.0,
            fraction_ok: 0.0,
        }));
    };

    // Decompose B = D·R: row norms are the scales, the angle the mean of both rows' angles.
    let (sx, sy) = (b.row(0).norm(), b.row(1).norm());
    let (angle_a, angle_b) = ((-b[(0, 1)]).atan2(b[(0, 0)]), b[(1, 0)].atan2(b[(1, 1)]));
    let angle = angle_a
        + 0.5 * (angle_b - angle_a + std::f64::consts::PI).rem_euclid(2.0 * std::f64::consts::PI)
        - 0.5 * std::f64::consts::PI;
    let inverse = b.try_inverse().ok_or(LatticeFitError::Diverged {
        radius_m: farthest,
        fraction_ok: 0.0,
    })?;

    // Index every set with the affine model, then refine (o, θ, sx, sy, Δ_k) by Gauss–Newton.
    let mut indexed: Vec<Vec<IndexedPosition>> = sets
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
    let count = 5 + 2 * sets.len().saturating_sub(1);
    let mut params = DVector::<f64>::zeros(count);
    params[0] = origin.x;
    params[1] = origin.y;
    params[2] = angle;
    params[3] = sx;
    params[4] = sy;
    let mut used = 0;
    let mut rms = f64::NAN;
    let mut converged = false;
    for _ in 0..MAX_GAUSS_NEWTON_ITERATIONS {
        let t = transform(params[2], [params[3], params[4]]);
        let (sin, cos) = params[2].sin_cos();
        let mut normal = DMatrix::<f64>::zeros(count, count);
        let mut rhs = DVector::<f64>::zeros(count);
        let (mut sum_sq, mut n_used) = (0.0, 0usize);
        for (set, points) in indexed.iter().enumerate() {
            let offset = if set == 0 {
                Vector2::zeros()
            } else {
                Vector2::new(params[5 + 2 * (set - 1)], params[6 + 2 * (set - 1)])
            };
            for (p, (n, m, site)) in points {
                let v = lattice_vector(lattice, *n, *m, *site);
                let r = p - (Vector2::new(params[0], params[1]) + offset + t * v);
                if r.norm() > max_deviation {
                    continue;
                }
                sum_sq += r.norm_squared();
                n_used += 1;
                let rotated = Vector2::new(cos * v.x - sin * v.y, sin * v.x + cos * v.y);
                let d_theta = Vector2::new(
                    params[3] * (-sin * v.x - cos * v.y),
                    params[4] * (cos * v.x - sin * v.y),
                );
                for axis in 0..2 {
                    let mut g = DVector::<f64>::zeros(count);
                    g[axis] = 1.0;
                    g[2] = d_theta[axis];
                    g[3 + axis] = rotated[axis];
                    if set > 0 {
                        g[5 + 2 * (set - 1) + axis] = 1.0;
                    }
                    normal += &g * g.transpose();
                    rhs += &g * r[axis];
                }
            }
        }
        used = n_used;
        rms = (sum_sq / n_used.max(1) as f64).sqrt();
        let Some(step) = normal.cholesky().map(|c| c.solve(&rhs)) else {
            break;
        };
        params += &step;
        if step.iter().take(2).all(|v| v.abs() < 1e-6 * nn) && step[2].abs() < 1e-12 {
            converged = true;
            break;
        }
    }
    // Re-index with the final model and report deviations.
    let final_fit = LatticeFit {
        origin_m: [params[0], params[1]],
        angle_rad: params[2],
        scale: [params[3], params[4]],
        set_offsets_m: (0..sets.len())
            .map(|set| {
                if set == 0 {
                    [0.0, 0.0]
                } else {
                    [params[5 + 2 * (set - 1)], params[6 + 2 * (set - 1)]]
                }
            })
            .collect(),
        points: Vec::new(),
        rms_deviation_m: rms,
        used,
        converged,
    };
    let t = final_fit.transform();
    let inverse = t.try_inverse().ok_or(LatticeFitError::Diverged {
        radius_m: farthest,
        fraction_ok: 0.0,
    })?;
    let points = indexed
        .iter_mut()
        .enumerate()
        .map(|(set, points)| {
            let origin =
                Vector2::from(final_fit.origin_m) + Vector2::from(final_fit.set_offsets_m[set]);
            points
                .iter()
                .map(|(p, _)| {
                    let (n, m, site, _) = nearest_site(lattice, origin, &t, &inverse, *p);
                    let r = p - origin - t * lattice_vector(lattice, n, m, site);
                    IndexedPoint {
                        n,
                        m,
                        site,
                        deviation_m: [r.x, r.y],
                    }
                })
                .collect()
        })
        .collect();
    Ok(LatticeFit {
        points,
        ..final_fit
    })
}
