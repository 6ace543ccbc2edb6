//! Observations: the features of a trace/retrace pair with their times, their lattice
//! indices and the base DHCT "sim" prediction.
//!
//! The base stage runs [`dhct_distortion::analyse`] (the local-distortion DHCT fit), or
//! takes a correction already made (the pipeline's), moves every feature to the sample frame, fits the lattice to the corrected features
//! ([`dhct_lattice::fit_lattice`]) so that each feature gets its ideal site, and pushes the
//! ideal site back through the fitted distortion: the predicted controller position solves
//! `p + d(t(p), pass) = site` (Newton in pixels). The gap of that "sim" is
//! `measured − predicted` in the controller frame.

use dhct_distortion::{DhctOptions, DistortionModel, PassInput, analyse, correct_features};
use dhct_features::Feature;
use dhct_lattice::{IndexedPoint, Lattice, LatticeFit, LatticeFitOptions, fit_lattice};
use dhct_scan::{ScanGeometry, ScanPass};
use nalgebra::Vector2;
use serde::{Deserialize, Serialize};

use crate::DiagnoseError;

/// Minimum number of indexed features for a diagnosis.
pub const MIN_FEATURES: usize = 40;

/// One feature as the diagnosis sees it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Observation {
    /// Index of the (non-empty) feature set it came from, in input order.
    pub set: usize,
    /// Index of the feature within its set.
    pub index: usize,
    /// Trace or retrace.
    pub pass: ScanPass,
    /// Measured controller position, metres (display frame).
    pub controller_m: [f64; 2],
    /// Seconds since frame start.
    pub time_s: f64,
    /// Seconds since the start of the feature's line (its own pass).
    pub line_time_s: f64,
    /// Local terrace level (the feature fit's background `z0` plus the line level removed
    /// before the fit, minus their median), metres.
    pub terrace_height_m: f64,
    /// Apparent feature height (signed amplitude), z units.
    pub apparent_height: f64,
    /// 1σ position uncertainty from the feature fit, metres `[x, y]`.
    pub fit_sigma_m: [f64; 2],
    /// Lattice indices `(n, m, site)`.
    pub indices: (i64, i64, usize),
    /// Ideal lattice vector `n·a1 + m·a2 + f_site`, metres, lattice frame (unrotated).
    pub lattice_vector_m: [f64; 2],
    /// `G⁻¹`, rows: the residual is compared with `fit_sigma_m` after this map, which
    /// undoes how a localisation error reaches it through the acquisition time assigned
    /// from the measured position (`timing_gain.rs`); the identity until the base model
    /// is known.
    pub whitening: [[f64; 2]; 2],
}

/// Result of the base stage.
#[derive(Debug, Clone)]
pub(crate) struct Prepared {
    pub observations: Vec<Observation>,
    pub dhct_model: DistortionModel,
    pub lattice_fit: LatticeFit,
    /// Controller-frame gap of the DHCT sim, metres, per observation.
    pub dhct_gap: Vec<[f64; 2]>,
    /// Features dropped: not indexed or farther than the deviation limit from their site.
    pub unindexed: usize,
    /// Features dropped: their fit residual is over [`POOR_FIT_FACTOR`] × the median.
    pub poor_fits: usize,
    pub input_features: usize,
}

/// A feature whose Gaussian fit leaves a residual RMS this many times the median one is
/// not used: the model does not describe it, so neither its centre nor its background
/// (the terrace height a height coupling acts on) can be trusted. Measured on the
/// `rendered-dev` scans with a step edge: the few such fits (residual 43 pm against a
/// median of 2–4 pm, background 500–900 pm off) held a height coupling's gap at 1.88 and
/// 1.26 × the floor; without them 1.39 and 1.01.
pub(crate) const POOR_FIT_FACTOR: f64 = 4.0;

/// The features the base stage turned into observations, and the numbers it dropped.
struct Observed {
    observations: Vec<Observation>,
    dhct_gap: Vec<[f64; 2]>,
    unindexed: usize,
    poor_fits: usize,
}

