//! Whether the lattice and constant given can be what the image shows.

use dhct_scan::Axis;
use serde::{Deserialize, Serialize};

use crate::{CalibrationError, LatticeMatch, LatticeMeasurement};

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
    /// Stop when the image's symmetry contradicts the lattice's (e.g. a square lattice on
    /// a hexagonal image). Off only for users who know better.
    pub check_lattice_type: bool,
    /// Largest anisotropy (ratio of principal stretches) a match may need. A hexagonal
    /// lattice becomes a square one at √3, so the default 1.7 keeps the two apart; a drift
    /// of 40 % of the slow-scan speed needs 1.67.
    pub max_anisotropy: f64,
    /// Largest power ratio between reflections that the lattice's symmetry makes
    /// equivalent (judged only where the strongest stands out of the background). Real
    /// images reach ~10 (tip shape, drift smearing the peaks); a square lattice read as
    /// hexagonal gives 10–1000 for features of σ = a/5 … a/3.
    pub max_shell_spread: f64,
}

impl Default for CheckOptions {
    fn default() -> Self {
        CheckOptions {
            pitch_tolerance: 0.15,
            check_lattice_type: true,
            max_anisotropy: 1.7,
            max_shell_spread: 30.0,
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
        in_range("pitch_tolerance", self.pitch_tolerance, 0.0, 100.0)?;
        in_range("max_anisotropy", self.max_anisotropy, 1.0, 100.0)?;
        in_range("max_shell_spread", self.max_shell_spread, 1.0, 1e12)
    }
}

/// The slow axis may be off by this factor more than the fast axis: a constant drift of
/// up to about the slow-scan speed stretches or squeezes it like a wrong pixel size.
pub const SLOW_AXIS_SLACK: f64 = 2.0;

/// A match with a moderate stretch and a moderate spread is still a contradiction when
/// both point the same way.
const COMBINED_ANISOTROPY: f64 = 1.4;
const COMBINED_SPREAD: f64 = 3.0;

/// Checks `matched` (from `measurement`) against the options: the lattice's symmetry,
/// then its size along the fast axis (`fast_axis`), where the pixel size is what it says
/// unless the file is wrong; the slow axis gets [`SLOW_AXIS_SLACK`].
pub fn check_inputs(
    measurement: &LatticeMeasurement,
    matched: &LatticeMatch,
    fast_axis: Axis,
    options: &CheckOptions,
) -> Result<(), CalibrationError> {
    let shows = measurement.lattice.describe();
    let calibration = &matched.calibration;
    if options.check_lattice_type {
        let worst = matched
            .shells
            .iter()
            .filter(|s| s.significant)
            .max_by(|a, b| a.spread.total_cmp(&b.spread));
        let spread = worst.map_or(1.0, |s| s.spread);
        let evidence = if calibration.anisotropy > options.max_anisotropy {
            Some(format!(
                "the image would have to be stretched {:.2}× more along one direction than \
                 along the other",
                calibration.anisotropy
            ))
        } else if spread > options.max_shell_spread
            || (spread > COMBINED_SPREAD && calibration.anisotropy > COMBINED_ANISOTROPY)
        {
            let shell = worst.expect("a spread above 1 comes from a shell");
            Some(format!(
                "reflections that are equivalent in the {} lattice ({}) differ {:.0}× in \
                 power in the image (signal-to-background {}), and the match needs a \
                 {:.2}× stretch",
                matched.lattice,
                indices(&shell.indices),
                spread,
                shell
                    .snr
                    .iter()
                    .map(|s| format!("{s:.0}"))
                    .collect::<Vec<_>>()
                    .join(" : "),
                calibration.anisotropy
            ))
        } else {
            None
        };
        if let Some(evidence) = evidence {
            return Err(CalibrationError::WrongLatticeType {
                shows,
                lattice: matched.lattice.clone(),
                evidence,
                measured: Box::new(measurement.lattice.clone()),
                best: Box::new(matched.clone()),
            });
        }
    }
    // The fast axis carries the pixel size: a slow drift stretches the slow axis as much
    // as a wrong pixel size would (one frame cannot tell them apart), so the slow axis only
    // has to stay within what a drift up to the slow-scan speed can do.
    let (fast, slow) = match fast_axis {
        Axis::Horizontal => (calibration.scale[0], calibration.scale[1]),
        Axis::Vertical => (calibration.scale[1], calibration.scale[0]),
    };
    let limit = 1.0 + options.pitch_tolerance;
    let slow_limit = SLOW_AXIS_SLACK * limit;
    let within = |k: f64, limit: f64| k <= limit && k >= 1.0 / limit;
    if !(within(fast, limit) && within(slow, slow_limit)) {
        let factor = if within(fast, limit) { slow } else { fast };
        let nn = matched.nn_in_file_m / calibration.mean_scale;
        return Err(CalibrationError::WrongScale {
            shows,
            lattice: matched.lattice.clone(),
            given_nn_m: nn,
            measured_nn_m: nn * factor,
            measured_nn_sigma_m: nn * calibration.scale_sigma[0].max(calibration.scale_sigma[1]),
            factor,
            tolerance: options.pitch_tolerance,
        });
    }
    Ok(())
}

fn indices(list: &[[i64; 2]]) -> String {
    list.iter()
        .map(|[h, k]| format!("({h},{k})"))
        .collect::<Vec<_>>()
        .join(", ")
}
