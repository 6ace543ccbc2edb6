//! The machine-readable results of a run: `model.json` (everything numeric) and the short
//! summary printed by `--json`.

use dhct_calibrate::PairCalibration;
use dhct_distortion::{
    DistortionModel, ExclusionCounts, ModelRoute, Parameter, RdfFit, RouteComparison,
};
use dhct_features::LineLevelling;
use dhct_lattice::{Lattice, PlaneGroup};
use dhct_pipeline::{
    AffineComparison, Analysis, CorrectedImageCheck, CorrectionSource, SkippedRegion, StageTimings,
    Warning,
};
use dhct_scan::{ScanGeometry, ScanPass};
use dhct_unitcell::{ConfidenceEllipse, SymmetryResidual};
use serde::Serialize;

/// How well the fitted model describes the local distortion measurements. Each RMS is
/// absent (`null`) when there are none: the global registration fits the model without
/// local neighbour shells.
#[derive(Debug, Clone, Serialize)]
pub struct Goodness {
    /// Local distortion measurements used (trace + retrace).
    pub local_measurements: usize,
    /// RMS of measured − modelled local fast-axis scale S (dimensionless).
    pub rms_scale_residual: Option<f64>,
    /// RMS of measured − modelled drift velocity, x and y, m/s.
    pub rms_drift_residual_m_per_s: [Option<f64>; 2],
    /// RMS of the measured drift velocity about zero, x and y, m/s (what an identity model
    /// would leave).
    pub rms_drift_m_per_s: [Option<f64>; 2],
}

/// Per-image counts.
#[derive(Debug, Clone, Serialize)]
pub struct PassCounts {
    /// Trace or retrace.
    pub pass: ScanPass,
    /// Features accepted.
    pub features: usize,
    /// Watershed regions above the correlation threshold.
    pub candidates: usize,
    /// Candidates rejected.
    pub rejected: usize,
    /// Features with the lattice's full nearest-neighbour shell, used for the model fit.
    pub selected_for_model: usize,
    /// Local distortion measurements (one per usable selected feature).
    pub local_distortions: usize,
    /// Features indexed to a lattice site.
    pub indexed: usize,
    /// Features whose corrected position lies outside the frame: the corrected image
    /// (cropped to the raw frame) does not show them; `features.csv` keeps them.
    pub outside_frame: usize,
    /// Factor per axis `[x, y]` by which the features' fitted 1σ were raised because the
    /// pixel noise is correlated (1 for white noise).
    pub correlated_noise_factor: [f64; 2],
    /// How the scan lines were levelled before the fits, and on what evidence.
    pub line_levelling: LineLevelling,
    /// Why the other features were not selected for the model fit.
    pub exclusions: ExclusionCounts,
    /// Whether the neighbours were found again in the frame corrected by a first fit (a
    /// large distortion left too few raw features with their full NN shell).
    pub neighbours_refined: bool,
    /// The fit of the radial distribution function of the raw (controller-frame) features.
    pub rdf_fit: RdfFit,
}

/// A confidence ellipse in report units.
#[derive(Debug, Clone, Serialize)]
pub struct EllipseSummary {
    /// Semi-axis of the 1σ ellipse along its major axis, metres.
    pub sigma_major_m: f64,
    /// Semi-axis of the 1σ ellipse along its minor axis, metres.
    pub sigma_minor_m: f64,
    /// Semi-axis of the 2σ ellipse along its major axis, metres.
    pub two_sigma_major_m: f64,
    /// Semi-axis of the 2σ ellipse along its minor axis, metres.
    pub two_sigma_minor_m: f64,
    /// Direction of the major axis from +x towards +y, degrees.
    pub angle_deg: f64,
    /// Standard deviation of the feature heights, metres, if heights were given.
    pub sigma_z: Option<f64>,
    /// Deviations the ellipse is made of.
    pub count: usize,
}