fn check(sets: &[&[Feature]]) -> Result<(), DiagnoseError> {
    for (s, set) in sets.iter().enumerate() {
        for (i, f) in set.iter().enumerate() {
            let bad = |what| DiagnoseError::NotFinite {
                set: s,
                index: i,
                what,
            };
            if !(f.x_px.is_finite() && f.y_px.is_finite()) {
                return Err(bad("position"));
            }
            if !(f.time_s.is_finite() && f.line_time_s.is_finite()) {
                return Err(bad("acquisition time"));
            }
        }
    }
    Ok(())
}

/// Solves `p + d(p) = target` for the controller pixel position `p` of `pass`.
pub(crate) fn predict_controller(
    model: &DistortionModel,
    geometry: &ScanGeometry,
    pass: ScanPass,
    target_m: [f64; 2],
    start_px: [f64; 2],
) -> [f64; 2] {
    let (px, py) = (geometry.pitch_x(), geometry.pitch_y());
    let f = |u: [f64; 2]| {
        let s = model.to_sample(geometry, pass, u[0], u[1]);
        [(s[0] - target_m[0]) / px, (s[1] - target_m[1]) / py]
    };
    let mut u = start_px;
    for _ in 0..20 {
        let r = f(u);
        if r[0].hypot(r[1]) < 1e-7 {
            break;
        }
        let h = 1e-3;
        let rx = f([u[0] + h, u[1]]);
        let ry = f([u[0], u[1] + h]);
        let (a, b, c, d) = (
            (rx[0] - r[0]) / h,
            (ry[0] - r[0]) / h,
            (rx[1] - r[1]) / h,
            (ry[1] - r[1]) / h,
        );
        let det = a * d - b * c;
        if det.abs() < 1e-12 {
            break;
        }
        u = [
            u[0] - (d * r[0] - b * r[1]) / det,
            u[1] - (-c * r[0] + a * r[1]) / det,
        ];
    }
    [u[0] * px, u[1] * py]
}

/// The features inside their masks (pixel under the feature's centre), per non-empty set,
/// with their indices in the input set.
struct Masked {
    /// Per kept set, the input index of each feature kept.
    original: Vec<Vec<usize>>,
    /// Per kept set, the features kept.
    sets: Vec<Vec<Feature>>,
}

impl Masked {
    fn new(inputs: &[PassInput]) -> Masked {
        let mut original: Vec<Vec<usize>> = Vec::new();
        let mut owned: Vec<Vec<Feature>> = Vec::new();
        for input in inputs {
            let mut idx = Vec::new();
            let mut kept = Vec::new();
            for (i, f) in input.features.iter().enumerate() {
                let inside = input.mask.is_none_or(|m| {
                    let (r, c) = (f.y_px.round(), f.x_px.round());
                    r >= 0.0
                        && c >= 0.0
                        && m.get((r as usize, c as usize)).copied().unwrap_or(false)
                });
                if inside {
                    idx.push(i);
                    kept.push(f.clone());
                }
            }
            if !kept.is_empty() {
                original.push(idx);
                owned.push(kept);
            }
        }
        Masked {
            original,
            sets: owned,
        }
    }
}

