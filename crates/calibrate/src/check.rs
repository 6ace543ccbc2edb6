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
    /// equivalent when the match also needs a stretch above [`STRETCHED_MATCH`] and a
    /// lattice of another shape fits with markedly less (a square lattice read on a
    /// drift-stretched hexagonal image gives 10–1000). Unequal power alone (a tip, drift,
    /// line jumps: 10–60× in real images) is reported, never refused.
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
/// also differ more than [`CheckOptions::max_shell_spread`] in power and a plain lattice
/// of another shape explains the image with at most this stretch: a hexagonal image read
/// as square (or the reverse) needs √3 ≈ 1.73, or from about 1.55 when drift has already
/// stretched it the right way.
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
    let contradiction = |m: &LatticeMatch| type_contradiction(m, measurement, fast_axis, options);
    let accepted = |m: &LatticeMatch| {
        !options.check_lattice_type || (m.explains_image && contradiction(m).is_none())
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
        && contradiction(wide).is_none()
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
        Some(m) => match contradiction(m) {
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
/// power, where a plain lattice of another shape explains the image without that stretch:
/// the image's symmetry contradicts the lattice's (a square lattice named on a
/// drift-stretched hexagonal image needs 1.55–1.7, the hexagonal lattice there far less).
/// Where no other shape does better, the stretch is the scan's (an uncalibrated head with
/// drift: 1.56–1.66 on ambient HOPG frames of a Nanosurf head whose one first-order pair is
/// weak), and the unequal power is reported, not refused.
fn type_contradiction(
    matched: &LatticeMatch,
    measurement: &LatticeMeasurement,
    fast_axis: Axis,
    options: &CheckOptions,
) -> Option<String> {
    let calibration = &matched.calibration;
    if calibration.anisotropy <= STRETCHED_MATCH {
        return None;
    }
    let shell = matched
        .shells
        .iter()
        .filter(|s| s.significant)
        .max_by(|a, b| a.spread.total_cmp(&b.spread))?;
    if shell.spread <= options.max_shell_spread {
        return None;
    }
    let other = better_shape(matched, measurement, &options.bounds(fast_axis).any_scale())?;
    Some(format!(
        "the match needs a {:.2}× stretch, and reflections that are equivalent in the {} \
         lattice ({}) differ {:.0}× in power in the image (signal-to-background {}), while \
         a {} lattice explains the image with a {:.2}× stretch",
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
        other.lattice,
        other.calibration.anisotropy,
    ))
}

/// How much less stretch another shape must need than the named lattice to contradict it.
const MARKEDLY_LESS_STRETCH: f64 = 1.2;

/// The plain hexagonal or square lattice (any constant) that explains the image with a
/// stretch of at most [`STRETCHED_MATCH`] and markedly less than `matched` needs, if one
/// does (the one needing least).
fn better_shape(
    matched: &LatticeMatch,
    measurement: &LatticeMeasurement,
    bounds: &MapBounds,
) -> Option<LatticeMatch> {
    let nn = matched.nn_in_file_m;
    let shapes: Vec<Box<dyn Lattice>> = [
        dhct_lattice::Hexagonal::new("hexagonal", nn, dhct_lattice::PlaneGroup::P6mm)
            .map(|l| Box::new(l) as Box<dyn Lattice>),
        dhct_lattice::Square::new(nn).map(|l| Box::new(l) as Box<dyn Lattice>),
    ]
    .into_iter()
    .flatten()
    .collect();
    let limit = STRETCHED_MATCH.min(matched.calibration.anisotropy / MARKEDLY_LESS_STRETCH);
    shapes
        .iter()
        .filter_map(|shape| match_lattice(measurement, shape.as_ref(), bounds))
        .filter(|m| m.explains_image && m.calibration.anisotropy <= limit)
        .min_by(|a, b| {
            a.calibration
                .anisotropy
                .total_cmp(&b.calibration.anisotropy)
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::measure_lattice;
    use dhct_lattice::{Hexagonal, PlaneGroup};
    use dhct_scan::{ScanDirection, ScanGeometry};
    use nalgebra::{Matrix2, Rotation2, Vector2};
    use ndarray::Array2;

    /// A hexagonal lattice (a = 2.46 Å) seen through `stretch` (file = stretch · sample)
    /// on 256² pixels of 20 pm: its three first-order waves (along −30°, 30° and 90°) at
    /// amplitudes `first`, and the second order weak.
    fn stretched_image(stretch: Matrix2<f64>, first: [f64; 3]) -> (Array2<f64>, ScanGeometry) {
        let (n, pitch, a) = (256, 2e-11, 2.46e-10);
        let k = 4.0 * std::f64::consts::PI / (3f64.sqrt() * a);
        let to_file = stretch.try_inverse().expect("invertible").transpose();
        let wave = |deg: f64, length: f64| {
            let t = deg.to_radians();
            to_file * Vector2::new(length * t.cos(), length * t.sin())
        };
        let mut waves: Vec<(Vector2<f64>, f64)> = [-30.0, 30.0, 90.0]
            .iter()
            .zip(first)
            .map(|(&d, amplitude)| (wave(d, k), amplitude))
            .collect();
        waves.extend([0.0, 60.0, 120.0].map(|d| (wave(d, k * 3f64.sqrt()), 0.1)));
        let z = Array2::from_shape_fn((n, n), |(r, c)| {
            let p = Vector2::new(c as f64 * pitch, r as f64 * pitch);
            waves
                .iter()
                .map(|(g, amp)| amp * g.dot(&p).cos())
                .sum::<f64>()
        });
        let geometry = ScanGeometry::new(
            n,
            n,
            pitch,
            pitch,
            1e-4,
            ScanDirection::Right,
            ScanDirection::Down,
        )
        .expect("a geometry");
        (z, geometry)
    }

    /// A stretch by `factor` along `deg` (degrees from x), lengths across kept.
    fn stretch_along(deg: f64, factor: f64) -> Matrix2<f64> {
        let r = Rotation2::new(deg.to_radians()).into_inner();
        r * Matrix2::new(factor, 0.0, 0.0, 1.0) * r.transpose()
    }

    fn checked(stretch: Matrix2<f64>) -> Result<LatticeMatch, CalibrationError> {
        // One first-order pair 4× weaker in amplitude (16× in power), as a tip or an
        // uncalibrated head with drift leave real HOPG frames.
        let (z, geometry) = stretched_image(stretch, [1.0, 1.0, 0.25]);
        let measured = measure_lattice(z.view(), &geometry, None).expect("a lattice");
        let graphite = Hexagonal::new("graphite", 2.46e-10, PlaneGroup::P3m1).expect("graphite");
        let options = CheckOptions {
            pitch_tolerance: 0.75,
            ..CheckOptions::default()
        };
        check_inputs(&measured, &graphite, Axis::Horizontal, &options)
    }

    /// A 1.6× stretch with one weak first-order pair is the scan's unless a lattice of
    /// another shape explains the image with markedly less (both stretches along an axis,
    /// so no shear): across the bisector of the two strong reflections no square lattice
    /// does, and graphite is fitted; along it, which opens them from 60° towards 90°, the
    /// square lattice needs about √3/1.6 and the image is refused, naming it.
    #[test]
    fn a_strong_stretch_with_unequal_power_is_refused_only_where_another_shape_fits_better() {
        let accepted = checked(stretch_along(90.0, 1.6)).expect("graphite fitted");
        assert!(
            (accepted.calibration.anisotropy - 1.6).abs() < 0.05,
            "{:?}",
            accepted.calibration
        );
        let refused = checked(stretch_along(0.0, 1.6)).expect_err("refused");
        let text = refused.to_string();
        assert!(text.contains("a square lattice explains"), "{text}");
    }
}
