//! The sample model: lattice features as 2-D Gaussians, defects, domains, steps and strain,
//! evaluated fast at any sample-frame point.
//!
//! Evaluation never loops over all features: a point's fractional lattice coordinates give
//! the few cells whose features can lie within the cutoff (4σ of the widest Gaussian plus
//! lobe offsets and strain), and each cell's state (present or not, strained position,
//! height) is a lookup in a dense table over the scanned area. Adatoms sit in a bin grid.

use std::f64::consts::SQRT_2;

use dhct_lattice::Lattice;
use nalgebra::{Matrix2, Vector2};
use rand::RngExt;
use serde::{Deserialize, Serialize};

use crate::SimulationError;
use crate::config::{FeatureShape, SurfaceConfig};
use crate::error::invalid;
use crate::noise::{Stream, stream_rng};
use crate::region::Region;

/// Gaussians are summed out to this many standard deviations.
pub const CUTOFF_SIGMAS: f64 = 4.0;

/// Largest number of lattice sites the dense site table may hold.
const MAX_TABLE_SITES: usize = 1 << 28;

/// An axis-aligned area of the sample frame, metres.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SampleArea {
    /// Lower corner `[x, y]`, metres.
    pub min_m: [f64; 2],
    /// Upper corner `[x, y]`, metres.
    pub max_m: [f64; 2],
}

impl SampleArea {
    fn min(&self) -> Vector2<f64> {
        Vector2::new(self.min_m[0], self.min_m[1])
    }
    fn max(&self) -> Vector2<f64> {
        Vector2::new(self.max_m[0], self.max_m[1])
    }
    /// True if `p` lies inside (boundary included).
    pub fn contains(&self, p: Vector2<f64>) -> bool {
        (self.min_m[0]..=self.max_m[0]).contains(&p.x)
            && (self.min_m[1]..=self.max_m[1]).contains(&p.y)
    }
    fn grown(&self, margin: f64) -> SampleArea {
        SampleArea {
            min_m: [self.min_m[0] - margin, self.min_m[1] - margin],
            max_m: [self.max_m[0] + margin, self.max_m[1] + margin],
        }
    }
    fn corners(&self) -> [Vector2<f64>; 4] {
        let (lo, hi) = (self.min(), self.max());
        [lo, Vector2::new(hi.x, lo.y), Vector2::new(lo.x, hi.y), hi]
    }
}

/// What a feature of the ground truth is.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case")]
pub enum FeatureKind {
    /// Motif site `site` of cell `(n, m)` of domain `domain` (0 = main, 1 = second domain).
    LatticeSite {
        /// The domain: 0 = main, 1 = second domain.
        domain: usize,
        /// Cell index along a1.
        n: i64,
        /// Cell index along a2.
        m: i64,
        /// Index of the motif site within the cell.
        site: usize,
    },
    /// Adatom number `index` (listed positions first, then random ones).
    Adatom {
        /// The adatom's number.
        index: usize,
    },
}

/// One imaged feature of the sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurfaceFeature {
    /// What it is.
    pub kind: FeatureKind,
    /// True position, metres, sample frame (the lattice site incl. strain; a molecule's
    /// lobes are placed relative to it).
    pub position: Vector2<f64>,
    /// Peak height before tip broadening, metres (feature height × motif relative height).
    pub amplitude: f64,
}

/// The terrace height of the sample without atomic corrugation: its steps on its tilted
/// plane.
#[derive(Debug, Clone)]
pub struct Terrace {
    steps: Vec<(Region, f64)>,
    plane_slope: Vector2<f64>,
    tip_sigma: f64,
}

impl Terrace {
    /// The steps of `surface`, broadened by a Gaussian tip of width `tip_sigma` (metres).
    pub fn new(surface: &SurfaceConfig, tip_sigma: f64) -> Terrace {
        Terrace {
            steps: surface
                .steps
                .iter()
                .map(|s| (s.region.clone(), s.height_m))
                .collect(),
            plane_slope: Vector2::from(surface.plane_slope),
            tip_sigma,
        }
    }

