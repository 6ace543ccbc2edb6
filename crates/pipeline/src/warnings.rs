//! What a finished analysis should not be trusted for: weak spots of the fit, results that
//! look wrong although every stage succeeded, and assumptions taken instead of data. Each
//! warning has a stable code, a message with the numbers, and what the user can do.

use dhct_calibrate::PairCalibration;
use dhct_distortion::{DhctResult, Parameter};
use dhct_lattice::Lattice;
use dhct_scan::quantity::{si, value_with_sigma};
use dhct_scan::{ScanGeometry, ScanPair, ScanPass, ValueSource};
use serde::{Deserialize, Serialize};

use crate::{
    AffineComparison, CORRECTED_ANGLE_TOLERANCE_DEG, CORRECTED_SCALE_TOLERANCE,
    CorrectedImageCheck, PassOutput, RegionFit,
};

/// Ratio of the lattice-fit deviation to the features' localisation uncertainty beyond
/// which a warning is given.
pub const DEVIATION_WARNING: f64 = 3.0;

/// Fitted lattice scale beyond which a warning is given (fraction).
pub const SCALE_WARNING: f64 = 0.03;

/// Apparent scale error (fraction, mean or per axis) beyond which the calibration is
/// reported as a warning: hysteresis and drift alone stretch a frame by a few per cent
/// (5 % × 3 % on the embedded example), which the model removes; beyond 10 % the file's
/// pixel size is likely off.
pub const CALIBRATION_WARNING: f64 = 0.10;

/// Below this fraction of indexed features a warning is given.
pub const INDEXED_WARNING: f64 = 0.5;

/// What a warning is about (stable names, for scripts).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum WarningCode {
    /// The lattice could not be measured from the image's Fourier transform.
    LatticeNotMeasured,
    /// The file's pixel size is off (calibrated from the lattice).
    PixelSizeCalibrated,
    /// The scan timing (pixel period, turnaround, directions) was assumed.
    AssumedTiming,
    /// The pixel size was assumed.
    AssumedPixelSize,
    /// A fitted parameter ended at a bound of its range.
    ParameterAtBound,
    /// Two fitted parameters are nearly degenerate.
    DegenerateParameters,
    /// A parameter's uncertainty exceeds its value, or is undetermined.
    UncertainParameter,
    /// The RDF fit is degenerate (shell widths implausible).
    ImplausibleRdf,
    /// The full model does worse than a global affine correction.
    WorseThanAffine,
    /// The corrected lattice is far from the nominal one.
    LatticeScale,
    /// Trace and retrace disagree after correction.
    TraceRetraceOffset,
    /// Features deviate far more than their localisation uncertainty.
    LargeDeviation,
    /// Few features were indexed.
    FewIndexed,
    /// A corrected image's lattice, measured by FFT, is not the lattice given.
    CorrectedImageOff,
    /// A corrected image's lattice could not be measured by FFT, so the correction is not
    /// checked against the image (the raw image's lattice was measured).
    CorrectedImageUnchecked,
    /// The drift model could not be fitted; the global affine correction was used.
    ModelNotFitted,
    /// The drift model's corrected image was not the lattice given; the global affine
    /// correction, whose image did better, was kept.
    ModelImageOff,
    /// One frame of a series deviates far more from the lattice than the others: the
    /// session's model does not explain it.
    FrameNotExplained,
    /// Two frames of a series, registered, do not line up pixel for pixel.
    FramesDisagree,
    /// Two consecutive frames registered by their images matched on few of their bands of
    /// lines: the drift within the later one rests on the spline's smoothness.
    FewComparisons,
    /// Whole lines of an image hold no data (not recorded: a scan stopped early).
    MissingLines,
}

