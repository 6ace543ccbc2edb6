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
mod displacement;
mod error;
pub mod fit;
mod hysteresis_problem;
pub mod local;
pub mod mask;
pub mod model;
pub mod neighbours;
mod point;
pub mod registration;
pub mod route_choice;
mod secant;
mod seed;
pub mod series;
mod thinning;

pub use correction::{
    CorrectedFeature, ExtendedImage, correct_features, correct_image, correct_image_full,
    pixel_sample_positions,
};
pub use displacement::{DisplacementField, displacement_field};
pub use error::DistortionError;
pub use fit::{FitOptions, HysteresisChoice, fit_model};
pub use local::{LocalDistortion, LocalSettings, estimate_lattice_angle, local_distortions};
pub use model::{
    Bound, DegeneratePair, DistortionModel, DriftCreep, FitDiagnostics, HysteresisLaw, Parameter,
};
pub use neighbours::{
    AngleStats, ExclusionCounts, NeighbourOptions, NeighbourSelection, Rdf, RdfFit,
    SelectedFeature, nn_angle_stats, radial_distribution, select_features, select_nearest,
};
pub use point::{MappedPoint, map_point};
pub use registration::Registration;
pub use route_choice::{ModelRoute, RouteComparison, RoutePolicy};
pub use seed::SeedMap;

use dhct_features::Feature;
use dhct_lattice::{Lattice, LocalDistortionMethod};
use dhct_scan::{ScanGeometry, ScanPass};
use ndarray::Array2;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Options of [`analyse`]; [`DhctOptions::validate`] checks their ranges.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DhctOptions {
    /// Neighbour search and RDF.
    pub neighbours: NeighbourOptions,
    /// Model fit.
    pub fit: FitOptions,
    /// Local-distortion method; `None` = the lattice's own choice.
    pub method: Option<LocalDistortionMethod>,
    /// Which route's model is used (both are fitted and compared).
    pub route: RoutePolicy,
}

impl DhctOptions {
    /// Checks the neighbour and fit options ([`NeighbourOptions::validate`],
    /// [`FitOptions::validate`]).
    pub fn validate(&self) -> Result<(), DistortionError> {
        self.neighbours.validate()?;
        self.fit.validate()
    }
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
    /// Neighbours, RDF, selection, in the controller frame (the raw positions).
    pub selection: NeighbourSelection,
    /// The neighbours `local` was measured with when they are not `selection`'s (see
    /// [`analyse`] and `neighbour_source`).
    #[serde(default)]
    pub refined_selection: Option<NeighbourSelection>,
    /// Where the neighbours `local` was measured with came from.
    #[serde(default)]
    pub neighbour_source: NeighbourSource,
    /// Estimated lattice angle, radians (display frame).
    pub lattice_angle_rad: f64,
    /// Local distortion of every usable selected feature.
    pub local: Vec<LocalDistortion>,
}

/// The result of [`analyse`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DhctResult {
    /// The fitted model (of the route [`DhctResult::routes`] chose).
    pub model: DistortionModel,
    /// Per-pass diagnostics.
    pub passes: Vec<PassAnalysis>,
    /// The local route against the global registration, cross-validated; `None` when the
    /// registration could not be fitted (then `route_note` says why) or was not tried.
    #[serde(default)]
    pub routes: Option<RouteComparison>,
    /// Why the global registration was not compared, when it was tried and failed.
    #[serde(default)]
    pub route_note: Option<String>,
}

impl DhctResult {
    /// A result of `model` alone (no passes analysed, no routes compared).
    pub fn of_model(model: DistortionModel) -> DhctResult {
        DhctResult {
            model,
            passes: Vec::new(),
            routes: None,
            route_note: None,
        }
    }
}

/// How the neighbours of the local distortions were found.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum NeighbourSource {
    /// The NN window among the raw (controller-frame) positions.
    #[default]
    RawWindow,
    /// The `k` nearest raw positions (the window selected too few features).
    RawNearest,
    /// The NN window among the positions corrected by a first model fit.
    CorrectedFrame,
}

impl PassAnalysis {
    /// The selection whose neighbours the local distortions were measured with.
    pub fn used_selection(&self) -> &NeighbourSelection {
        self.refined_selection.as_ref().unwrap_or(&self.selection)
    }
}

/// A refined selection replaces the raw one only if it selects more than this factor as
/// many features.
const REFINE_GAIN: f64 = 1.1;

