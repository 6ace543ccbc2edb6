//! The final stage of the whole-image lattice fit: Gauss–Newton refinement of
//! `(o, θ, s_x, s_y, Δ_k)` over every indexed point set, and the re-indexing of every point
//! with the refined model (see `fit.rs` for the model).

use nalgebra::{DMatrix, DVector, Matrix2, Vector2};

use crate::Lattice;
use crate::fit_result::{
    IndexedPoint, IndexedPosition, LatticeFit, MAX_GAUSS_NEWTON_ITERATIONS, lattice_vector,
    nearest_site, transform,
};

/// The rotation θ and scales `(s_x, s_y)` of `B = D·R(θ)`: the row norms are the scales, the
/// angle the mean of both rows' angles.
fn decompose(b: &Matrix2<f64>) -> (f64, [f64; 2]) {
    use std::f64::consts::PI;
    let (sx, sy) = (b.row(0).norm(), b.row(1).norm());
    let (angle_a, angle_b) = ((-b[(0, 1)]).atan2(b[(0, 0)]), b[(1, 0)].atan2(b[(1, 1)]));
    let angle = angle_a + 0.5 * (angle_b - angle_a + PI).rem_euclid(2.0 * PI) - 0.5 * PI;
    (angle, [sx, sy])
}

/// The offset `Δ_set` in the parameter vector (zero for set 0).
fn set_offset(params: &DVector<f64>, set: usize) -> Vector2<f64> {
    if set == 0 {
        Vector2::zeros()
    } else {
        Vector2::new(params[5 + 2 * (set - 1)], params[6 + 2 * (set - 1)])
    }
}

/// One Gauss–Newton system: normal matrix, right-hand side, sum of squared residuals and
/// number of points used (those within `max_deviation`).
struct NormalEquations {
    normal: DMatrix<f64>,
    rhs: DVector<f64>,
    sum_sq: f64,
    used: usize,
}

/// The normal equations of the model at `params` over the indexed points.
fn normal_equations(
    lattice: &dyn Lattice,
    indexed: &[Vec<IndexedPosition>],
    params: &DVector<f64>,
    max_deviation: f64,
) -> NormalEquations {
    let count = params.len();
    let t = transform(params[2], [params[3], params[4]]);
    let (sin, cos) = params[2].sin_cos();
    let mut eq = NormalEquations {
        normal: DMatrix::zeros(count, count),
        rhs: DVector::zeros(count),
        sum_sq: 0.0,
        used: 0,
    };
    for (set, points) in indexed.iter().enumerate() {
        let offset = set_offset(params, set);
        for (p, (n, m, site)) in points {
            let v = lattice_vector(lattice, *n, *m, *site);
            let r = p - (Vector2::new(params[0], params[1]) + offset + t * v);
            if r.norm() > max_deviation {
                continue;
            }
            eq.sum_sq += r.norm_squared();
            eq.used += 1;
            let rotated = Vector2::new(cos * v.x - sin * v.y, sin * v.x + cos * v.y);
            let d_theta = Vector2::new(
                params[3] * (-sin * v.x - cos * v.y),
                params[4] * (cos * v.x - sin * v.y),
            );
            // The gradient's non-zeros only: a long series has hundreds of sets, and a
            // dense outer product per point would cost the square of that.
            for axis in 0..2 {
                let mut g = [
                    (axis, 1.0),
                    (2, d_theta[axis]),
                    (3 + axis, rotated[axis]),
                    (0, 0.0),
                ];
                let used = if set > 0 {
                    g[3] = (5 + 2 * (set - 1) + axis, 1.0);
                    4
                } else {
                    3
                };
                for &(a, ga) in &g[..used] {
                    eq.rhs[a] += ga * r[axis];
                    for &(b, gb) in &g[..used] {
                        eq.normal[(a, b)] += ga * gb;
                    }
                }
            }
        }
    }
    eq
}

/// Refines `(o, θ, s_x, s_y, Δ_k)` from the affine model `(origin, b)` by Gauss–Newton over
/// the points within `max_deviation` (metres) of their sites; `nn` (metres) sets the step
/// tolerance. The fit's `points` are left empty (see [`reindex`]).
pub(crate) fn refine(
    lattice: &dyn Lattice,
    indexed: &[Vec<IndexedPosition>],
    (origin, b): (Vector2<f64>, Matrix2<f64>),
    max_deviation: f64,
    nn: f64,
) -> LatticeFit {
    let (angle, [sx, sy]) = decompose(&b);
    let count = 5 + 2 * indexed.len().saturating_sub(1);
    let mut params = DVector::<f64>::zeros(count);
    params[0] = origin.x;
    params[1] = origin.y;
    params[2] = angle;
    params[3] = sx;
    params[4] = sy;
    let (mut used, mut rms, mut converged) = (0, f64::NAN, false);
    for _ in 0..MAX_GAUSS_NEWTON_ITERATIONS {
        let eq = normal_equations(lattice, indexed, &params, max_deviation);
        used = eq.used;
        rms = (eq.sum_sq / eq.used.max(1) as f64).sqrt();
        let Some(step) = eq.normal.cholesky().map(|c| c.solve(&eq.rhs)) else {
            break;
        };
        params += &step;
        if step.iter().take(2).all(|v| v.abs() < 1e-6 * nn) && step[2].abs() < 1e-12 {
            converged = true;
            break;
        }
    }
    LatticeFit {
        origin_m: [params[0], params[1]],
        angle_rad: params[2],
        scale: [params[3], params[4]],
        set_offsets_m: (0..indexed.len())
            .map(|set| {
                let o = set_offset(&params, set);
                [o.x, o.y]
            })
            .collect(),
        points: Vec::new(),
        rms_deviation_m: rms,
        used,
        converged,
    }
}

/// `fit` with every point re-indexed by its own model and its deviation reported; `None`
/// when the fitted map is singular.
pub(crate) fn reindex(
    lattice: &dyn Lattice,
    fit: LatticeFit,
    indexed: &[Vec<IndexedPosition>],
) -> Option<LatticeFit> {
    let t = fit.transform();
    let inverse = t.try_inverse()?;
    let points = indexed
        .iter()
        .enumerate()
        .map(|(set, points)| {
            let origin = Vector2::from(fit.origin_m) + Vector2::from(fit.set_offsets_m[set]);
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
    Some(LatticeFit { points, ..fit })
}
