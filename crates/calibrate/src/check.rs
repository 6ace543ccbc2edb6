//! Whether the lattice and constant given can be what the image shows: the named lattice
//! is fitted within the physical bounds ([`crate::named_fit`]); the inputs are refused
//! only when no map inside them explains the image's strong peaks.

use dhct_lattice::Lattice;
use dhct_scan::Axis;
use serde::{Deserialize, Serialize};

use crate::named_fit::MapBounds;
use crate::{CalibrationError, LatticeMatch, LatticeMeasurement, match_lattice};

/// How strictly the inputs are checked against the image.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CheckOptions {
    /// Largest relative error of the file's pixel size along the fast axis accepted: the
    /// lattice's size in file units may differ from the one given by at most this fraction
    /// (either way) along the fast axis, and by [`SLOW_AXIS_SLACK`] times as much along the
    /// slow axis (where a drift looks the same). Default 0.15; a lattice preset
    /// whose constant is known (nothing typed) is typically given 0.75 (a
    /// factor 1.75: a head off by 40 % either way).
    pub pitch_tolerance: f64,
    /// Stop when the named lattice explains too little of the image's spectrum (less
    /// than [`crate::MIN_EXPLAINED_FRACTION`] of the strong peaks' amplitude), or when a
    /// strongly stretched match also has equivalent reflections of very unequal power.
    /// Off only for users who know better.
    pub check_lattice_type: bool,
    /// Largest anisotropy (ratio of principal stretches) a match may need. A hexagonal
    /// lattice becomes a square one at √3, so the default 1.7 keeps the two apart; a drift
    /// of 40 % of the slow-scan speed needs 1.67.
    pub max_anisotropy: f64,
    /// Largest shear of the slow axis a match may need, degrees (a fast drift of
    /// tan 25° ≈ 47 % of the slow-scan speed). Default 25.
    pub max_shear_deg: f64,
    /// Largest power ratio between reflections that the lattice's symmetry makes
    /// equivalent when the match also needs a stretch above [`STRETCHED_MATCH`] (a square
    /// lattice read on a drift-stretched hexagonal image gives 10–1000). Unequal power alone
    /// (a tip, drift, line jumps: 10–60× in real images) is reported, never refused.
    pub max_shell_spread: f64,
}

impl Default for CheckOptions {
    fn default() -> Self {
        CheckOptions {
            pitch_tolerance: 0.15,
            check_lattice_type: true,
            max_anisotropy: 1.7,
            max_shear_deg: 25.0,
            max_shell_spread: 10.0,
        }
    }
}

impl CheckOptions {
    /// Checks the ranges; the message names the key, the value and the range.
    pub fn validate(&self) -> Result<(), String> {
        let in_range = |name: &str, v: f64, lo: f64, hi: f64| {
            if v.is_finite() && v >= lo && v <= hi {
                Ok(())
            } else {
                Err(format!(
                    "calibration.{name} must be in {lo}..={hi}, got {v}"
                ))
            }
        };
        in_range(
            "pitch_tolerance",
            self.pitch_tolerance,
            0.0,
            MAX_PITCH_TOLERANCE,
        )?;
        in_range("max_anisotropy", self.max_anisotropy, 1.0, 100.0)?;
        in_range("max_shear_deg", self.max_shear_deg, 0.0, 80.0)?;
        in_range("max_shell_spread", self.max_shell_spread, 1.0, 1e12)
    }
}

/// The largest pixel-size tolerance a user may set. Beyond it (the command line's `--nn
/// auto`) the constant is unknown, and no reading of the image is preferred for the scale
/// it needs.
pub const MAX_PITCH_TOLERANCE: f64 = 100.0;

/// The slow axis may be off by this factor more than the fast axis: a constant drift of
/// up to about the slow-scan speed stretches or squeezes it like a wrong pixel size.
pub const SLOW_AXIS_SLACK: f64 = 2.0;

/// A match needing more stretch than this is a contradiction when equivalent reflections
/// also differ more than [`CheckOptions::max_shell_spread`] in power: a hexagonal image
/// read as square (or the reverse) needs √3 ≈ 1.73, or from about 1.55 when drift has
/// already stretched it the right way.
pub const STRETCHED_MATCH: f64 = 1.55;