/// An input the user can give to change a result. Each front end spells it its own way
/// (the command line as a flag, Python as a keyword), so the library's texts name the
/// quantity and list these values rather than an option's spelling.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum UserInput {
    /// Which lattice the image shows.
    Lattice,
    /// The lattice's nearest-neighbour distance.
    NearestNeighbourDistance,
    /// The time per scan line.
    LineTime,
    /// The time per pixel along the fast axis.
    PixelPeriod,
    /// The pixel size.
    PixelSize,
    /// The time at each line end.
    Turnaround,
    /// The fast and slow scan directions.
    ScanDirections,
    /// A mask restricting the analysis.
    Mask,
    /// Whether the tracked features are bright (maxima) or dark (minima).
    Polarity,
    /// That the lattice constant is right and the file's pixel size may be off
    /// (calibrate the pixel size from the lattice).
    CalibratePixelSize,
    /// That the inputs are trusted: no check against the image, no calibration.
    TrustInputs,
}

/// One warning.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Warning {
    /// What it is about.
    pub code: WarningCode,
    /// What was found, with the numbers.
    pub message: String,
    /// What the user can do about it (naming quantities, not option spellings).
    pub what_to_do: String,
    /// The inputs [`Warning::what_to_do`] refers to, for front ends to name their options.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub inputs: Vec<UserInput>,
    /// Whether the advice is to diagnose the gap between the model and the data (front
    /// ends name their way: `dhct diagnose`, `dhct.diagnose`).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub suggests_diagnosis: bool,
}

impl Warning {
    /// A warning of `code`: what was found (`message`, with the numbers) and what to do.
    pub fn new(code: WarningCode, message: String, what_to_do: &str) -> Warning {
        Warning {
            code,
            message,
            what_to_do: what_to_do.to_string(),
            inputs: Vec::new(),
            suggests_diagnosis: false,
        }
    }

    /// The same warning, advising a diagnosis of the gap.
    pub fn suggesting_diagnosis(mut self) -> Warning {
        self.suggests_diagnosis = true;
        self
    }

    /// The same warning, naming the inputs its advice refers to.
    pub fn with_inputs(mut self, inputs: &[UserInput]) -> Warning {
        self.inputs = inputs.to_vec();
        self
    }
}

impl std::fmt::Display for Warning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{}: {} (what to do: {})",
            self.code.name(),
            self.message,
            self.what_to_do
        )
    }
}

impl WarningCode {
    /// The stable name (as in JSON).
    pub fn name(self) -> &'static str {
        match self {
            WarningCode::LatticeNotMeasured => "lattice_not_measured",
            WarningCode::PixelSizeCalibrated => "pixel_size_calibrated",
            WarningCode::AssumedTiming => "assumed_timing",
            WarningCode::AssumedPixelSize => "assumed_pixel_size",
            WarningCode::ParameterAtBound => "parameter_at_bound",
            WarningCode::DegenerateParameters => "degenerate_parameters",
            WarningCode::UncertainParameter => "uncertain_parameter",
            WarningCode::ImplausibleRdf => "implausible_rdf",
            WarningCode::WorseThanAffine => "worse_than_affine",
            WarningCode::LatticeScale => "lattice_scale",
            WarningCode::TraceRetraceOffset => "trace_retrace_offset",
            WarningCode::LargeDeviation => "large_deviation",
            WarningCode::FewIndexed => "few_indexed",
            WarningCode::CorrectedImageOff => "corrected_image_off",
            WarningCode::CorrectedImageUnchecked => "corrected_image_unchecked",
            WarningCode::ModelNotFitted => "model_not_fitted",
            WarningCode::ModelImageOff => "model_image_off",
            WarningCode::FrameNotExplained => "frame_not_explained",
            WarningCode::FramesDisagree => "frames_disagree",
            WarningCode::FewComparisons => "few_comparisons",
            WarningCode::MissingLines => "missing_lines",
        }
    }
}