    /// Terrace height at sample point `p` (metres): the plane's height there (0 at the
    /// sample origin) plus the heights of the steps whose upper terrace contains `p`, with
    /// an erf edge profile of width σ_tip.
    pub fn height(&self, p: Vector2<f64>) -> f64 {
        let steps: f64 = self
            .steps
            .iter()
            .map(|(region, height)| {
                height * edge_profile(region.signed_distance(p), self.tip_sigma)
            })
            .sum();
        self.plane_slope.dot(&p) + steps
    }

    /// True if there are no steps and no tilt.
    pub fn is_flat(&self) -> bool {
        self.steps.is_empty() && self.plane_slope == Vector2::zeros()
    }
}

/// 0 outside, 1 inside, an erf ramp of width `sigma` across the boundary.
fn edge_profile(signed_distance: f64, sigma: f64) -> f64 {
    if sigma > 0.0 {
        0.5 * (1.0 + dhct_numerics::special::erf(signed_distance / (SQRT_2 * sigma)))
    } else if signed_distance >= 0.0 {
        1.0
    } else {
        0.0
    }
}

/// One Gaussian, ready to evaluate: `factor · exp(−½ (d−o)ᵀ Q (d−o))`.
#[derive(Debug, Clone, Copy)]
struct CompiledLobe {
    offset: Vector2<f64>,
    /// Inverse covariance `[[qxx, qxy], [qxy, qyy]]`.
    qxx: f64,
    qxy: f64,
    qyy: f64,
    /// Relative height × volume-preserving tip-broadening factor.
    factor: f64,
}

impl CompiledLobe {
    /// A lobe with widths `sigma` along axes rotated by `angle`, offset `offset`, all in the
    /// sample frame, broadened by an isotropic Gaussian tip.
    fn new(
        offset: Vector2<f64>,
        sigma: [f64; 2],
        angle: f64,
        relative_height: f64,
        tip_sigma: f64,
    ) -> CompiledLobe {
        let (sin, cos) = angle.sin_cos();
        let rotation = Matrix2::new(cos, -sin, sin, cos);
        let variances = Matrix2::new(sigma[0] * sigma[0], 0.0, 0.0, sigma[1] * sigma[1]);
        let covariance = rotation * variances * rotation.transpose();
        let tip = tip_sigma * tip_sigma;
        let broadened = covariance + Matrix2::new(tip, 0.0, 0.0, tip);
        let det = broadened.determinant();
        let det0 = covariance.determinant();
        CompiledLobe {
            offset,
            qxx: broadened[(1, 1)] / det,
            qxy: -broadened[(0, 1)] / det,
            qyy: broadened[(0, 0)] / det,
            factor: relative_height * (det0 / det).sqrt(),
        }
    }

    /// Reach of the lobe from its site: 4σ of the broadened major axis plus the offset.
    fn reach(sigma: [f64; 2], tip_sigma: f64, offset: Vector2<f64>) -> f64 {
        let major = sigma[0].max(sigma[1]);
        CUTOFF_SIGMAS * (major * major + tip_sigma * tip_sigma).sqrt() + offset.norm()
    }

    #[inline]
    fn value(&self, d: Vector2<f64>) -> f64 {
        let (x, y) = (d.x - self.offset.x, d.y - self.offset.y);
        let q = self.qxx * x * x + 2.0 * self.qxy * x * y + self.qyy * y * y;
        self.factor * (-0.5 * q).exp()
    }
}

/// The shape of one feature in the sample frame (lobes rotated by the domain's angle).
#[derive(Debug, Clone)]
struct CompiledShape {
    lobes: Vec<CompiledLobe>,
    reach: f64,
}

impl CompiledShape {
    fn feature(shape: &FeatureShape, rotation_angle: f64, tip_sigma: f64) -> CompiledShape {
        let (sin, cos) = rotation_angle.sin_cos();
        let rotation = Matrix2::new(cos, -sin, sin, cos);
        let mut lobes = Vec::new();
        let mut reach: f64 = 0.0;
        if shape.lobes.is_empty() {
            lobes.push(CompiledLobe::new(
                Vector2::zeros(),
                shape.sigma_m,
                shape.angle_rad + rotation_angle,
                1.0,
                tip_sigma,
            ));
            reach = CompiledLobe::reach(shape.sigma_m, tip_sigma, Vector2::zeros());
        }
        for lobe in &shape.lobes {
            let offset = rotation * Vector2::new(lobe.offset_m[0], lobe.offset_m[1]);
            let sigma = lobe.sigma_m.unwrap_or(shape.sigma_m);
            let angle = lobe.angle_rad.unwrap_or(shape.angle_rad) + rotation_angle;
            lobes.push(CompiledLobe::new(
                offset,
                sigma,
                angle,
                lobe.relative_height,
                tip_sigma,
            ));
            reach = reach.max(CompiledLobe::reach(sigma, tip_sigma, offset));
        }
        CompiledShape { lobes, reach }
    }