impl From<&ConfidenceEllipse> for EllipseSummary {
    fn from(e: &ConfidenceEllipse) -> Self {
        EllipseSummary {
            sigma_major_m: e.sigma_major_m,
            sigma_minor_m: e.sigma_minor_m,
            two_sigma_major_m: 2.0 * e.sigma_major_m,
            two_sigma_minor_m: 2.0 * e.sigma_minor_m,
            angle_deg: e.angle_rad.to_degrees(),
            sigma_z: e.sigma_z_m,
            count: e.count,
        }
    }
}

/// One region's lattice fit.
#[derive(Debug, Clone, Serialize)]
pub struct RegionSummary {
    /// Region number (by size, largest first).
    pub region: usize,
    /// Pixels in the region.
    pub pixels: usize,
    /// Features indexed to a lattice site, all passes.
    pub features_indexed: usize,
    /// Features used in the final lattice fit.
    pub features_used_in_fit: usize,
    /// Fitted lattice origin, metres (sample frame).
    pub origin_m: [f64; 2],
    /// Fitted lattice rotation from +x towards +y, degrees.
    pub angle_deg: f64,
    /// Fitted scales along x and y (1 = the lattice's nominal size).
    pub scale: [f64; 2],
    /// The lattice constant implied along x and y (nominal × scale), metres.
    pub lattice_constant_m: [f64; 2],
    /// RMS deviation of the fitted features from their sites, metres.
    pub rms_deviation_m: f64,
    /// Retrace offset relative to trace (Δx, Δy), metres, when both were fitted.
    pub set_offsets_m: Vec<[f64; 2]>,
    /// Deviations from the whole-region fit, all passes pooled.
    pub whole_ellipse: EllipseSummary,
    /// Corner deviations from the local unit-cell fits, all passes pooled, when there are
    /// enough.
    pub local_ellipse: Option<EllipseSummary>,
    /// Local unit cells fitted, all passes.
    pub local_cells: usize,
}

/// Unit-cell results.
#[derive(Debug, Clone, Serialize)]
pub struct UnitCellSummary {
    /// The plane group of the symmetry average.
    pub group: PlaneGroup,
    /// Local cells found (all regions and passes).
    pub cells_available: usize,
    /// Local cells kept by the selection and averaged.
    pub cells_selected: usize,
    /// How far the averaged cell is from every plane group compatible with the lattice.
    pub residuals: Vec<SymmetryResidual>,
    /// The group's asymmetric unit: polygon corners, fractional coordinates.
    pub asymmetric_unit: Vec<[f64; 2]>,
}

/// The local route against the global registration ([`dhct_distortion::RouteComparison`]
/// without the registration's model, which `model` holds when it was chosen).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RouteSummary {
    /// The route used: `local-distortion` or `global-registration`.
    pub chosen: ModelRoute,
    /// The route with the smaller held-out deviation.
    pub better: ModelRoute,
    /// Held-out RMS deviation from the ideal lattice of the local route, metres.
    pub local_held_out_rms_m: f64,
    /// The same of the global registration, metres.
    pub global_held_out_rms_m: f64,
    /// Cross-validation folds (interleaved bands of lines).
    pub folds: usize,
    /// Features indexed and registered.
    pub features: usize,
}

impl RouteSummary {
    fn of(c: &RouteComparison) -> RouteSummary {
        RouteSummary {
            chosen: c.chosen,
            better: c.better,
            local_held_out_rms_m: c.local_held_out_rms_m,
            global_held_out_rms_m: c.global_held_out_rms_m,
            folds: c.folds,
            features: c.features,
        }
    }

    /// One sentence: both routes' held-out deviations and the one used.
    pub fn describe(&self) -> String {
        let local = if self.local_held_out_rms_m.is_finite() {
            format!("{:.1} pm", self.local_held_out_rms_m * 1e12)
        } else {
            "not fitted".into()
        };
        let used = match self.chosen {
            ModelRoute::LocalDistortion => "local distortions (the paper's route)",
            ModelRoute::GlobalRegistration => "global registration",
        };
        let mut line = format!(
            "held-out rms deviation from the lattice: local distortions {local}, global \
             registration {:.1} pm ({} features, {}-fold cross-validation); model from {used}",
            self.global_held_out_rms_m * 1e12,
            self.features,
            self.folds
        );
        if self.better != self.chosen {
            line.push_str(match self.better {
                ModelRoute::GlobalRegistration => {
                    " (the global registration cross-validates better; the paper's route was \
                     asked for)"
                }
                ModelRoute::LocalDistortion => " (the local route cross-validates better)",
            });
        }
        line
    }
}