impl CheckOptions {
    /// The bounds of the map from the lattice to the image that these options accept.
    pub fn bounds(&self, fast_axis: Axis) -> MapBounds {
        let limit = 1.0 + self.pitch_tolerance;
        let slow = SLOW_AXIS_SLACK * limit;
        MapBounds {
            max_anisotropy: self.max_anisotropy,
            max_shear_deg: self.max_shear_deg,
            fast_axis,
            fast_scale: [1.0 / limit, limit],
            slow_scale: [1.0 / slow, slow],
        }
    }
}

/// Fits `lattice` to the measured peaks within the options' bounds and checks the match:
/// the map must explain the image's strong peaks. A map within the default (typed-constant)
/// pixel-size tolerance that explains them is taken before a wider tolerance is searched.
/// When none inside the bounds does, the
/// error says why: a map outside the pixel-size tolerance would ([`CalibrationError::WrongScale`]),
/// or no plausible map does, naming the peaks left unexplained
/// ([`CalibrationError::WrongLatticeType`]).
pub fn check_inputs(
    measurement: &LatticeMeasurement,
    lattice: &dyn Lattice,
    fast_axis: Axis,
    options: &CheckOptions,
) -> Result<LatticeMatch, CalibrationError> {
    let accepted = |m: &LatticeMatch| {
        !options.check_lattice_type
            || (m.explains_image && type_contradiction(m, options).is_none())
    };
    // The reading that needs the smallest pixel-size correction comes first: where the
    // file's pixel size explains the image (the atoms under a commensurate superstructure),
    // a wider tolerance does not make the superstructure the lattice.
    let typed = CheckOptions::default().pitch_tolerance;
    if options.pitch_tolerance > typed && options.pitch_tolerance <= MAX_PITCH_TOLERANCE {
        let narrow = CheckOptions {
            pitch_tolerance: typed,
            ..*options
        };
        if let Some(matched) = match_lattice(measurement, lattice, &narrow.bounds(fast_axis))
            && accepted(&matched)
        {
            return Ok(matched);
        }
    }
    let bounds = options.bounds(fast_axis);
    let within = match_lattice(measurement, lattice, &bounds);
    if let Some(matched) = &within
        && accepted(matched)
    {
        return Ok(matched.clone());
    }
    let any_scale = match_lattice(measurement, lattice, &bounds.any_scale());
    if let Some(wide) = &any_scale
        && wide.explains_image
        && type_contradiction(wide, options).is_none()
    {
        let at_given = partial_fit_note(within.as_ref());
        return Err(wrong_scale(measurement, wide, fast_axis, options, at_given));
    }
    let best = within.or(any_scale);
    let evidence = match &best {
        None => format!(
            "no stretch up to {:.2}× with a shear up to {:.0}° puts its reflections on two \
             independent peaks of the image",
            options.max_anisotropy, options.max_shear_deg
        ),
        Some(m) => match type_contradiction(m, options) {
            Some(evidence) => evidence,
            None => unexplained_evidence(m),
        },
    };
    Err(CalibrationError::WrongLatticeType {
        shows: measurement.lattice.describe(),
        lattice: lattice.name().to_string(),
        evidence,
        measured: Box::new(measurement.lattice.clone()),
        best: best.map(Box::new),
    })
}

/// What the lattice explains at the constant given, when its strongest reflections are
/// there but a stronger pattern (a superstructure) leaves it below
/// [`crate::MIN_EXPLAINED_FRACTION`]; empty otherwise.
fn partial_fit_note(within: Option<&LatticeMatch>) -> String {
    let Some(m) = within.filter(|m| {
        m.primary_coverage >= crate::MIN_PRIMARY_COVERAGE
            && m.explained_fraction < crate::MIN_EXPLAINED_FRACTION
    }) else {
        return String::new();
    };
    let rest = if m.unexplained.is_empty() {
        String::new()
    } else {
        format!(
            " (the rest: {} peaks on none of its reflections, e.g. a superstructure)",
            m.unexplained.len()
        )
    };
    format!(
        "; at {} it explains only {:.0} % of the strong Fourier peaks' amplitude \
         (of those at its periods or shorter){rest}",
        crate::length(m.nn_in_file_m / m.calibration.mean_scale),
        100.0 * m.explained_fraction,
    )
}