    fn single(shape: &FeatureShape, rotation_angle: f64, tip_sigma: f64) -> CompiledShape {
        CompiledShape {
            lobes: vec![CompiledLobe::new(
                Vector2::zeros(),
                shape.sigma_m,
                shape.angle_rad + rotation_angle,
                1.0,
                tip_sigma,
            )],
            reach: CompiledLobe::reach(shape.sigma_m, tip_sigma, Vector2::zeros()),
        }
    }

    #[inline]
    fn value(&self, d: Vector2<f64>) -> f64 {
        self.lobes.iter().map(|lobe| lobe.value(d)).sum()
    }
}

/// The state of one lattice site: its peak height (0 = absent) and position.
#[derive(Debug, Clone, Copy)]
struct SiteEntry {
    amplitude: f64,
    position: Vector2<f64>,
}

/// One domain's sites over the scanned area, indexed by cell and motif site.
#[derive(Debug, Clone)]
struct DomainTable {
    inverse: Matrix2<f64>,
    origin: Vector2<f64>,
    motif_fractional: Vec<[f64; 2]>,
    n0: i64,
    m0: i64,
    n_count: i64,
    m_count: i64,
    entries: Vec<SiteEntry>,
    /// Half-widths of the candidate windows in fractional coordinates.
    reach_n: f64,
    reach_m: f64,
    shape: CompiledShape,
    cutoff_squared: f64,
}

impl DomainTable {
    fn index(&self, n: i64, m: i64, site: usize) -> usize {
        (((n - self.n0) * self.m_count + (m - self.m0)) as usize) * self.motif_fractional.len()
            + site
    }

    /// Fractional coordinate windows of candidate cells near `p` for motif site `site`,
    /// grown by `reach_scale` × the cutoff window.
    fn window(&self, f: Vector2<f64>, site: usize, extra: f64) -> (i64, i64, i64, i64) {
        let [s1, s2] = self.motif_fractional[site];
        let n_lo = ((f.x - s1 - self.reach_n - extra).ceil() as i64).max(self.n0);
        let n_hi =
            ((f.x - s1 + self.reach_n + extra).floor() as i64).min(self.n0 + self.n_count - 1);
        let m_lo = ((f.y - s2 - self.reach_m - extra).ceil() as i64).max(self.m0);
        let m_hi =
            ((f.y - s2 + self.reach_m + extra).floor() as i64).min(self.m0 + self.m_count - 1);
        (n_lo, n_hi, m_lo, m_hi)
    }

    #[inline]
    fn height(&self, p: Vector2<f64>) -> f64 {
        let f = self.inverse * (p - self.origin);
        let mut z = 0.0;
        for site in 0..self.motif_fractional.len() {
            let (n_lo, n_hi, m_lo, m_hi) = self.window(f, site, 0.0);
            for n in n_lo..=n_hi {
                for m in m_lo..=m_hi {
                    let entry = self.entries[self.index(n, m, site)];
                    if entry.amplitude == 0.0 {
                        continue;
                    }
                    let d = p - entry.position;
                    if d.norm_squared() > self.cutoff_squared {
                        continue;
                    }
                    z += entry.amplitude * self.shape.value(d);
                }
            }
        }
        z
    }

    /// The present site nearest `p` within `radius`, as (index, distance).
    fn nearest(&self, p: Vector2<f64>, radius: f64) -> Option<(usize, f64)> {
        let f = self.inverse * (p - self.origin);
        let extra = radius * self.inverse.row(0).norm().max(self.inverse.row(1).norm());
        let mut best: Option<(usize, f64)> = None;
        for site in 0..self.motif_fractional.len() {
            let (n_lo, n_hi, m_lo, m_hi) = self.window(f, site, extra);
            for n in n_lo..=n_hi {
                for m in m_lo..=m_hi {
                    let index = self.index(n, m, site);
                    let entry = self.entries[index];
                    let distance = (p - entry.position).norm();
                    if entry.amplitude != 0.0
                        && distance <= radius
                        && best.is_none_or(|(_, d)| distance < d)
                    {
                        best = Some((index, distance));
                    }
                }
            }
        }
        best
    }
}