/// Runs neighbours, local distortion and the joint fit over all given passes.
///
/// Neighbours are first found among the raw (controller-frame) positions. A large drift
/// squeezes part of the raw lattice out of the NN window, and the features that stay
/// selected are the less distorted ones, which biases the fit (at a drift of 30 % of the
/// slow-scan speed, 20 % of the features stay and the slow scale comes out 0.8 % off).
/// So the neighbours are found again among the positions corrected by that first fit,
/// where the lattice is nearly ideal; if that selects markedly more features, the local
/// distortions are measured again (raw positions, the new neighbour sets) and the model
/// re-fitted, up to twice. Beyond ~30 % no raw feature keeps its full shell in the window;
/// the first model then comes from each feature's `k` nearest neighbours
/// ([`select_nearest`]).
pub fn analyse(
    inputs: &[PassInput],
    geometry: &ScanGeometry,
    lattice: &dyn Lattice,
    options: &DhctOptions,
) -> Result<DhctResult, DistortionError> {
    analyse_seeded(inputs, geometry, lattice, options, None)
}

/// [`analyse`] with the first neighbour search done among the raw positions undone by
/// `seed` (the affine map the image's lattice measured: a pixel size off by tens of percent,
/// a drift that shears the raw lattice), instead of among the raw positions themselves: the
/// NN window around the lattice's spacing would otherwise miss most neighbours. The local
/// distortions are measured in `geometry` all the same, so the model absorbs the map (as
/// slow drift and a hysteresis scale) and its parameters keep their meaning.
///
/// The global registration ([`registration`]) is fitted beside the local route, started
/// from its model, and the two are cross-validated ([`route_choice`]); the model is the
/// winner's. When the local route cannot fit a model at all (too few full neighbour shells:
/// a frame of a few large cells, a lattice stretched past the window), the registration is
/// started from `seed`'s map (else from the raw positions) and its model is used; only
/// when that fails too is the local route's error returned.
pub fn analyse_seeded(
    inputs: &[PassInput],
    geometry: &ScanGeometry,
    lattice: &dyn Lattice,
    options: &DhctOptions,
    seed: Option<&SeedMap>,
) -> Result<DhctResult, DistortionError> {
    // Passes without features are skipped; `inputs[k]` belongs to `passes[k]` from here.
    let inputs: Vec<&PassInput> = inputs.iter().filter(|i| !i.features.is_empty()).collect();
    let (mut model, passes) = match local_route(&inputs, geometry, lattice, options, seed) {
        Ok(local) => local,
        Err(local_error) => {
            return registration_alone(&inputs, geometry, lattice, options, seed, &local_error)
                .map_err(|_| local_error);
        }
    };
    let (routes, route_note) = if options.route == RoutePolicy::LocalOnly {
        (
            None,
            Some("the global registration was not asked for".to_string()),
        )
    } else {
        match global_route(&inputs, &passes, geometry, lattice, &model, options) {
            Ok(routes) => (Some(routes), None),
            Err(e) => (None, Some(e.to_string())),
        }
    };
    if let Some(routes) = &routes
        && routes.chosen == ModelRoute::GlobalRegistration
    {
        model = routes.registration.model.clone();
    }
    Ok(DhctResult {
        model,
        passes,
        routes,
        route_note,
    })
}

/// The paper's route: neighbours (seeded by `seed`, refined in the corrected frame), local
/// distortions, the pooled model fit.
fn local_route(
    inputs: &[&PassInput],
    geometry: &ScanGeometry,
    lattice: &dyn Lattice,
    options: &DhctOptions,
    seed: Option<&SeedMap>,
) -> Result<(DistortionModel, Vec<PassAnalysis>), DistortionError> {
    let method = options
        .method
        .unwrap_or_else(|| lattice.local_distortion_method());
    // The passes are independent until the pooled fit: measured side by side.
    let mut passes: Vec<PassAnalysis> = inputs
        .par_iter()
        .map(|input| {
            let pass = input.features[0].pass;
            let selection = select_seeded(input, seed, geometry, lattice, options)?;
            Ok(measure_pass(
                input, pass, selection, None, geometry, lattice, method,
            ))
        })
        .collect::<Result<_, DistortionError>>()?;
    let windowed: usize = passes.iter().map(|p| p.selection.selected.len()).sum();
    if windowed < fit::MIN_FEATURES {
        // Too distorted for the window: a first model from the k nearest neighbours.
        passes = passes
            .into_iter()
            .zip(inputs)
            .map(|(previous, input)| {
                let selected = nearest_seeded(input, seed, geometry, lattice)?;
                let nearest = NeighbourSelection {
                    selected,
                    exclusions: ExclusionCounts::default(),
                    ..previous.selection.clone()
                };
                Ok(measure_pass(
                    input,
                    previous.pass,
                    previous.selection,
                    Some((nearest, NeighbourSource::RawNearest)),
                    geometry,
                    lattice,
                    method,
                ))
            })
            .collect::<Result<_, DistortionError>>()?;
    }
    let mut model = fit_pooled(&passes, geometry, options)?;
    for _ in 0..2 {
        let refined: Vec<NeighbourSelection> = inputs
            .par_iter()
            .map(|input| {
                let to_sample = |f: &Feature| model.to_sample(geometry, f.pass, f.x_px, f.y_px);
                select_in_frame(input, to_sample, geometry, lattice, options)
            })
            .collect::<Result<_, DistortionError>>()?;
        let gained = refined.iter().zip(&passes).any(|(selection, previous)| {
            let before = previous.used_selection().selected.len();
            // The k-nearest bootstrap is always replaced by the windowed selection.
            let bootstrap = previous.neighbour_source == NeighbourSource::RawNearest;
            (bootstrap && !selection.selected.is_empty())
                || selection.selected.len() as f64 > REFINE_GAIN * before as f64
        });
        if !gained {
            break;
        }
        passes = passes
            .into_par_iter()
            .zip(inputs.par_iter())
            .zip(refined)
            .map(|((previous, input), selection)| {
                measure_pass(
                    input,
                    previous.pass,
                    previous.selection,
                    Some((selection, NeighbourSource::CorrectedFrame)),
                    geometry,
                    lattice,
                    method,
                )
            })
            .collect();
        model = fit_pooled(&passes, geometry, options)?;
    }
    Ok((model, passes))
}