/// Runs the base stage on `sets` (controller frame, each of one pass).
pub(crate) fn prepare(
    inputs: &[PassInput],
    geometry: &ScanGeometry,
    lattice: &dyn Lattice,
    source: &BaseSource,
    max_deviation_fraction: f64,
) -> Result<Prepared, DiagnoseError> {
    let raw: Vec<&[Feature]> = inputs.iter().map(|i| i.features).collect();
    check(&raw)?;
    // Apply the masks (pixel under the feature's centre); keep the original indices.
    let masked = Masked::new(inputs);
    let sets: Vec<&[Feature]> = masked.sets.iter().map(|s| s.as_slice()).collect();
    let input_features: usize = raw.iter().map(|s| s.len()).sum();
    if input_features < MIN_FEATURES {
        return Err(DiagnoseError::TooFewFeatures {
            what: "diagnosis",
            found: input_features,
            needed: MIN_FEATURES,
        });
    }
    let (model, fit) = base_fits(&sets, geometry, lattice, source)?;
    let base = BaseStage::new(&model, &fit, geometry, lattice, &sets);
    let Observed {
        observations,
        dhct_gap,
        unindexed,
        poor_fits,
    } = base.observe(&sets, &masked.original, max_deviation_fraction);
    if observations.len() < MIN_FEATURES {
        return Err(DiagnoseError::TooFewFeatures {
            what: "diagnosis (indexed features)",
            found: observations.len(),
            needed: MIN_FEATURES,
        });
    }
    Ok(Prepared {
        observations,
        dhct_model: model,
        lattice_fit: fit,
        dhct_gap,
        unindexed,
        poor_fits,
        input_features,
    })
}

/// Where the base stage's correction comes from.
#[derive(Debug, Clone, Copy)]
pub(crate) enum BaseSource<'a> {
    /// Fitted here ([`analyse`] with these options); the lattice with default options.
    Fit(&'a DhctOptions),
    /// A correction already made (e.g. the pipeline's, drift model or affine) and the
    /// lattice-fit options it was judged with: nothing is refitted.
    Given {
        model: &'a DistortionModel,
        lattice_fit: &'a LatticeFitOptions,
    },
}

/// The base correction of `sets` (fitted or given, see [`BaseSource`]) and the lattice
/// fitted to the features it corrected (sample frame).
fn base_fits(
    sets: &[&[Feature]],
    geometry: &ScanGeometry,
    lattice: &dyn Lattice,
    source: &BaseSource,
) -> Result<(DistortionModel, LatticeFit), DiagnoseError> {
    let (model, lattice_options) = match *source {
        BaseSource::Fit(dhct) => {
            let inputs: Vec<PassInput> = sets
                .iter()
                .map(|s| PassInput {
                    features: s,
                    mask: None,
                })
                .collect();
            let model = analyse(&inputs, geometry, lattice, dhct)?.model;
            (model, LatticeFitOptions::default())
        }
        BaseSource::Given { model, lattice_fit } => (model.clone(), *lattice_fit),
    };
    let corrected: Vec<Vec<[f64; 2]>> = sets
        .iter()
        .map(|s| {
            correct_features(&model, geometry, s)
                .iter()
                .map(|c| [c.x_m, c.y_m])
                .collect()
        })
        .collect();
    let refs: Vec<&[[f64; 2]]> = corrected.iter().map(|c| c.as_slice()).collect();
    let fit = fit_lattice(lattice, &refs, &lattice_options)?;
    Ok((model, fit))
}

/// What turns the features into observations: the base stage's fits, the scan, the
/// lattice and its primitive vectors (metres), and the median local background
/// (`z0 + removed_level`) of every feature.
struct BaseStage<'a> {
    model: &'a DistortionModel,
    fit: &'a LatticeFit,
    geometry: &'a ScanGeometry,
    lattice: &'a dyn Lattice,
    primitive: [Vector2<f64>; 2],
    z0_median: f64,
}

