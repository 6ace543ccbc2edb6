//! The ground truth of a simulation: every feature's true sample position, where and when
//! each pass imaged it, the true displacement field on the pixel grid, and every effect's
//! parameters.
//!
//! A feature at sample position `p_s` is imaged where the tip was there: the controller
//! position `p_c` solving `p_c + d(t(p_c), pass) = p_s`. The acquisition time depends on
//! `p_c`, so this is solved per feature and pass by a damped Newton iteration (finite-
//! difference Jacobian) in pixel coordinates, to 1e-6 px.

use dhct_scan::{ImageChannel, ScanGeometry, ScanPass};
use nalgebra::{Matrix2, Vector2};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::config::SimulationConfig;
use crate::effects::{Effect, EffectConfig};
use crate::raster::Displacer;
use crate::surface::{FeatureKind, SampleArea, SurfaceFeature};

/// Convergence tolerance of the controller-position solve, pixels.
pub const SOLVE_TOLERANCE_PX: f64 = 1e-6;

/// Maximum Newton iterations per feature and pass.
const MAX_ITERATIONS: usize = 100;

/// Everything known about one simulation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GroundTruth {
    /// `"dhct-simulate <version>"`.
    pub generator: String,
    /// The config that produced it.
    pub config: SimulationConfig,
    /// The scan geometry of both images.
    pub geometry: ScanGeometry,
    /// The sample-frame bounding box of every tip position (metres).
    pub visited_area: SampleArea,
    /// The effects with their parameter names and values (SI units).
    pub effects: Vec<EffectRecord>,
    /// Every feature whose true position lies in the visited area.
    pub features: Vec<FeatureTruth>,
    /// True displacement fields (trace, retrace), written as NPY files, not in JSON.
    #[serde(skip)]
    pub displacement: Vec<DisplacementField>,
}

/// One effect and its parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EffectRecord {
    /// The config kind.
    pub name: String,
    /// Parameter names (units in the names).
    pub parameter_names: Vec<String>,
    /// Parameter values, same order.
    pub parameters: Vec<f64>,
    /// The full config entry.
    pub config: EffectConfig,
}

impl EffectRecord {
    /// Describes `effect`.
    pub fn of(effect: &dyn Effect) -> EffectRecord {
        EffectRecord {
            name: effect.name().to_string(),
            parameter_names: effect
                .parameter_names()
                .into_iter()
                .map(String::from)
                .collect(),
            parameters: effect.parameters(),
            config: effect.config(),
        }
    }
}

/// The true tip displacement `d = p_sample − p_ctrl` of one pass on the pixel grid.
#[derive(Debug, Clone, PartialEq)]
pub struct DisplacementField {
    /// Trace or retrace.
    pub pass: ScanPass,
    /// x component, metres, `(rows, columns)`.
    pub dx: ImageChannel,
    /// y component, metres, `(rows, columns)`.
    pub dy: ImageChannel,
}

/// One feature of the ground truth.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FeatureTruth {
    /// Index in [`GroundTruth::features`].
    pub index: usize,
    /// Lattice site (domain, cell, motif site) or adatom.
    pub kind: FeatureKind,
    /// True position, metres, sample frame.
    pub sample_position_m: [f64; 2],
    /// Peak height before tip broadening, metres.
    pub amplitude_m: f64,
    /// Where and when the trace imaged it.
    pub trace: FeatureAcquisition,
    /// Where and when the retrace imaged it.
    pub retrace: FeatureAcquisition,
}

/// Where and when one pass imaged a feature.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FeatureAcquisition {
    /// Controller position, pixels `[x = column, y = row]` (sub-pixel).
    pub controller_position_px: [f64; 2],
    /// Controller position, metres `[x, y]`.
    pub controller_position_m: [f64; 2],
    /// Seconds since frame start.
    pub time_since_frame_start_s: f64,
    /// Seconds since the start of its line (this pass's direction).
    pub time_since_line_start_s: f64,
    /// Tip displacement there, metres: `sample − controller`.
    pub displacement_m: [f64; 2],
    /// True if the controller position lies on the image (within half a pixel of the
    /// outer pixel centres).
    pub in_image: bool,
    /// True if the solve reached the tolerance (false e.g. at a tip jump, where a feature
    /// can be skipped or imaged twice).
    pub converged: bool,
    /// Remaining mismatch `|p_c + d − p_s|`, metres.
    pub residual_m: f64,
}