/// The global registration alone, from `seed`'s map (the raw positions without one),
/// when the local route could not fit a model; its cross-validation has no local route to
/// compare with.
fn registration_alone(
    inputs: &[&PassInput],
    geometry: &ScanGeometry,
    lattice: &dyn Lattice,
    options: &DhctOptions,
    seed: Option<&SeedMap>,
    local_error: &DistortionError,
) -> Result<DhctResult, DistortionError> {
    let start = seed
        .and_then(|s| s.as_model(geometry))
        .unwrap_or_else(DistortionModel::identity);
    let inputs: Vec<PassInput> = inputs.iter().map(|i| **i).collect();
    let (registration, features) = registration::register_from(
        &inputs,
        geometry,
        lattice,
        &start,
        registration::StartQuality::Rough,
        &options.fit,
    )?;
    let routes = route_choice::compare_routes(
        &[],
        &features,
        registration,
        geometry,
        lattice.nearest_neighbour_distance(),
        &options.fit,
        options.route,
    )?;
    Ok(DhctResult {
        model: routes.registration.model.clone(),
        passes: Vec::new(),
        routes: Some(routes),
        route_note: Some(format!(
            "the local route could not fit a model ({local_error}); the model is the global \
             registration's"
        )),
    })
}

/// The global registration started from `model` (features indexed in its corrected
/// frame), cross-validated against the local route of `passes`.
fn global_route(
    inputs: &[&PassInput],
    passes: &[PassAnalysis],
    geometry: &ScanGeometry,
    lattice: &dyn Lattice,
    model: &DistortionModel,
    options: &DhctOptions,
) -> Result<RouteComparison, DistortionError> {
    let inputs: Vec<PassInput> = inputs.iter().map(|i| **i).collect();
    let (registration, features) = registration::register_from(
        &inputs,
        geometry,
        lattice,
        model,
        registration::StartQuality::Fitted,
        &options.fit,
    )?;
    let local: Vec<LocalDistortion> = passes.iter().flat_map(|p| p.local.clone()).collect();
    route_choice::compare_routes(
        &local,
        &features,
        registration,
        geometry,
        lattice.nearest_neighbour_distance(),
        &options.fit,
        options.route,
    )
}

/// Local distortions of one pass with the neighbours of `refined` and where they came from
/// (else `selection`'s, the raw window).
fn measure_pass(
    input: &PassInput,
    pass: ScanPass,
    selection: NeighbourSelection,
    refined: Option<(NeighbourSelection, NeighbourSource)>,
    geometry: &ScanGeometry,
    lattice: &dyn Lattice,
    method: LocalDistortionMethod,
) -> PassAnalysis {
    let points_m: Vec<[f64; 2]> = input
        .features
        .iter()
        .map(|f| [f.x_px * geometry.pitch_x(), f.y_px * geometry.pitch_y()])
        .collect();
    let (refined, neighbour_source) = match refined {
        Some((r, source)) => (Some(r), source),
        None => (None, NeighbourSource::RawWindow),
    };
    let used = refined.as_ref().unwrap_or(&selection);
    let angle = estimate_lattice_angle(&points_m, &used.selected, lattice);
    let local = local_distortions(
        input.features,
        &used.selected,
        &LocalSettings {
            geometry,
            lattice,
            method,
            lattice_angle_rad: angle,
        },
    );
    PassAnalysis {
        pass,
        selection,
        refined_selection: refined,
        neighbour_source,
        lattice_angle_rad: angle,
        local,
    }
}