/// What the calibration stage found or could not do.
pub(crate) fn calibration_warnings(found: &Result<PairCalibration, String>) -> Vec<Warning> {
    let found = match found {
        Ok(found) => found,
        Err(reason) => {
            return vec![
                Warning::new(
                    WarningCode::LatticeNotMeasured,
                    format!(
                        "the lattice could not be measured from the image's Fourier transform \
                     ({reason}): the lattice and its constant were not checked against the \
                     image, and the file's pixel size is taken as right"
                    ),
                    "check that the lattice and its nearest-neighbour distance describe the \
                 image; a mask over the atomically resolved area helps the measurement",
                )
                .with_inputs(&[
                    UserInput::Lattice,
                    UserInput::NearestNeighbourDistance,
                    UserInput::Mask,
                ]),
            ];
        }
    };
    let c = &found.calibration;
    let off = |k: f64| (k - 1.0).abs() > CALIBRATION_WARNING;
    if !(off(c.scale[0]) || off(c.scale[1]) || off(c.mean_scale)) {
        return Vec::new();
    }
    vec![
        Warning::new(
            WarningCode::PixelSizeCalibrated,
            format!(
                "the lattice looks {:.1} % × {:.1} % as long along x × y in the file as the \
             lattice given (shear {:.1}°): the file's pixel size is likely off (a constant \
             drift or the piezo hysteresis stretch a frame too, by less); the lattice was \
             taken as the standard",
                100.0 * c.scale[0],
                100.0 * c.scale[1],
                c.shear_deg
            ),
            "if the lattice constant given is right, nothing: the corrected data are calibrated \
         by it; otherwise give the right one",
        )
        .with_inputs(&[UserInput::NearestNeighbourDistance]),
    ]
}

/// What stage 0 found about the inputs: the calibration's warnings, the assumptions
/// taken for what the file did not state, and lines that hold no data.
pub(crate) fn input_warnings(
    calibration: &Result<PairCalibration, String>,
    pair: &ScanPair,
) -> Vec<Warning> {
    let mut warnings = calibration_warnings(calibration);
    warnings.extend(assumption_warnings(pair.geometry()));
    warnings.extend(missing_lines_warning(pair));
    warnings
}

/// Whole lines with no finite value, per image: a scan stopped before its last line (the
/// readers read lines that repeat one value to the end as not recorded).
pub(crate) fn missing_lines_warning(pair: &ScanPair) -> Option<Warning> {
    let geometry = pair.geometry();
    let lines = geometry.slow_len();
    let counts: Vec<String> = pair
        .images()
        .filter_map(|(pass, image)| {
            let missing = (0..lines)
                .filter(|&k| {
                    let line = image.line(geometry.fast_axis(), k);
                    line.iter().all(|v| !v.is_finite())
                })
                .count();
            (missing > 0).then(|| format!("{pass}: {missing} of {lines} lines"))
        })
        .collect();
    (!counts.is_empty()).then(|| {
        Warning::new(
            WarningCode::MissingLines,
            format!(
                "whole lines hold no data ({}): not recorded (a scan stopped early) or missing \
                 in the file; the analysis uses the lines that were recorded",
                counts.join("; ")
            ),
            "nothing if the scan was stopped; the lattice, the model and the corrected images \
             cover the recorded lines only",
        )
    })
}

/// The scan timing or pixel size that the file did not state.
pub(crate) fn assumption_warnings(geometry: &ScanGeometry) -> Vec<Warning> {
    let mut warnings = Vec::new();
    if geometry.timing_source() != ValueSource::Stated {
        warnings.push(
            Warning::new(
                WarningCode::AssumedTiming,
                format!(
                    "the file does not state all of the scan timing (its pixel period, \
                 turnaround or a scan direction was assumed, as the file's notes say; {:.4} ms \
                 per pixel used): drift velocities, accelerations and times are in assumed \
                 units (the correction itself does not depend on them)",
                    geometry.pixel_period() * 1e3
                ),
                "give the real line time or pixel period",
            )
            .with_inputs(&[UserInput::LineTime, UserInput::PixelPeriod]),
        );
    }
    if geometry.scale_source() != ValueSource::Stated {
        warnings.push(
            Warning::new(
                WarningCode::AssumedPixelSize,
                "the pixel size was not read from the file but assumed".into(),
                "give the pixel size, or rely on the lattice (see the calibration)",
            )
            .with_inputs(&[UserInput::PixelSize]),
        );
    }
    warnings
}