/// `angle_deg` reduced into `(−period/2, period/2]` (degrees): a lattice turned by its own
/// symmetry rotation is the same lattice.
pub fn within_period(angle_deg: f64, period_deg: f64) -> f64 {
    if !(period_deg.is_finite() && period_deg > 0.0) {
        return angle_deg;
    }
    let r = angle_deg.rem_euclid(period_deg);
    if r > period_deg / 2.0 {
        r - period_deg
    } else {
        r
    }
}

/// The hysteresis in words: the law and the apparent fast-axis scale `S` (apparent over true
/// length) at the first pixel, mid-line and the last pixel; `None` without hysteresis.
pub fn hysteresis_words(law: &dhct_scan::HysteresisLaw, geometry: &ScanGeometry) -> Option<String> {
    use dhct_scan::HysteresisLaw;
    if *law == HysteresisLaw::none() {
        return None;
    }
    let form = match law {
        HysteresisLaw::Power { .. } => "S = k·τ^n, τ in seconds since the line start",
        HysteresisLaw::Quartic { .. } => "the paper's quartic in τ over the line time",
        HysteresisLaw::Exponential { .. } => "S = 1 + A·exp(−τ/τ_h)",
    };
    let (first, last) = (
        0.5 * geometry.pixel_period(),
        geometry.line_scan_time() - 0.5 * geometry.pixel_period(),
    );
    Some(format!(
        "the image is stretched along the fast axis by S = {:.4} at the first pixel, {:.4} \
         mid-line and {:.4} at the last (apparent over true length: the tip lags behind the \
         controller where S > 1; {form}; 1 = no hysteresis)",
        law.scale(first),
        law.scale(0.5 * (first + last)),
        law.scale(last)
    ))
}

/// Everything numeric of a run (`model.json`).
#[derive(Debug, Clone, Serialize)]
pub struct RunSummary {
    /// The dhct version that made the run.
    pub dhct_version: &'static str,
    /// The input's name: its path, or a note for arrays.
    pub input: String,
    /// The retrace file's path, if the retrace came from its own file.
    pub retrace_input: Option<String>,
    /// The lattice's name.
    pub lattice: String,
    /// Whether the lattice was assumed (none was named: graphite, held to a typed
    /// constant's pixel-size tolerance) rather than given by the user.
    pub lattice_assumed: bool,
    /// The lattice's nearest-neighbour distance, metres.
    pub nearest_neighbour_distance_m: f64,
    /// The rotation (degrees) that maps the lattice onto itself: its rotation in an image is
    /// known modulo this (60 for hexagonal, 90 for square).
    pub rotation_period_deg: f64,
    /// The input's scan geometry.
    pub geometry: ScanGeometry,
    /// The model the correction used: the drift/creep/hysteresis model, or the affine map
    /// when that was kept instead.
    pub model: DistortionModel,
    /// The model's parameters with uncertainty and unit.
    pub parameters: Vec<Parameter>,
    /// How well the model describes the local distortion measurements.
    pub goodness: Goodness,
    /// Per-image counts, trace first.
    pub passes: Vec<PassCounts>,
    /// One lattice fit per mask region (the whole image without a mask), largest first.
    pub regions: Vec<RegionSummary>,
    /// Regions that were not fitted, and why.
    pub skipped_regions: Vec<SkippedRegion>,
    /// The averaged unit cell, when enough cells were selected.
    pub unit_cell: Option<UnitCellSummary>,
    /// Why there is no unit-cell analysis, if there is none.
    pub unit_cell_note: Option<String>,
    /// What not to trust and what to do, each with a stable `code` (see
    /// `dhct_pipeline::WarningCode`).
    pub warnings: Vec<Warning>,
    /// The lattice the images show in file units and the calibration it gives (x and y
    /// scale, shear, rotation), measured before anything else; `null` with
    /// `calibration_note` saying why when it could not be measured.
    pub calibration: Option<PairCalibration>,
    /// Why there is no calibration, if there is none.
    pub calibration_note: Option<String>,
    /// Per region: the full model against the global affine correction (same lattice fit).
    pub affine_baseline: Vec<AffineComparison>,
    /// The model's two routes (local distortions, global registration) cross-validated on
    /// the image's own features, and the one chosen; `null` with `model_route_note` saying
    /// why when the registration could not be fitted.
    pub model_routes: Option<RouteSummary>,
    /// Why the routes were not compared, or how the model was found when the local route
    /// failed.
    pub model_route_note: Option<String>,
    /// Which correction the corrected data come from (`drift-model` or `affine`).
    pub correction: CorrectionSource,
    /// The fitted drift/creep/hysteresis model when the affine correction was kept instead
    /// (`model` and `parameters` then describe the affine map).
    pub rejected_model: Option<DistortionModel>,
    /// Each corrected image's lattice measured by FFT against the lattice given (x and y
    /// scale, shear): the check an outside user would make.
    pub corrected_images: Vec<CorrectedImageCheck>,
    /// Wall time of each analysis stage, seconds.
    pub timings: StageTimings,
    /// Reading the input, seconds.
    pub read_s: f64,
    /// Writing the outputs and the report, seconds (filled after writing).
    pub write_s: f64,
    /// The files written, names relative to the output directory (filled after writing).
    pub outputs: Vec<String>,
}