impl<'a> BaseStage<'a> {
    fn new(
        model: &'a DistortionModel,
        fit: &'a LatticeFit,
        geometry: &'a ScanGeometry,
        lattice: &'a dyn Lattice,
        sets: &[&[Feature]],
    ) -> BaseStage<'a> {
        let z0_median = dhct_numerics::robust::finite_median(
            sets.iter()
                .flat_map(|s| s.iter().map(|f| f.z0 + f.removed_level)),
        )
        .unwrap_or(0.0);
        BaseStage {
            model,
            fit,
            geometry,
            lattice,
            primitive: lattice.primitive_vectors(),
            z0_median,
        }
    }

    /// Every indexed feature of `sets` within `max_deviation_fraction` of the NN distance
    /// of its site and with a fit residual within [`POOR_FIT_FACTOR`] of the median, as an
    /// observation, with the DHCT sim's gap (controller frame, metres); and the numbers of
    /// features dropped. `original` maps back to the input indices.
    fn observe(
        &self,
        sets: &[&[Feature]],
        original: &[Vec<usize>],
        max_deviation_fraction: f64,
    ) -> Observed {
        let (fit, lattice, geometry) = (self.fit, self.lattice, self.geometry);
        let nn = lattice.nearest_neighbour_distance() * fit.scale[0].abs().max(fit.scale[1].abs());
        let (px, py) = (geometry.pitch_x(), geometry.pitch_y());
        let poor_limit = dhct_numerics::robust::finite_median(
            sets.iter().flat_map(|s| s.iter().map(|f| f.residual_rms)),
        )
        .filter(|m| *m > 0.0)
        .map_or(f64::INFINITY, |m| POOR_FIT_FACTOR * m);
        let mut observations = Vec::new();
        let mut dhct_gap = Vec::new();
        let (mut unindexed, mut poor_fits) = (0, 0);
        for (s, set) in sets.iter().enumerate() {
            for (i, f) in set.iter().enumerate() {
                if f.residual_rms > poor_limit {
                    poor_fits += 1;
                    continue;
                }
                let Some(p) = fit.points.get(s).and_then(|pts| pts.get(i)) else {
                    unindexed += 1;
                    continue;
                };
                if p.deviation_m[0].hypot(p.deviation_m[1]) > max_deviation_fraction * nn {
                    unindexed += 1;
                    continue;
                }
                let site = fit.site_position(lattice, p.n, p.m, p.site, 0);
                let predicted =
                    predict_controller(self.model, geometry, f.pass, site, [f.x_px, f.y_px]);
                dhct_gap.push([f.x_px * px - predicted[0], f.y_px * py - predicted[1]]);
                observations.push(self.observation((s, original[s][i]), f, p));
            }
        }
        Observed {
            observations,
            dhct_gap,
            unindexed,
            poor_fits,
        }
    }

    /// The observation of feature `f` (input `index` of set `set`) indexed as `p`.
    fn observation(
        &self,
        (set, index): (usize, usize),
        f: &Feature,
        p: &IndexedPoint,
    ) -> Observation {
        let (px, py) = (self.geometry.pitch_x(), self.geometry.pitch_y());
        let [a1, a2] = self.primitive;
        let x = a1 * p.n as f64 + a2 * p.m as f64 + self.lattice.site_position(p.site);
        let sigma = |v: f64, pitch: f64| {
            if v.is_finite() && v > 0.0 {
                v * pitch
            } else {
                f64::NAN
            }
        };
        Observation {
            set,
            index,
            pass: f.pass,
            controller_m: [f.x_px * px, f.y_px * py],
            time_s: f.time_s,
            line_time_s: f.line_time_s,
            terrace_height_m: match f.z0 + f.removed_level {
                z if z.is_finite() => z - self.z0_median,
                _ => 0.0,
            },
            apparent_height: f.height,
            fit_sigma_m: [sigma(f.x_sigma_px, px), sigma(f.y_sigma_px, py)],
            indices: (p.n, p.m, p.site),
            lattice_vector_m: [x.x, x.y],
            whitening: NO_WHITENING,
        }
    }
}

/// The identity: residuals compared with the fits' 1σ as they are.
pub(crate) const NO_WHITENING: [[f64; 2]; 2] = [[1.0, 0.0], [0.0, 1.0]];

/// `w·v`: a residual `v` whitened by an observation's 2 × 2 matrix `w` (rows).
pub(crate) fn whiten(w: &[[f64; 2]; 2], v: [f64; 2]) -> [f64; 2] {
    [
        w[0][0] * v[0] + w[0][1] * v[1],
        w[1][0] * v[0] + w[1][1] * v[1],
    ]
}