/// Weak spots of the model fit: parameters at bounds, degenerate pairs, uncertainties
/// larger than the values, implausible RDF fits.
pub(crate) fn fit_warnings(dhct: &DhctResult) -> Vec<Warning> {
    let model = &dhct.model;
    let mut warnings: Vec<Warning> = model
        .diagnostics
        .at_bounds
        .iter()
        .map(|b| {
            let unit = unit_of(&model.parameters, &b.parameter);
            Warning::new(
                WarningCode::ParameterAtBound,
                format!(
                    "{} = {} ended at a bound of its range [{}, {}]: the data do not \
                     determine it",
                    b.parameter,
                    si(b.value, unit),
                    si(b.range[0], unit),
                    si(b.range[1], unit)
                ),
                "treat the drift/creep split as unmeasured; a longer or second frame, or \
                 the real scan timing, constrains it",
            )
        })
        .collect();
    let pairs = &model.diagnostics.degenerate_pairs;
    if !pairs.is_empty() {
        warnings.push(Warning::new(
            WarningCode::DegenerateParameters,
            format!(
                "nearly degenerate parameter pairs (only their combinations are measured): {}",
                pairs
                    .iter()
                    .map(|p| format!("{}–{} ({:+.3})", p.first, p.second, p.correlation))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
            if pairs.iter().all(|p| drift_family(&p.first, &p.second)) {
                "expected and harmless on one frame: over a single frame a drift velocity, its \
                 acceleration and the creep look alike, and the correction uses only their \
                 combination; do not read them separately (a sequence of frames or a longer \
                 frame tells them apart)"
            } else {
                "do not interpret them separately; the correction uses only their combinations"
            },
        ));
    }
    warnings.extend(uncertain(&model.parameters));
    for pass in &dhct.passes {
        let fit = &pass.used_selection().rdf_fit;
        if !fit.is_plausible() {
            warnings.push(
                Warning::new(
                    WarningCode::ImplausibleRdf,
                    format!(
                        "{}: the RDF fit is degenerate (shell widths {}): the neighbour window \
                     stayed at the lattice's nominal spacing",
                        pass.pass,
                        fit.widths_m
                            .iter()
                            .map(|w| dhct_calibrate::length(*w))
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                    "check the lattice and its nearest-neighbour distance; mask defects and \
                 other domains",
                )
                .with_inputs(&[
                    UserInput::Lattice,
                    UserInput::NearestNeighbourDistance,
                    UserInput::Mask,
                ]),
            );
        }
    }
    warnings
}

/// The unit of the fitted parameter `name` (empty when it is not among `parameters`).
fn unit_of<'a>(parameters: &'a [Parameter], name: &str) -> &'a str {
    parameters
        .iter()
        .find(|p| p.name == name)
        .map_or("", |p| p.unit.as_str())
}

/// One warning for every parameter whose uncertainty exceeds its value or is undetermined.
fn uncertain(parameters: &[Parameter]) -> Option<Warning> {
    let listed: Vec<String> = parameters
        .iter()
        .filter(|p| !p.sigma.is_finite() || p.sigma > p.value.abs())
        .map(|p| {
            if p.sigma.is_finite() {
                format!(
                    "{} = {}",
                    p.name,
                    value_with_sigma(p.value, p.sigma, &p.unit)
                )
            } else {
                format!("{} = {} (undetermined)", p.name, si(p.value, &p.unit))
            }
        })
        .collect();
    (!listed.is_empty()).then(|| {
        Warning::new(
            WarningCode::UncertainParameter,
            format!(
                "parameters whose uncertainty exceeds their value or is undetermined by the \
                 data: {}",
                listed.join(", ")
            ),
            "read them as consistent with zero; they still enter the correction",
        )
    })
}