fn rms(values: impl Iterator<Item = f64>) -> f64 {
    let (mut sum, mut n) = (0.0, 0usize);
    for v in values.filter(|v| v.is_finite()) {
        sum += v * v;
        n += 1;
    }
    if n == 0 {
        f64::NAN
    } else {
        (sum / n as f64).sqrt()
    }
}

/// How well `analysis`'s model describes its local distortion measurements.
pub fn goodness(analysis: &Analysis) -> Goodness {
    let model = &analysis.dhct.model;
    let local: Vec<_> = analysis
        .dhct
        .passes
        .iter()
        .flat_map(|p| p.local.iter())
        .collect();
    // No local measurements (the global registration route): no RMS, rather than NaN.
    let measured = |v: f64| v.is_finite().then_some(v);
    Goodness {
        local_measurements: local.len(),
        rms_scale_residual: measured(rms(local
            .iter()
            .map(|l| l.scale - model.hysteresis.scale(l.line_time_s)))),
        rms_drift_residual_m_per_s: [0, 1].map(|k| {
            measured(rms(local
                .iter()
                .map(|l| l.drift_m_per_s[k] - model.drift.velocity(l.time_s)[k])))
        }),
        rms_drift_m_per_s: [0, 1].map(|k| measured(rms(local.iter().map(|l| l.drift_m_per_s[k])))),
    }
}

/// The features of `p` whose corrected position lies outside its frame (pixel centres at
/// whole output pixels, so the frame spans `[-0.5, n - 0.5]`).
fn outside_frame(p: &dhct_pipeline::PassOutput) -> usize {
    let (rows, columns) = p.corrected_image.dim();
    let inside = |v: f64, n: usize| v >= -0.5 && v <= n as f64 - 0.5;
    p.corrected
        .iter()
        .filter(|f| !(inside(f.x_px, columns) && inside(f.y_px, rows)))
        .count()
}