/// Why a match explains too little: its explained fraction and the strong peaks it
/// leaves, with their periods and fractional indices.
fn unexplained_evidence(matched: &LatticeMatch) -> String {
    let peaks: Vec<String> = matched
        .unexplained
        .iter()
        .take(6)
        .map(|p| {
            format!(
                "{} period at {:.0}° ({:.0} % of the strongest power; index ({:.2}, {:.2}))",
                crate::length(p.period_m),
                p.frequency_per_m[1]
                    .atan2(p.frequency_per_m[0])
                    .to_degrees(),
                100.0 * p.relative_power,
                p.fractional_index[0],
                p.fractional_index[1]
            )
        })
        .collect();
    let missing = if matched.primary_coverage < crate::MIN_PRIMARY_COVERAGE {
        format!(
            "; only {:.0} % of the reflections it predicts strongest are in the image",
            100.0 * matched.primary_coverage
        )
    } else {
        String::new()
    };
    format!(
        "its best map (a {:.2}× stretch) explains {:.0} % of the strong Fourier peaks' \
         amplitude (of those at its periods or shorter){missing}; left unexplained: {}",
        matched.calibration.anisotropy,
        100.0 * matched.explained_fraction,
        if peaks.is_empty() {
            "no strong peak".to_string()
        } else {
            peaks.join("; ")
        }
    )
}

/// A strongly stretched match whose equivalent reflections also differ strongly in
/// power: the image's symmetry contradicts the lattice's.
fn type_contradiction(matched: &LatticeMatch, options: &CheckOptions) -> Option<String> {
    let calibration = &matched.calibration;
    if calibration.anisotropy <= STRETCHED_MATCH {
        return None;
    }
    let shell = matched
        .shells
        .iter()
        .filter(|s| s.significant)
        .max_by(|a, b| a.spread.total_cmp(&b.spread))?;
    (shell.spread > options.max_shell_spread).then(|| {
        format!(
            "the match needs a {:.2}× stretch, and reflections that are equivalent in the {} \
             lattice ({}) differ {:.0}× in power in the image (signal-to-background {})",
            calibration.anisotropy,
            matched.lattice,
            indices(&shell.indices),
            shell.spread,
            shell
                .snr
                .iter()
                .map(|s| format!("{s:.0}"))
                .collect::<Vec<_>>()
                .join(" : "),
        )
    })
}

/// The error for a lattice that explains the image only with a pixel size off by more
/// than the tolerance.
fn wrong_scale(
    measurement: &LatticeMeasurement,
    matched: &LatticeMatch,
    fast_axis: Axis,
    options: &CheckOptions,
    at_given: String,
) -> CalibrationError {
    let calibration = &matched.calibration;
    let (fast, slow) = match fast_axis {
        Axis::Horizontal => (calibration.scale[0], calibration.scale[1]),
        Axis::Vertical => (calibration.scale[1], calibration.scale[0]),
    };
    let limit = 1.0 + options.pitch_tolerance;
    let within = |k: f64, limit: f64| k <= limit && k >= 1.0 / limit;
    let factor = if within(fast, limit) { slow } else { fast };
    let nn = matched.nn_in_file_m / calibration.mean_scale;
    CalibrationError::WrongScale {
        shows: measurement.lattice.describe(),
        lattice: matched.lattice.clone(),
        given_nn_m: nn,
        measured_nn_m: nn * factor,
        measured_nn_sigma_m: nn * calibration.scale_sigma[0].max(calibration.scale_sigma[1]),
        factor,
        tolerance: options.pitch_tolerance,
        at_given,
    }
}

fn indices(list: &[[i64; 2]]) -> String {
    list.iter()
        .map(|[h, k]| format!("({h},{k})"))
        .collect::<Vec<_>>()
        .join(", ")
}