/// Adatoms binned on a square grid for evaluation.
#[derive(Debug, Clone)]
struct AdatomGrid {
    positions: Vec<Vector2<f64>>,
    amplitude: f64,
    shape: CompiledShape,
    origin: Vector2<f64>,
    bin: f64,
    bins_x: usize,
    bins_y: usize,
    /// CSR: adatoms of bin `b` are `members[starts[b]..starts[b + 1]]`.
    starts: Vec<usize>,
    members: Vec<usize>,
}

impl AdatomGrid {
    fn new(
        positions: Vec<Vector2<f64>>,
        amplitude: f64,
        shape: CompiledShape,
        area: SampleArea,
    ) -> AdatomGrid {
        let bin = shape.reach.max(1e-12);
        let origin = area.min() - Vector2::repeat(bin);
        let span = area.max() - origin + Vector2::repeat(bin);
        let bins_x = ((span.x / bin).ceil() as usize).clamp(1, 4096);
        let bins_y = ((span.y / bin).ceil() as usize).clamp(1, 4096);
        let bin_x = span.x / bins_x as f64;
        let bin_y = span.y / bins_y as f64;
        let bin = bin_x.max(bin_y).max(bin);
        let mut counts = vec![0usize; bins_x * bins_y + 1];
        let bin_of = |p: &Vector2<f64>| -> Option<usize> {
            let bx = ((p.x - origin.x) / bin).floor();
            let by = ((p.y - origin.y) / bin).floor();
            (bx >= 0.0 && by >= 0.0 && (bx as usize) < bins_x && (by as usize) < bins_y)
                .then(|| by as usize * bins_x + bx as usize)
        };
        for p in &positions {
            if let Some(b) = bin_of(p) {
                counts[b + 1] += 1;
            }
        }
        for b in 1..counts.len() {
            counts[b] += counts[b - 1];
        }
        let starts = counts.clone();
        let mut fill = counts;
        let mut members = vec![0; starts[bins_x * bins_y]];
        for (index, p) in positions.iter().enumerate() {
            if let Some(b) = bin_of(p) {
                members[fill[b]] = index;
                fill[b] += 1;
            }
        }
        AdatomGrid {
            positions,
            amplitude,
            shape,
            origin,
            bin,
            bins_x,
            bins_y,
            starts,
            members,
        }
    }

    #[inline]
    fn height(&self, p: Vector2<f64>) -> f64 {
        if self.members.is_empty() {
            return 0.0;
        }
        let bx = ((p.x - self.origin.x) / self.bin).floor() as i64;
        let by = ((p.y - self.origin.y) / self.bin).floor() as i64;
        let reach_squared = self.shape.reach * self.shape.reach;
        let mut z = 0.0;
        for y in (by - 1).max(0)..=(by + 1).min(self.bins_y as i64 - 1) {
            for x in (bx - 1).max(0)..=(bx + 1).min(self.bins_x as i64 - 1) {
                let b = y as usize * self.bins_x + x as usize;
                for &index in &self.members[self.starts[b]..self.starts[b + 1]] {
                    let d = p - self.positions[index];
                    if d.norm_squared() <= reach_squared {
                        z += self.amplitude * self.shape.value(d);
                    }
                }
            }
        }
        z
    }
}

/// The sample over a scanned area: `height(p)` = terrace + features + adatoms.
#[derive(Debug, Clone)]
pub struct Surface {
    terrace: Terrace,
    domains: Vec<DomainTable>,
    adatoms: AdatomGrid,
    features: Vec<SurfaceFeature>,
    modulations: Vec<CompiledModulation>,
}

/// A [`crate::config::Modulation`] in the sample frame.
#[derive(Debug, Clone, Copy)]
struct CompiledModulation {
    /// `2π·G`, radians per metre.
    wave: Vector2<f64>,
    /// The lattice origin, metres.
    origin: Vector2<f64>,
    /// Amplitude, metres.
    amplitude: f64,
}

