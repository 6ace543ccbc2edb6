//! What the lattice fit finds ([`LatticeFit`]: origin, rotation, scales, every point
//! indexed) and the geometry both its stages share: the map `D·R(θ)`, a site's lattice-frame
//! position, the site nearest to a point.

use nalgebra::{Matrix2, Vector2};
use serde::{Deserialize, Serialize};

use crate::Lattice;

/// Gauss–Newton iterations of the final fit.
pub const MAX_GAUSS_NEWTON_ITERATIONS: usize = 20;

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
pub(crate) type SiteIndex = (i64, i64, usize);

/// A position (metres) with its site.
pub(crate) type IndexedPosition = (Vector2<f64>, SiteIndex);

/// The map `D·R(θ)` of scales `scale` and rotation `angle`.
pub(crate) fn transform(angle: f64, scale: [f64; 2]) -> Matrix2<f64> {
    let (sin, cos) = angle.sin_cos();
    Matrix2::new(
        scale[0] * cos,
        -scale[0] * sin,
        scale[1] * sin,
        scale[1] * cos,
    )
}

/// The lattice-frame position (metres) of site `site` in cell `(n, m)`.
pub(crate) fn lattice_vector(lattice: &dyn Lattice, n: i64, m: i64, site: usize) -> Vector2<f64> {
    let [a1, a2] = lattice.primitive_vectors();
    a1 * n as f64 + a2 * m as f64 + lattice.site_position(site)
}

/// The site nearest to `p` under the affine model `p ≈ o + B·v`: indices and squared error.
pub(crate) fn nearest_site(
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
