//! Nearest neighbours, local distortion, the drift/creep/hysteresis model and the correction
//! (DHCT steps 3–5; Yothers, Browder & Bumm, Rev. Sci. Instrum. 88, 013708 (2017)).
//!
//! # Pipeline
//!
//! 1. [`neighbours`]: KD-tree NN search, RDF and its Gaussian fit at the lattice's shells,
//!    selection of features with the lattice's full NN count inside the mask.
//! 2. [`local`]: the local distortion `S`, `D` at each selected feature (ellipse fit for
//!    lattices whose NNs lie on a circle, local affine map otherwise).
//! 3. [`fit`]: one robust weighted least-squares fit of drift + creep `D(t)` and hysteresis
//!    `S(τ)` to trace and retrace pooled, with uncertainties.
//! 4. [`correction`]: every feature and pixel moved to the sample frame; images resampled.
//!
//! [`analyse`] runs steps 1–3.
//!
//! # Frames, units, signs
//!
//! * **Controller frame**: the display-oriented pixel grid of `dhct-scan` (x = column to the
//!   right, y = row downwards; pixel centres at integers; metres = px·pitch).
//! * **Sample frame**: the same axes and origin, fixed to the sample.
//! * The tip commanded to `p_c` at time `t` (since frame start, from
//!   [`dhct_scan::ScanGeometry::acquisition_time`]) in pass `pass` is at `p_s = p_c + d`,
//!   with `d` the displacement of the tip *relative to the sample* (a sample drifting right
//!   is `d.x < 0`), the convention of `dhct-simulate`. `D = ∂d/∂t` (m/s). `S` is the
//!   apparent local fast-axis scale (> 1: features look farther apart along the fast axis).
//! * SI units throughout (metres, seconds); fits work internally in nm.
//!
//! # Differences from the authors' Matlab (deliberate)
//!
//! * Exact acquisition times for features *and* pixels (within-line time, retrace delay,
//!   turnaround, reversed directions), so corrected pixels and features agree; the
//!   Matlab's pixel/feature off-by-one and missing within-line time are gone.
//! * Exact local kinematics (see [`local`]) and a fit that compares each measurement with
//!   the model's secant over the feature's own neighbours, not the derivative.
//! * Hysteresis displacement is the exact `∫(S − 1)` the simulator uses, anchored so the tip
//!   is continuous at the trace → retrace turnaround; `t0 = exp(q) > 0`; the power law is
//!   checked for `n > −1`.
//! * Weighted (per-axis robust scale), Huber-robust fits with uncertainties; non-square
//!   images; no-data pixels are NaN, not 0; z is never shifted.
//!
//! ```
//! use dhct_distortion::{DistortionModel, DriftCreep, HysteresisLaw};
//! use dhct_scan::{ScanDirection, ScanGeometry, ScanPass};
//!
//! let g = ScanGeometry::new(64, 64, 0.1e-9, 0.1e-9, 1e-3,
//!                           ScanDirection::Right, ScanDirection::Down).unwrap();
//! // 10 pm/s drift to the right (tip relative to sample), no hysteresis.
//! let drift = DriftCreep { velocity_m_per_s: [1e-11, 0.0], ..DriftCreep::none() };
//! let model = DistortionModel::new(drift, HysteresisLaw::none());
//! // The first trace pixel is acquired at t = 0.5 ms: displaced by 5e-15 m.
//! let [x, _] = model.to_sample(&g, ScanPass::Trace, 0.0, 0.0);
//! assert!((x - 5e-15).abs() < 1e-20);
//! ```

pub mod correction;
mod error;
pub mod fit;
mod lm;
pub mod local;
pub mod mask;
pub mod model;
pub mod neighbours;

pub use correction::{CorrectedFeature, correct_features, correct_image, pixel_sample_positions};
pub use error::DistortionError;
pub use fit::{FitOptions, HysteresisChoice, fit_model};
pub use local::{LocalDistortion, LocalSettings, estimate_lattice_angle, local_distortions};
pub use model::{DistortionModel, DriftCreep, HysteresisLaw, Parameter};
pub use neighbours::{
    AngleStats, ExclusionCounts, NeighbourOptions, NeighbourSelection, Rdf, RdfFit,
    SelectedFeature, nn_angle_stats, radial_distribution, select_features,
};

use dhct_features::Feature;
use dhct_lattice::{Lattice, LocalDistortionMethod};
use dhct_scan::{ScanGeometry, ScanPass};
use ndarray::Array2;
use serde::{Deserialize, Serialize};

/// Options of [`analyse`].
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(default)]
pub struct DhctOptions {
    /// Neighbour search and RDF.
    pub neighbours: NeighbourOptions,
    /// Model fit.
    pub fit: FitOptions,
    /// Local-distortion method; `None` = the lattice's own choice.
    pub method: Option<LocalDistortionMethod>,
}

/// One pass's input: its features (controller frame) and optional mask.
#[derive(Debug, Clone, Copy)]
pub struct PassInput<'a> {
    /// The features of one image (all of the same pass).
    pub features: &'a [Feature],
    /// `rows × columns`, true = use.
    pub mask: Option<&'a Array2<bool>>,
}

/// Steps 1–2 for one pass.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PassAnalysis {
    /// Trace or retrace.
    pub pass: ScanPass,
    /// Neighbours, RDF, selection.
    pub selection: NeighbourSelection,
    /// Estimated lattice angle, radians (display frame).
    pub lattice_angle_rad: f64,
    /// Local distortion of every usable selected feature.
    pub local: Vec<LocalDistortion>,
}

/// The result of [`analyse`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DhctResult {
    /// The fitted model.
    pub model: DistortionModel,
    /// Per-pass diagnostics.
    pub passes: Vec<PassAnalysis>,
}

/// Runs neighbours, local distortion and the joint fit over all given passes.
pub fn analyse(
    inputs: &[PassInput],
    geometry: &ScanGeometry,
    lattice: &dyn Lattice,
    options: &DhctOptions,
) -> Result<DhctResult, DistortionError> {
    let method = options
        .method
        .unwrap_or_else(|| lattice.local_distortion_method());
    let mut passes = Vec::new();
    for input in inputs {
        let Some(pass) = input.features.first().map(|f| f.pass) else {
            continue;
        };
        let points_px: Vec<[f64; 2]> = input.features.iter().map(|f| [f.x_px, f.y_px]).collect();
        let selection = select_features(
            &points_px,
            geometry,
            input.mask,
            lattice,
            &options.neighbours,
        )?;
        let points_m: Vec<[f64; 2]> = points_px
            .iter()
            .map(|p| [p[0] * geometry.pitch_x(), p[1] * geometry.pitch_y()])
            .collect();
        let angle = estimate_lattice_angle(&points_m, &selection.selected, lattice);
        let local = local_distortions(
            input.features,
            &selection.selected,
            &LocalSettings {
                geometry,
                lattice,
                method,
                lattice_angle_rad: angle,
            },
        );
        passes.push(PassAnalysis {
            pass,
            selection,
            lattice_angle_rad: angle,
            local,
        });
    }
    let pooled: Vec<LocalDistortion> = passes.iter().flat_map(|p| p.local.clone()).collect();
    let model = fit_model(
        &pooled,
        geometry.frame_duration(),
        geometry.line_scan_time(),
        &options.fit,
    )?;
    Ok(DhctResult { model, passes })
}