/// The positions (pixels of `geometry`) of the features of `input` inside its mask (judged
/// at their raw position), each moved by `to_frame` (raw metres → metres of another frame),
/// and their indices in `input.features`.
fn moved_positions(
    input: &PassInput,
    geometry: &ScanGeometry,
    to_frame: impl Fn(&Feature) -> [f64; 2],
) -> (Vec<usize>, Vec<[f64; 2]>) {
    let raw: Vec<[f64; 2]> = input.features.iter().map(|f| [f.x_px, f.y_px]).collect();
    let inside = neighbours::inside_mask(&raw, input.mask);
    let kept: Vec<usize> = (0..raw.len()).filter(|&i| inside[i]).collect();
    let moved = kept
        .iter()
        .map(|&i| {
            let [x, y] = to_frame(&input.features[i]);
            [x / geometry.pitch_x(), y / geometry.pitch_y()]
        })
        .collect();
    (kept, moved)
}

/// Indices of `selected` (into the kept features) back to indices into `input.features`.
fn reindexed(mut selected: Vec<SelectedFeature>, kept: &[usize]) -> Vec<SelectedFeature> {
    for s in &mut selected {
        s.index = kept[s.index];
        for n in &mut s.neighbours {
            *n = kept[*n];
        }
    }
    selected
}

/// Neighbour selection among the features of `input` moved by `to_frame` (raw metres →
/// metres of the frame searched). Features outside the mask (judged at their raw position)
/// are left out first; indices refer to `input.features`.
fn select_in_frame(
    input: &PassInput,
    to_frame: impl Fn(&Feature) -> [f64; 2],
    geometry: &ScanGeometry,
    lattice: &dyn Lattice,
    options: &DhctOptions,
) -> Result<NeighbourSelection, DistortionError> {
    let (kept, moved) = moved_positions(input, geometry, to_frame);
    let mut selection = select_features(&moved, geometry, None, lattice, &options.neighbours)?;
    selection.exclusions.outside_mask = input.features.len() - kept.len();
    selection.selected = reindexed(std::mem::take(&mut selection.selected), &kept);
    Ok(selection)
}

/// Raw metres → the frame `seed` undoes the measured map in (about the frame centre).
fn seed_frame<'a>(seed: &'a SeedMap, geometry: &'a ScanGeometry) -> impl Fn(&Feature) -> [f64; 2] {
    let (px, py) = (geometry.pitch_x(), geometry.pitch_y());
    let centre = [
        0.5 * (geometry.columns() as f64 - 1.0) * px,
        0.5 * (geometry.rows() as f64 - 1.0) * py,
    ];
    move |f: &Feature| seed.to_sample_like([f.x_px * px, f.y_px * py], centre)
}

/// The first neighbour selection of a pass: among the raw positions, or among them undone
/// by `seed`.
fn select_seeded(
    input: &PassInput,
    seed: Option<&SeedMap>,
    geometry: &ScanGeometry,
    lattice: &dyn Lattice,
    options: &DhctOptions,
) -> Result<NeighbourSelection, DistortionError> {
    match seed {
        Some(seed) => select_in_frame(
            input,
            seed_frame(seed, geometry),
            geometry,
            lattice,
            options,
        ),
        None => {
            let points: Vec<[f64; 2]> = input.features.iter().map(|f| [f.x_px, f.y_px]).collect();
            select_features(&points, geometry, input.mask, lattice, &options.neighbours)
        }
    }
}

/// [`select_nearest`] among the raw positions, or among them undone by `seed`.
fn nearest_seeded(
    input: &PassInput,
    seed: Option<&SeedMap>,
    geometry: &ScanGeometry,
    lattice: &dyn Lattice,
) -> Result<Vec<SelectedFeature>, DistortionError> {
    match seed {
        Some(seed) => {
            let (kept, moved) = moved_positions(input, geometry, seed_frame(seed, geometry));
            let selected = select_nearest(&moved, geometry, None, lattice)?;
            Ok(reindexed(selected, &kept))
        }
        None => {
            let points: Vec<[f64; 2]> = input.features.iter().map(|f| [f.x_px, f.y_px]).collect();
            select_nearest(&points, geometry, input.mask, lattice)
        }
    }
}

fn fit_pooled(
    passes: &[PassAnalysis],
    geometry: &ScanGeometry,
    options: &DhctOptions,
) -> Result<DistortionModel, DistortionError> {
    let pooled: Vec<LocalDistortion> = passes.iter().flat_map(|p| p.local.clone()).collect();
    fit_model(
        &pooled,
        geometry.frame_duration(),
        geometry.line_scan_time(),
        &options.fit,
    )
}