impl CompiledModulation {
    /// The modulations of `surface`: each index turned into a frequency by the lattice's
    /// reciprocal basis, rotated with the surface.
    fn all(surface: &SurfaceConfig, lattice: &dyn Lattice) -> Vec<CompiledModulation> {
        let [a1, a2] = lattice.translation_cell();
        let Some(inverse) = Matrix2::from_columns(&[a1, a2]).try_inverse() else {
            return Vec::new();
        };
        let reciprocal = inverse.transpose();
        let (s, c) = surface.angle_rad.sin_cos();
        let rotation = Matrix2::new(c, -s, s, c);
        surface
            .modulations
            .iter()
            .map(|m| CompiledModulation {
                wave: rotation
                    * reciprocal
                    * Vector2::new(m.index[0], m.index[1])
                    * (2.0 * std::f64::consts::PI),
                origin: Vector2::new(surface.origin_m[0], surface.origin_m[1]),
                amplitude: m.amplitude_m,
            })
            .collect()
    }

    fn height(&self, p: Vector2<f64>) -> f64 {
        self.amplitude * self.wave.dot(&(p - self.origin)).cos()
    }
}

/// splitmix64: a fast, well-mixed 64-bit hash step.
fn splitmix64(x: u64) -> u64 {
    let mut z = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A uniform number in [0, 1) fixed by the seed and a site's indices.
fn site_uniform(seed: u64, domain: usize, n: i64, m: i64, site: usize) -> f64 {
    let mut h = splitmix64(seed ^ 0x5641_4341_4E43_5921);
    for value in [domain as u64, n as u64, m as u64, site as u64] {
        h = splitmix64(h ^ value);
    }
    (h >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

impl Surface {
    /// Builds the sample covering `area` (the sample-frame bounding box of every point the
    /// tip visits), from the surface config, tip width and seed.
    pub fn build(
        surface: &SurfaceConfig,
        lattice: &dyn Lattice,
        tip_sigma: f64,
        seed: u64,
        area: SampleArea,
        nominal: SampleArea,
    ) -> Result<Surface, SimulationError> {
        let terrace = Terrace::new(surface, tip_sigma);
        let mut orientations = vec![(surface.angle_rad, surface.origin_m)];
        if let Some(domain) = &surface.second_domain {
            orientations.push((domain.angle_rad, domain.origin_m));
        }
        let strain_margin = strain_margin(surface, &area);
        let mut domains = Vec::with_capacity(orientations.len());
        for (domain, (angle, origin)) in orientations.into_iter().enumerate() {
            domains.push(build_domain(
                surface,
                lattice,
                tip_sigma,
                seed,
                domain,
                angle,
                Vector2::new(origin[0], origin[1]),
                area,
                strain_margin,
            )?);
        }
        // Listed vacancies: the nearest present site within half the NN distance.
        let radius = 0.5 * lattice.nearest_neighbour_distance();
        for p in &surface.defects.vacancy_positions_m {
            let p = Vector2::new(p[0], p[1]);
            let nearest = domains
                .iter()
                .enumerate()
                .filter_map(|(d, table)| table.nearest(p, radius).map(|(i, dist)| (d, i, dist)))
                .min_by(|a, b| a.2.total_cmp(&b.2));
            if let Some((d, index, _)) = nearest {
                domains[d].entries[index].amplitude = 0.0;
            }
        }
        let adatom_positions = adatom_positions(surface, seed, nominal);
        let adatom_shape = CompiledShape::single(&surface.feature, surface.angle_rad, tip_sigma);
        let adatom_amplitude = surface.feature.height_m * surface.defects.adatom_relative_height;
        let mut features = Vec::new();
        for (d, table) in domains.iter().enumerate() {
            for n in table.n0..table.n0 + table.n_count {
                for m in table.m0..table.m0 + table.m_count {
                    for site in 0..table.motif_fractional.len() {
                        let entry = table.entries[table.index(n, m, site)];
                        if entry.amplitude != 0.0 && area.contains(entry.position) {
                            features.push(SurfaceFeature {
                                kind: FeatureKind::LatticeSite {
                                    domain: d,
                                    n,
                                    m,
                                    site,
                                },
                                position: entry.position,
                                amplitude: entry.amplitude,
                            });
                        }
                    }
                }
            }
        }
        for (index, p) in adatom_positions.iter().enumerate() {
            if area.contains(*p) {
                features.push(SurfaceFeature {
                    kind: FeatureKind::Adatom { index },
                    position: *p,
                    amplitude: adatom_amplitude,
                });
            }
        }
        let grid_area = area.grown(adatom_shape.reach);
        Ok(Surface {
            terrace,
            domains,
            adatoms: AdatomGrid::new(adatom_positions, adatom_amplitude, adatom_shape, grid_area),
            features,
            modulations: CompiledModulation::all(surface, lattice),
        })
    }

    /// Measured height (metres) with the tip at sample point `p` (metres).
    #[inline]
    pub fn height(&self, p: Vector2<f64>) -> f64 {
        let mut z = if self.terrace.is_flat() {
            0.0
        } else {
            self.terrace.height(p)
        };
        for domain in &self.domains {
            z += domain.height(p);
        }
        for modulation in &self.modulations {
            z += modulation.height(p);
        }
        z + self.adatoms.height(p)
    }

    /// The terrace height at `p` (steps only).
    pub fn terrace(&self) -> &Terrace {
        &self.terrace
    }

    /// Every feature whose true position lies in the scanned area: present lattice sites
    /// (domain order, then cell order) followed by adatoms.
    pub fn features(&self) -> &[SurfaceFeature] {
        &self.features
    }
}

/// An upper bound of how far strain moves a site inside `area`.
fn strain_margin(surface: &SurfaceConfig, area: &SampleArea) -> f64 {
    surface
        .strain
        .iter()
        .map(|s| {
            let gradient = Matrix2::new(
                s.strain[0][0],
                s.strain[0][1],
                s.strain[1][0],
                s.strain[1][1],
            );
            let anchor = Vector2::new(s.anchor_m[0], s.anchor_m[1]);
            area.corners()
                .iter()
                .map(|c| (gradient * (c - anchor)).norm())
                .fold(0.0, f64::max)
                * 1.5
        })
        .fold(0.0, f64::max)
}

/// The strain displacement of a site at unstrained position `p`.
fn strain_displacement(surface: &SurfaceConfig, p: Vector2<f64>) -> Vector2<f64> {
    let mut u = Vector2::zeros();
    for s in &surface.strain {
        if s.region.contains(p) {
            let gradient = Matrix2::new(
                s.strain[0][0],
                s.strain[0][1],
                s.strain[1][0],
                s.strain[1][1],
            );
            u += gradient * (p - Vector2::new(s.anchor_m[0], s.anchor_m[1]));
        }
    }
    u
}

#[allow(clippy::too_many_arguments)]
fn build_domain(
    surface: &SurfaceConfig,
    lattice: &dyn Lattice,
    tip_sigma: f64,
    seed: u64,
    domain: usize,
    angle: f64,
    origin: Vector2<f64>,
    area: SampleArea,
    strain_margin: f64,
) -> Result<DomainTable, SimulationError> {
    let [a1, a2] = lattice.primitive_vectors();
    let (sin, cos) = angle.sin_cos();
    let rotation = Matrix2::new(cos, -sin, sin, cos);
    let basis = rotation * Matrix2::from_columns(&[a1, a2]);
    let inverse = basis
        .try_inverse()
        .ok_or_else(|| invalid("surface.lattice", "primitive vectors are parallel"))?;
    let shape = CompiledShape::feature(&surface.feature, angle, tip_sigma);
    let motif_fractional: Vec<[f64; 2]> = lattice.motif().iter().map(|s| s.fractional).collect();
    let relative: Vec<f64> = lattice.motif().iter().map(|s| s.relative_height).collect();

    // Cells whose sites can lie within reach of the area (after strain).
    let table_area = area.grown(shape.reach + strain_margin);
    let (mut lo, mut hi) = (
        Vector2::repeat(f64::INFINITY),
        Vector2::repeat(f64::NEG_INFINITY),
    );
    for corner in table_area.corners() {
        let f = inverse * (corner - origin);
        lo = lo.inf(&f);
        hi = hi.sup(&f);
    }
    let (s_lo, s_hi) = motif_fractional.iter().fold(
        (Vector2::repeat(0.0f64), Vector2::repeat(0.0f64)),
        |(l, h), s| {
            (
                l.inf(&Vector2::new(s[0], s[1])),
                h.sup(&Vector2::new(s[0], s[1])),
            )
        },
    );
    let n0 = (lo.x - s_hi.x).floor() as i64 - 1;
    let m0 = (lo.y - s_hi.y).floor() as i64 - 1;
    let n_count = (hi.x - s_lo.x).ceil() as i64 + 1 - n0 + 1;
    let m_count = (hi.y - s_lo.y).ceil() as i64 + 1 - m0 + 1;
    let sites =
        (n_count.max(0) as u128) * (m_count.max(0) as u128) * motif_fractional.len() as u128;
    if sites > MAX_TABLE_SITES as u128 {
        return Err(invalid(
            "surface",
            format!(
                "the scanned sample area ({:.3e} x {:.3e} m after displacements) holds {sites} \
                 lattice sites, more than the limit of {MAX_TABLE_SITES}; \
                 check the lattice constant and the effect amplitudes",
                area.max_m[0] - area.min_m[0],
                area.max_m[1] - area.min_m[1],
            ),
        ));
    }

    let second_region = surface.second_domain.as_ref().map(|d| &d.region);
    let vacancy_fraction = surface.defects.vacancy_fraction;
    let vacancy_seed = surface.defects.vacancy_seed.unwrap_or(seed);
    let mut entries = Vec::with_capacity(sites as usize);
    let mut max_strain: f64 = 0.0;
    for n in n0..n0 + n_count {
        for m in m0..m0 + m_count {
            for (site, s) in motif_fractional.iter().enumerate() {
                let ideal = origin + basis * Vector2::new(n as f64 + s[0], m as f64 + s[1]);
                let in_second = second_region.is_some_and(|r| r.contains(ideal));
                let present = match domain {
                    0 => !in_second,
                    _ => in_second,
                } && (vacancy_fraction == 0.0
                    || site_uniform(vacancy_seed, domain, n, m, site) >= vacancy_fraction);
                let u = strain_displacement(surface, ideal);
                max_strain = max_strain.max(u.norm());
                entries.push(SiteEntry {
                    amplitude: if present {
                        surface.feature.height_m * relative[site]
                    } else {
                        0.0
                    },
                    position: ideal + u,
                });
            }
        }
    }
    // Candidate windows: cutoff plus the largest strain displacement, in fractional units.
    let search = shape.reach + max_strain;
    Ok(DomainTable {
        inverse,
        origin,
        motif_fractional,
        n0,
        m0,
        n_count,
        m_count,
        entries,
        reach_n: search * inverse.row(0).norm(),
        reach_m: search * inverse.row(1).norm(),
        cutoff_squared: shape.reach * shape.reach,
        shape,
    })
}

/// Listed adatoms, then `adatom_count` uniformly random ones over the nominal image area.
fn adatom_positions(surface: &SurfaceConfig, seed: u64, nominal: SampleArea) -> Vec<Vector2<f64>> {
    let mut positions: Vec<Vector2<f64>> = surface
        .defects
        .adatom_positions_m
        .iter()
        .map(|p| Vector2::new(p[0], p[1]))
        .collect();
    let mut rng = stream_rng(seed, Stream::Surface, 0, 0);
    for _ in 0..surface.defects.adatom_count {
        let x = nominal.min_m[0] + (nominal.max_m[0] - nominal.min_m[0]) * rng.random::<f64>();
        let y = nominal.min_m[1] + (nominal.max_m[1] - nominal.min_m[1]) * rng.random::<f64>();
        positions.push(Vector2::new(x, y));
    }
    positions
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tip_broadening_keeps_the_volume() {
        let sharp = CompiledLobe::new(Vector2::zeros(), [1.0, 2.0], 0.3, 1.0, 0.0);
        let blunt = CompiledLobe::new(Vector2::zeros(), [1.0, 2.0], 0.3, 1.0, 1.5);
        let volume = |lobe: &CompiledLobe| {
            let h = 0.05;
            let mut sum = 0.0;
            for i in -400..=400 {
                for j in -400..=400 {
                    sum += lobe.value(Vector2::new(i as f64 * h, j as f64 * h));
                }
            }
            sum * h * h
        };
        let (a, b) = (volume(&sharp), volume(&blunt));
        assert!((a - b).abs() < 1e-6 * a, "{a} vs {b}");
        assert!((a - std::f64::consts::TAU * 2.0).abs() < 1e-6 * a);
    }
}