/// The drift model could not be fitted (`reason`): the global affine correction stands in.
pub(crate) fn model_failure_warning(reason: String) -> Warning {
    Warning::new(
        WarningCode::ModelNotFitted,
        format!(
            "the drift/creep/hysteresis model could not be fitted ({reason}); the image was \
             corrected by the global affine map measured from its lattice (no time-dependent \
             distortion removed)"
        ),
        "take lengths from the corrected image, not drift values; a larger frame (more \
         cells) or a mask over the atomically resolved part lets the model be fitted",
    )
}

/// The full model against the global affine correction.
pub(crate) fn affine_warnings(comparisons: &[AffineComparison], fell_back: bool) -> Vec<Warning> {
    comparisons
        .iter()
        .filter(|c| c.model_is_worse())
        .map(|c| {
            Warning::new(
                WarningCode::WorseThanAffine,
                format!(
                    "region {}: the drift/creep/hysteresis model does worse than a global \
                     affine correction (rms {:.1} pm on {} features vs {:.1} pm on {}, lattice \
                     scales {:.4} × {:.4} vs {:.4} × {:.4}){}",
                    c.region,
                    c.model_rms_m * 1e12,
                    c.model_used,
                    c.affine_rms_m * 1e12,
                    c.affine_used,
                    c.model_scale[0],
                    c.model_scale[1],
                    c.affine_scale[0],
                    c.affine_scale[1],
                    if fell_back {
                        ": the affine correction was kept"
                    } else {
                        ""
                    }
                ),
                "the model does not describe this scan: use the affine result, mask defects \
                 and steps, or diagnose the gap to see what is missing",
            )
            .suggesting_diagnosis()
        })
        .collect()
}

/// Whether two parameters are drift terms of one axis, or one of them and the creep's
/// `t0`: their near-degeneracy is the nature of a single frame, not a fault.
fn drift_family(a: &str, b: &str) -> bool {
    let axis = |p: &str| match p {
        "v_x" | "a_x" | "C_x" => Some('x'),
        "v_y" | "a_y" | "C_y" => Some('y'),
        "t0" => Some('t'),
        _ => None,
    };
    match (axis(a), axis(b)) {
        (Some(x), Some(y)) => x == y || x == 't' || y == 't',
        _ => false,
    }
}

/// "`what`: its lattice, measured by FFT, is … (more than 1.5 % or 1° off)": the message of
/// a corrected (or registered) image whose FFT check `check` failed against `lattice`.
pub fn image_off_message(what: &str, check: &CorrectedImageCheck, lattice: &dyn Lattice) -> String {
    format!(
        "{what}: its lattice, measured by FFT, is {} (more than {:.1} % or {:.0}° off)",
        check.describe(lattice),
        100.0 * CORRECTED_SCALE_TOLERANCE,
        CORRECTED_ANGLE_TOLERANCE_DEG
    )
}

/// "`what`: its lattice could not be measured by FFT …": the message of a corrected (or
/// registered) image that could not be checked although the raw image could.
pub fn image_unchecked_message(what: &str) -> String {
    format!(
        "{what}: its lattice could not be measured by FFT (the raw image's could), so the \
         correction is not checked against the image"
    )
}

/// Corrected images whose lattice, measured by FFT, is not the lattice given.
pub(crate) fn corrected_image_warnings(
    lattice: &dyn Lattice,
    checks: &[CorrectedImageCheck],
) -> Vec<Warning> {
    checks
        .iter()
        .filter(|c| !c.passes())
        .map(|c| {
            Warning::new(
                WarningCode::CorrectedImageOff,
                image_off_message(&format!("corrected {}", c.pass), c, lattice),
                "do not take lengths from this image: check the scan timing and directions, \
                 mask steps and defects, or use the other pass",
            )
            .with_inputs(&[
                UserInput::LineTime,
                UserInput::Turnaround,
                UserInput::ScanDirections,
                UserInput::Mask,
            ])
        })
        .collect()
}