/// The counts of one image.
fn pass_counts(analysis: &Analysis, p: &dhct_pipeline::PassOutput) -> PassCounts {
    let dhct = analysis.dhct.passes.iter().find(|d| d.pass == p.pass);
    PassCounts {
        pass: p.pass,
        features: p.features.features.len(),
        candidates: p.features.candidates,
        rejected: p.features.rejected.len(),
        selected_for_model: dhct.map(|d| d.used_selection().selected.len()).unwrap_or(0),
        local_distortions: dhct.map(|d| d.local.len()).unwrap_or(0),
        indexed: p.indices.iter().flatten().count(),
        outside_frame: outside_frame(p),
        correlated_noise_factor: p.features.correlated_noise_factor,
        line_levelling: p.features.line_levelling.clone(),
        exclusions: dhct
            .map(|d| d.used_selection().exclusions)
            .unwrap_or_default(),
        neighbours_refined: dhct.is_some_and(|d| d.refined_selection.is_some()),
        rdf_fit: dhct.map(|d| d.selection.rdf_fit.clone()).unwrap_or(RdfFit {
            nn_distance_m: f64::NAN,
            shells_m: vec![],
            amplitudes: vec![],
            widths_m: vec![],
            fwhm_m: vec![],
        }),
    }
}

/// One region's lattice fit; `nominal` = |a1|, |a2| of the lattice given, metres.
fn region_summary(r: &dhct_pipeline::RegionFit, nominal: [f64; 2]) -> RegionSummary {
    RegionSummary {
        region: r.region,
        pixels: r.pixels,
        features_indexed: r.members.iter().map(Vec::len).sum(),
        features_used_in_fit: r.fit.used,
        origin_m: r.fit.origin_m,
        angle_deg: r.fit.angle_rad.to_degrees(),
        scale: r.fit.scale,
        lattice_constant_m: [nominal[0] * r.fit.scale[0], nominal[1] * r.fit.scale[1]],
        rms_deviation_m: r.fit.rms_deviation_m,
        set_offsets_m: r.fit.set_offsets_m.iter().skip(1).copied().collect(),
        whole_ellipse: (&r.whole_ellipse).into(),
        local_ellipse: r.local_ellipse.as_ref().map(Into::into),
        local_cells: r.local_cells.iter().map(Vec::len).sum(),
    }
}

/// The summary of `analysis` of an input named `input` (and `retrace_input`) read in
/// `read_s` seconds; `outputs` and `write_s` are left empty for the writer to fill.
pub fn summarise(
    input: String,
    retrace_input: Option<String>,
    lattice: &dyn Lattice,
    geometry: &ScanGeometry,
    analysis: &Analysis,
    read_s: f64,
) -> RunSummary {
    let [a1, a2] = lattice.primitive_vectors();
    let nominal = [a1.norm(), a2.norm()];
    let passes = analysis
        .passes
        .iter()
        .map(|p| pass_counts(analysis, p))
        .collect();
    let regions = analysis
        .regions
        .iter()
        .map(|r| region_summary(r, nominal))
        .collect();
    RunSummary {
        dhct_version: env!("CARGO_PKG_VERSION"),
        input,
        retrace_input,
        lattice: lattice.name().to_string(),
        rotation_period_deg: lattice.bond_direction_period().to_degrees(),
        lattice_assumed: false,
        nearest_neighbour_distance_m: lattice.nearest_neighbour_distance(),
        geometry: geometry.clone(),
        model: analysis.dhct.model.clone(),
        parameters: analysis.dhct.model.parameters.clone(),
        goodness: goodness(analysis),
        passes,
        regions,
        skipped_regions: analysis.skipped_regions.clone(),
        unit_cell: analysis.unit_cell.as_ref().map(|c| UnitCellSummary {
            group: c.group,
            cells_available: c.cells_available,
            cells_selected: c.cells_selected,
            residuals: c.residuals.clone(),
            asymmetric_unit: c.asymmetric_unit.clone(),
        }),
        unit_cell_note: analysis.unit_cell_note.clone(),
        warnings: analysis.warnings.clone(),
        calibration: analysis.calibration.as_ref().ok().cloned(),
        calibration_note: analysis.calibration.as_ref().err().cloned(),
        affine_baseline: analysis.affine.clone(),
        model_routes: analysis.dhct.routes.as_ref().map(RouteSummary::of),
        model_route_note: analysis.dhct.route_note.clone(),
        correction: analysis.correction,
        rejected_model: analysis.rejected_model.clone(),
        corrected_images: analysis.corrected_images.clone(),
        timings: analysis.timings,
        read_s,
        write_s: 0.0,
        outputs: Vec::new(),
    }
}
