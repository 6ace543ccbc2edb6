//! Local distortion at each selected feature from its nearest neighbours.
//!
//! # Derivation (exact kinematic form)
//!
//! Work in the pass's scan basis: `ê_f` along that pass's fast direction, `ê_s` along the
//! slow direction (display frame). The tip at controller position `p_c` is at sample
//! position `p_s = p_c + d(t(p_c), τ(p_c))` (see [`crate::model`]). Moving the controller by
//! `δ` along `ê_f` takes `δ/v_f` seconds (fast speed `v_f`) and advances the line time by the
//! same; along `ê_s`, `δ/v_s` seconds (`v_s = pitch_s/(2·T_L)`). With `D = ∂d/∂t` (drift +
//! creep velocity) and `∂d/∂τ = −v_f·(S − 1)·ê_f` (fast hysteresis, both passes), the local
//! sample-per-controller map is, in `(ê_f, ê_s)` components,
//!
//! ```text
//! J = [ 2 − S + D_f/v_f    D_f/v_s     ]
//!     [ D_s/v_f            1 + D_s/v_s ]
//! ```
//!
//! `D_s/v_f` is ~10⁻⁴ (it is a tiny rotation), so `J` is upper triangular and is fixed
//! uniquely by the observed neighbours up to a rotation of the sample:
//!
//! * **Ellipse** (lattices whose NNs lie on a circle of radius `r0`, the paper's eq. 6): a
//!   conic `A f² + B f s + C s² + D f + E s = 1` is fitted to the NN positions (free centre);
//!   its centred matrix `E` satisfies `E = JᵀJ/r0²`, so the Cholesky factor of `r0²·E` is
//!   `Jᵀ`. This is the same as the paper's `h`, `w`, `s_c` (`h = r0/j22`, `w = r0/j11`) but
//!   without the first-order approximations (and with `h`, not `r0`, in the right places).
//! * **Affine** (any lattice): the ideal NN vectors `u` (rotated by the globally estimated
//!   lattice angle) are matched to the observed ones `c` by direction, `M` minimises
//!   `Σ|c − M u|²`, and its RQ decomposition `M = K·R(ψ)` (K upper triangular) gives
//!   `J = K⁻¹`; `ψ` is the local rotation.
//!
//! Then `D_f = v_s·j12`, `D_s = v_s·(j22 − 1)`, `S = 2 − j11 + D_f/v_f`, and
//! `D = D_f·ê_f + D_s·ê_s` in the display frame (m/s, tip relative to sample).
//! `r0` is the lattice's *nominal* NN distance: it calibrates the corrected image.

use dhct_features::Feature;
use dhct_lattice::{
    Lattice, LocalDistortionMethod, direction_period, estimate_rotation, undirected_directions,
};
use dhct_scan::{ScanGeometry, ScanPass};
use nalgebra::{Matrix2, Vector2};
use serde::{Deserialize, Serialize};

use crate::model::scan_basis;
use crate::neighbours::SelectedFeature;

/// The local distortion measured at one feature.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LocalDistortion {
    /// Index of the feature in the input slice.
    pub index: usize,
    /// Its pass.
    pub pass: ScanPass,
    /// Controller position, pixels.
    pub x_px: f64,
    /// Controller position, pixels.
    pub y_px: f64,
    /// Acquisition time, seconds since frame start.
    pub time_s: f64,
    /// Seconds since its line start (its pass's direction).
    pub line_time_s: f64,
    /// Apparent fast-axis scale `S` (dimensionless).
    pub scale: f64,
    /// Drift + creep velocity `D` of the tip relative to the sample, m/s, display `[x, y]`.
    pub drift_m_per_s: [f64; 2],
    /// `D` in the pass's scan basis `[fast, slow]`, m/s.
    pub drift_fast_slow_m_per_s: [f64; 2],
    /// `J` (sample per controller displacement) in the scan basis, row-major.
    pub jacobian: [[f64; 2]; 2],
    /// Local rotation of the neighbours (affine method), radians; 0 for the ellipse.
    pub rotation_rad: f64,
    /// Acquisition-time offsets of the neighbours from this feature, seconds
    /// (`Δt = s/v_s + f/v_f`): the local measurement is a secant over these, which the
    /// model fit reproduces instead of assuming `D` constant across the neighbourhood.
    pub neighbour_dt_s: Vec<f64>,
    /// Line-time offsets of the neighbours, seconds (`Δτ = f/v_f`).
    pub neighbour_dtau_s: Vec<f64>,
}