/// Corrected images of `passes` whose lattice could not be measured by FFT although the raw
/// images' was (`measured`): their correction is not checked against the image.
pub(crate) fn unchecked_image_warnings(
    measured: bool,
    passes: &[ScanPass],
    checks: &[CorrectedImageCheck],
) -> Vec<Warning> {
    if !measured {
        return Vec::new();
    }
    passes
        .iter()
        .filter(|&&pass| checks.iter().all(|c| c.pass != pass))
        .map(|pass| {
            Warning::new(
                WarningCode::CorrectedImageUnchecked,
                image_unchecked_message(&format!("corrected {pass}")),
                "check lengths in this image against a known feature before taking them; \
                 a mask over the atomically resolved area, without defects and steps, helps \
                 the measurement",
            )
            .with_inputs(&[UserInput::Mask])
        })
        .collect()
}

/// The drift model's corrected images that failed the FFT check, when the affine
/// correction was kept for that reason.
pub(crate) fn model_image_warnings(
    lattice: &dyn Lattice,
    rejected: &[CorrectedImageCheck],
) -> Vec<Warning> {
    rejected
        .iter()
        .filter(|c| !c.passes())
        .map(|c| {
            Warning::new(
                WarningCode::ModelImageOff,
                format!(
                    "the drift/creep/hysteresis model fitted the features, but the lattice of \
                     its corrected {}, measured by FFT, is {}: the global affine correction, \
                     whose images did better, was kept",
                    c.pass,
                    c.describe(lattice)
                ),
                "take lengths from the corrected images, not drift values; a mask over the \
                 whole atomically resolved area, or a diagnosis of the gap, shows where the \
                 model fails",
            )
            .with_inputs(&[UserInput::Mask])
            .suggesting_diagnosis()
        })
        .collect()
}

/// Results that look wrong although every stage succeeded.
pub(crate) fn plausibility_warnings(
    lattice: &dyn Lattice,
    regions: &[RegionFit],
    passes: &[PassOutput],
) -> Vec<Warning> {
    let mut warnings = Vec::new();
    for r in regions {
        warnings.extend(scale_warning(lattice, r));
        warnings.extend(offset_warning(lattice, r));
        warnings.extend(deviation_warning(r, passes));
    }
    for p in passes {
        let total = p.features.features.len();
        let indexed = p.indices.iter().flatten().count();
        if total > 0 && (indexed as f64) < INDEXED_WARNING * total as f64 {
            warnings.push(Warning::new(
                WarningCode::FewIndexed,
                format!(
                    "{}: only {indexed} of {total} features were indexed by the lattice fit",
                    p.pass
                ),
                "use a mask to exclude steps, defects and other domains",
            ));
        }
    }
    warnings
}

fn scale_warning(lattice: &dyn Lattice, r: &RegionFit) -> Option<Warning> {
    let worst = r
        .fit
        .scale
        .iter()
        .map(|s| (s - 1.0).abs())
        .fold(0.0, f64::max);
    (worst > SCALE_WARNING).then(|| {
        Warning::new(
            WarningCode::LatticeScale,
            format!(
                "region {}: the corrected lattice is {:.1} % x {:.1} % of the nominal {} \
                 lattice (scales {:.4}, {:.4})",
                r.region,
                100.0 * r.fit.scale[0],
                100.0 * r.fit.scale[1],
                lattice.name(),
                r.fit.scale[0],
                r.fit.scale[1]
            ),
            "check the lattice constant and the drift model (a drift near the slow-scan \
             speed is not recoverable)",
        )
        .with_inputs(&[UserInput::NearestNeighbourDistance])
    })
}

fn offset_warning(lattice: &dyn Lattice, r: &RegionFit) -> Option<Warning> {
    let offset = r
        .fit
        .set_offsets_m
        .iter()
        .skip(1)
        .map(|o| o[0].hypot(o[1]))
        .fold(0.0, f64::max);
    (offset > 0.25 * lattice.nearest_neighbour_distance()).then(|| {
        Warning::new(
            WarningCode::TraceRetraceOffset,
            format!(
                "region {}: trace and retrace disagree by {:.1} pm after correction (more \
                 than a quarter of the NN distance)",
                r.region,
                offset * 1e12
            ),
            "check the turnaround time and the scan directions",
        )
        .with_inputs(&[UserInput::Turnaround, UserInput::ScanDirections])
    })
}