/// Solves where `pass` imaged sample point `target` (metres).
pub fn locate(displacer: &Displacer, pass: ScanPass, target: Vector2<f64>) -> FeatureAcquisition {
    let geometry = displacer.geometry();
    let (pitch_x, pitch_y) = (geometry.pitch_x(), geometry.pitch_y());
    let residual = |u: Vector2<f64>| -> Vector2<f64> {
        Vector2::new(u.x * pitch_x, u.y * pitch_y) + displacer.displacement(pass, u.x, u.y) - target
    };
    // Residual in pixels, so both axes weigh alike.
    let in_pixels = |r: Vector2<f64>| Vector2::new(r.x / pitch_x, r.y / pitch_y);
    let mut u = Vector2::new(target.x / pitch_x, target.y / pitch_y);
    let mut r = in_pixels(residual(u));
    let mut converged = r.norm() <= SOLVE_TOLERANCE_PX;
    let h = 1e-4;
    for _ in 0..MAX_ITERATIONS {
        if converged {
            break;
        }
        let rx = in_pixels(residual(u + Vector2::new(h, 0.0)));
        let ry = in_pixels(residual(u + Vector2::new(0.0, h)));
        let jacobian = Matrix2::from_columns(&[(rx - r) / h, (ry - r) / h]);
        let step = jacobian.try_inverse().map_or(r, |inverse| inverse * r);
        let mut scale = 1.0;
        loop {
            let candidate = u - step * scale;
            let rc = in_pixels(residual(candidate));
            if rc.norm() < r.norm() || scale < 1e-4 {
                u = candidate;
                r = rc;
                break;
            }
            scale *= 0.5;
        }
        converged = r.norm() <= SOLVE_TOLERANCE_PX;
    }
    let time = geometry.acquisition_time(pass, u.x, u.y);
    let d = displacer.displacement(pass, u.x, u.y);
    let in_image = |value: f64, count: usize| value >= -0.5 && value <= count as f64 - 0.5;
    FeatureAcquisition {
        controller_position_px: [u.x, u.y],
        controller_position_m: [u.x * pitch_x, u.y * pitch_y],
        time_since_frame_start_s: time.since_frame_start,
        time_since_line_start_s: time.since_line_start,
        displacement_m: [d.x, d.y],
        in_image: in_image(u.x, geometry.columns()) && in_image(u.y, geometry.rows()),
        converged,
        residual_m: Vector2::new(r.x * pitch_x, r.y * pitch_y).norm(),
    }
}

/// Locates every feature in both passes (in parallel; the order is kept).
pub(crate) fn feature_truths(
    displacer: &Displacer,
    features: &[SurfaceFeature],
) -> Vec<FeatureTruth> {
    features
        .par_iter()
        .enumerate()
        .map(|(index, feature)| FeatureTruth {
            index,
            kind: feature.kind,
            sample_position_m: [feature.position.x, feature.position.y],
            amplitude_m: feature.amplitude,
            trace: locate(displacer, ScanPass::Trace, feature.position),
            retrace: locate(displacer, ScanPass::Retrace, feature.position),
        })
        .collect()
}

impl GroundTruth {
    /// The displacement field of `pass`, if simulated.
    pub fn displacement_of(&self, pass: ScanPass) -> Option<&DisplacementField> {
        self.displacement.iter().find(|field| field.pass == pass)
    }

    /// The features imaged (converged, on the image) by `pass`.
    pub fn imaged_features(&self, pass: ScanPass) -> impl Iterator<Item = &FeatureTruth> {
        self.features.iter().filter(move |f| {
            let a = f.acquisition(pass);
            a.in_image && a.converged
        })
    }
}

impl FeatureTruth {
    /// Where and when `pass` imaged this feature.
    pub fn acquisition(&self, pass: ScanPass) -> &FeatureAcquisition {
        match pass {
            ScanPass::Trace => &self.trace,
            ScanPass::Retrace => &self.retrace,
        }
    }
}