/// Lattice orientation (radians, display frame, from +x towards +y) estimated from the NN
/// vectors of the selected features against the ideal NN directions of every motif site
/// (not necessarily equally spaced), modulo their symmetry period.
pub fn estimate_lattice_angle(
    points_m: &[[f64; 2]],
    selected: &[SelectedFeature],
    lattice: &dyn Lattice,
) -> f64 {
    let tolerance = 1e-6;
    let ideal = ideal_directions(lattice, 0.0);
    let directions = undirected_directions(ideal.iter().map(|u| [u.x, u.y]), tolerance);
    let period = direction_period(&directions, tolerance);
    let bonds = selected.iter().flat_map(|s| {
        let c = points_m[s.index];
        s.neighbours
            .iter()
            .map(move |&j| [points_m[j][0] - c[0], points_m[j][1] - c[1]])
    });
    estimate_rotation(bonds, &directions, period).unwrap_or(0.0)
}

/// The ideal NN vectors of every motif site and their negatives (deduplicated), rotated by
/// `angle`, metres, display frame.
fn ideal_directions(lattice: &dyn Lattice, angle: f64) -> Vec<Vector2<f64>> {
    let rotation = Matrix2::new(angle.cos(), -angle.sin(), angle.sin(), angle.cos());
    let mut out: Vec<Vector2<f64>> = Vec::new();
    for site in 0..lattice.motif().len() {
        for v in lattice.nearest_neighbours(site) {
            for w in [v, -v] {
                let w = rotation * w;
                if !out.iter().any(|u| (u - w).norm() < 1e-6 * w.norm()) {
                    out.push(w);
                }
            }
        }
    }
    out.sort_by(|a, b| a.y.atan2(a.x).total_cmp(&b.y.atan2(b.x)));
    out
}

/// Everything [`local_distortions`] needs besides the features.
#[derive(Debug, Clone, Copy)]
pub struct LocalSettings<'a> {
    /// The scan.
    pub geometry: &'a ScanGeometry,
    /// The lattice.
    pub lattice: &'a dyn Lattice,
    /// Ellipse or affine.
    pub method: LocalDistortionMethod,
    /// Lattice angle in the image (radians), for matching neighbours (affine).
    pub lattice_angle_rad: f64,
}

/// Measures the local distortion of every selected feature of one pass. Features whose fit
/// is degenerate or whose distortion is implausible (`|j12|` or `|j22 − 1|` > 1, like the
/// Matlab's ratio test) are skipped.
pub fn local_distortions(
    features: &[Feature],
    selected: &[SelectedFeature],
    settings: &LocalSettings,
) -> Vec<LocalDistortion> {
    let geometry = settings.geometry;
    let (px, py) = (geometry.pitch_x(), geometry.pitch_y());
    let r0 = settings.lattice.nearest_neighbour_distance();
    let ideal = ideal_directions(settings.lattice, settings.lattice_angle_rad);
    let (vf, vs) = (geometry.fast_speed(), geometry.slow_speed());
    selected
        .iter()
        .filter_map(|s| {
            let f = features.get(s.index)?;
            let (ef, es) = scan_basis(geometry, f.pass);
            let (ef, es) = (Vector2::new(ef[0], ef[1]), Vector2::new(es[0], es[1]));
            let to_basis = |v: Vector2<f64>| Vector2::new(v.dot(&ef), v.dot(&es));
            let observed: Vec<Vector2<f64>> = s
                .neighbours
                .iter()
                .filter_map(|&j| features.get(j))
                .map(|g| Vector2::new((g.x_px - f.x_px) * px, (g.y_px - f.y_px) * py))
                .collect();
            let (jac, rotation) = match settings.method {
                LocalDistortionMethod::Ellipse => {
                    let obs: Vec<Vector2<f64>> = observed.iter().map(|v| to_basis(*v)).collect();
                    (ellipse_jacobian(&obs, r0)?, 0.0)
                }
                LocalDistortionMethod::Affine => {
                    let pairs = match_neighbours(&observed, &ideal)?;
                    let pairs: Vec<(Vector2<f64>, Vector2<f64>)> = pairs
                        .into_iter()
                        .map(|(c, u)| (to_basis(c), to_basis(u)))
                        .collect();
                    affine_jacobian(&pairs)?
                }
            };
            let (j11, j12, j22) = (jac[(0, 0)], jac[(0, 1)], jac[(1, 1)]);
            if !(j11.is_finite() && j12.abs() < 1.0 && (j22 - 1.0).abs() < 1.0) {
                return None;
            }
            let d_f = vs * j12;
            let d_s = vs * (j22 - 1.0);
            let scale = 2.0 - j11 + d_f / vf;
            let d = ef * d_f + es * d_s;
            let (dt, dtau): (Vec<f64>, Vec<f64>) = observed
                .iter()
                .map(|c| {
                    let (f, s) = (c.dot(&ef), c.dot(&es));
                    (s / vs + f / vf, f / vf)
                })
                .unzip();
            Some(LocalDistortion {
                index: s.index,
                pass: f.pass,
                x_px: f.x_px,
                y_px: f.y_px,
                time_s: f.time_s,
                line_time_s: f.line_time_s,
                scale,
                drift_m_per_s: [d.x, d.y],
                drift_fast_slow_m_per_s: [d_f, d_s],
                jacobian: [[j11, j12], [jac[(1, 0)], j22]],
                rotation_rad: rotation,
                neighbour_dt_s: dt,
                neighbour_dtau_s: dtau,
            })
        })
        .collect()
}