/// The corrected lattice should deviate from its fit about as much as the features' own
/// localisation uncertainty; far more means the model missed something.
fn deviation_warning(r: &RegionFit, passes: &[PassOutput]) -> Option<Warning> {
    let mut sigmas: Vec<f64> = Vec::new();
    for (k, members) in r.members.iter().enumerate() {
        let Some(pass) = passes.iter().find(|p| p.pass == r.passes[k]) else {
            continue;
        };
        let pitch = (pass.features.features.first())
            .map(|f| {
                if f.x_px != 0.0 {
                    f.x_m / f.x_px
                } else {
                    f64::NAN
                }
            })
            .unwrap_or(f64::NAN);
        sigmas.extend(members.iter().map(|&i| {
            let f = &pass.features.features[i];
            pitch.abs() * (0.5 * (f.x_sigma_px.powi(2) + f.y_sigma_px.powi(2))).sqrt()
        }));
    }
    sigmas.retain(|s| s.is_finite() && *s > 0.0);
    let localisation = dhct_numerics::robust::median(&mut sigmas)?;
    let ratio = r.whole_ellipse.sigma_major_m / localisation;
    (ratio > DEVIATION_WARNING).then(|| {
        Warning::new(
            WarningCode::LargeDeviation,
            format!(
                "region {}: features deviate {:.1} pm (1σ, major axis) from the fitted \
                 lattice, {ratio:.1}× their localisation uncertainty ({:.1} pm)",
                r.region,
                r.whole_ellipse.sigma_major_m * 1e12,
                localisation * 1e12
            ),
            "the drift model may not describe this scan, or the surface is not the lattice \
             given: diagnose the gap",
        )
        .suggesting_diagnosis()
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use dhct_distortion::{
        Bound, DegeneratePair, DistortionModel, DriftCreep, FitDiagnostics, HysteresisLaw,
    };
    use dhct_scan::ScanDirection;

    fn parameter(name: &str, value: f64, sigma: f64) -> Parameter {
        Parameter {
            name: name.into(),
            value,
            sigma,
            unit: "m/s".into(),
        }
    }

    fn codes(warnings: &[Warning]) -> Vec<WarningCode> {
        warnings.iter().map(|w| w.code).collect()
    }

    #[test]
    fn a_weak_fit_is_named_with_what_to_do() {
        let mut model = DistortionModel::new(DriftCreep::none(), HysteresisLaw::none());
        model.parameters = vec![
            parameter("v_x", 7.2e-8, 1e-10),
            parameter("C_x", -3.8e-3, f64::NAN),
            parameter("a_x", 1e-16, 5e-16),
        ];
        model.diagnostics = FitDiagnostics {
            degenerate_pairs: vec![DegeneratePair {
                first: "v_x".into(),
                second: "C_x".into(),
                correlation: -0.999,
            }],
            at_bounds: vec![Bound {
                parameter: "t0".into(),
                value: 52428.8,
                range: [0.01, 52428.8],
            }],
        };
        let warnings = fit_warnings(&DhctResult::of_model(model));
        assert_eq!(
            codes(&warnings),
            [
                WarningCode::ParameterAtBound,
                WarningCode::DegenerateParameters,
                WarningCode::UncertainParameter
            ]
        );
        assert!(warnings[1].message.contains("v_x–C_x"));
        // A drift/creep pair is the nature of one frame, and said so.
        assert!(warnings[1].what_to_do.contains("expected and harmless"));
        assert!(drift_family("v_y", "t0") && !drift_family("v_x", "k"));
        assert!(!drift_family("v_x", "v_y"));
        let listed = &warnings[2].message;
        assert!(listed.contains("C_x") && listed.contains("undetermined"));
        assert!(listed.contains("a_x") && !listed.contains("v_x"));
        assert!(warnings.iter().all(|w| !w.what_to_do.is_empty()));
        // Well determined parameters say nothing.
        assert!(uncertain(&[parameter("v_y", 1e-9, 1e-11)]).is_none());
    }

    #[test]
    fn an_assumed_timing_and_a_model_worse_than_affine_are_warnings() {
        let geometry = ScanGeometry::new(
            8,
            8,
            1e-10,
            1e-10,
            1e-3,
            ScanDirection::Right,
            ScanDirection::Down,
        )
        .unwrap()
        .with_timing_source(ValueSource::Assumed);
        let warnings = assumption_warnings(&geometry);
        assert_eq!(codes(&warnings), [WarningCode::AssumedTiming]);
        assert!(warnings[0].inputs.contains(&UserInput::LineTime));
        assert!(
            assumption_warnings(&geometry.clone().with_timing_source(ValueSource::Stated))
                .is_empty()
        );

        let comparison = AffineComparison {
            region: 0,
            model_rms_m: 43e-12,
            affine_rms_m: 42e-12,
            model_used: 600,
            affine_used: 610,
            model_scale: [0.999, 0.971],
            affine_scale: [0.997, 0.998],
        };
        assert!(comparison.model_is_worse());
        let warnings = affine_warnings(&[comparison], true);
        assert_eq!(codes(&warnings), [WarningCode::WorseThanAffine]);
        assert!(warnings[0].message.contains("affine correction was kept"));
        let better = AffineComparison {
            model_rms_m: 3e-12,
            model_scale: [1.0, 1.0],
            ..comparison
        };
        assert!(!better.model_is_worse());
        assert!(affine_warnings(&[better], false).is_empty());
    }

    #[test]
    fn a_corrected_image_that_could_not_be_measured_is_named_when_the_raw_one_was() {
        let checked = CorrectedImageCheck {
            pass: ScanPass::Trace,
            calibration: dhct_calibrate::Calibration::identity(),
            angle_error_deg: 0.0,
        };
        let both = [ScanPass::Trace, ScanPass::Retrace];
        let warnings = unchecked_image_warnings(true, &both, &[checked]);
        assert_eq!(codes(&warnings), [WarningCode::CorrectedImageUnchecked]);
        assert!(warnings[0].message.starts_with("corrected retrace:"));
        // Nothing to say when the raw images' lattice was not measured either (that has its
        // own warning), or when every corrected image was checked.
        assert!(unchecked_image_warnings(false, &both, &[]).is_empty());
        assert!(unchecked_image_warnings(true, &both[..1], &[checked]).is_empty());
    }

    #[test]
    fn a_lattice_that_cannot_be_measured_or_a_wrong_pixel_size_is_reported() {
        let warnings = calibration_warnings(&Err("no peak".into()));
        assert_eq!(codes(&warnings), [WarningCode::LatticeNotMeasured]);
        assert!(warnings[0].message.contains("no peak"));
    }

    #[test]
    fn lines_without_data_are_named() {
        let geometry = ScanGeometry::new(
            8,
            6,
            1e-10,
            1e-10,
            1e-3,
            ScanDirection::Right,
            ScanDirection::Up,
        )
        .unwrap();
        let mut z = ndarray::Array2::from_elem((6, 8), 1e-10);
        let trace = dhct_scan::ImageChannel::new("Z", "m", z.clone());
        let pair = ScanPair::new(geometry.clone(), trace, None).unwrap();
        assert!(missing_lines_warning(&pair).is_none());
        z.row_mut(0).fill(f64::NAN);
        z.row_mut(1).fill(f64::NAN);
        z[[2, 3]] = f64::NAN;
        let trace = dhct_scan::ImageChannel::new("Z", "m", z);
        let pair = ScanPair::new(geometry, trace, None).unwrap();
        let warning = missing_lines_warning(&pair).expect("two lines hold no data");
        assert_eq!(warning.code, WarningCode::MissingLines);
        assert!(
            warning.message.contains("trace: 2 of 6 lines"),
            "{}",
            warning.message
        );
    }
}