/// `J` (upper triangular) from the NN positions relative to the centre feature, in the
/// scan basis (metres), by the conic fit and a Cholesky factorisation.
fn ellipse_jacobian(points: &[Vector2<f64>], r0: f64) -> Option<Matrix2<f64>> {
    if points.len() < 5 {
        return None;
    }
    // Scale to ~1 for conditioning.
    let q = 1.0 / r0;
    let mut ata = nalgebra::SMatrix::<f64, 5, 5>::zeros();
    let mut atb = nalgebra::SVector::<f64, 5>::zeros();
    for p in points {
        let (x, y) = (p.x * q, p.y * q);
        let row = nalgebra::SVector::<f64, 5>::new(x * x, x * y, y * y, x, y);
        ata += row * row.transpose();
        atb += row;
    }
    let c = ata.lu().solve(&atb)?;
    let mq = Matrix2::new(c[0], 0.5 * c[1], 0.5 * c[1], c[2]);
    let g = Vector2::new(c[3], c[4]);
    let centre = -0.5 * mq.try_inverse()? * g;
    let kappa = 1.0 + centre.dot(&(mq * centre));
    if kappa.is_nan() || kappa <= 0.0 {
        return None;
    }
    // In units of r0: E' = mq/kappa and J^T J = E' (r0 = 1 in these units).
    let e = mq / kappa;
    let chol = e.cholesky()?;
    Some(chol.l().transpose())
}

/// Assigns each observed NN vector to the nearest ideal direction; each ideal vector at
/// most once.
fn match_neighbours(
    observed: &[Vector2<f64>],
    ideal: &[Vector2<f64>],
) -> Option<Vec<(Vector2<f64>, Vector2<f64>)>> {
    let mut used = vec![false; ideal.len()];
    let mut pairs = Vec::with_capacity(observed.len());
    for c in observed {
        let (k, _) = ideal
            .iter()
            .enumerate()
            .map(|(k, u)| (k, c.dot(u) / (c.norm() * u.norm())))
            .max_by(|a, b| a.1.total_cmp(&b.1))?;
        if used[k] {
            return None;
        }
        used[k] = true;
        pairs.push((*c, ideal[k]));
    }
    Some(pairs)
}

/// `J` and the local rotation from matched `(observed, ideal)` pairs in the scan basis.
fn affine_jacobian(pairs: &[(Vector2<f64>, Vector2<f64>)]) -> Option<(Matrix2<f64>, f64)> {
    let mut cu = Matrix2::zeros();
    let mut uu = Matrix2::zeros();
    for (c, u) in pairs {
        cu += c * u.transpose();
        uu += u * u.transpose();
    }
    let m = cu * uu.try_inverse()?;
    // RQ: M = K R(ψ), R(ψ) = [[cos, −sin], [sin, cos]], K upper triangular.
    let k22 = m[(1, 0)].hypot(m[(1, 1)]);
    if k22.is_nan() || k22 <= 0.0 {
        return None;
    }
    let (s, c) = (m[(1, 0)] / k22, m[(1, 1)] / k22);
    let k11 = m[(0, 0)] * c - m[(0, 1)] * s;
    let k12 = m[(0, 0)] * s + m[(0, 1)] * c;
    let k = Matrix2::new(k11, k12, 0.0, k22);
    Some((k.try_inverse()?, s.atan2(c)))
}
