//! The lattice an STM image shows, measured from the image itself, before any feature is
//! found: the peaks of its power spectrum, for trace and retrace.
//!
//! The lattice the user named is fitted to the peaks' *positions* ([`match_lattice`]): the
//! affine map (x and y scale, shear, rotation, within physical bounds) under which its
//! predicted reflections land on the strong peaks gives the calibration of the file's frame
//! ([`Calibration`]) — the lattice is the internal standard, the file's pixel size may be
//! off by tens of percent and differently per axis. Peaks it does not predict (satellites,
//! a charge-density wave, a moiré) are reported, never made the cell; unequal power of
//! equivalent reflections is reported. The inputs are refused ([`check_inputs`]) only
//! when no plausible map explains the strong peaks: a square lattice on a hexagonal image,
//! a constant that would need the pixel size to be wrong by ×2. The global affine map
//! `K⁻¹` is also the floor that a full drift model must beat.
//!
//! ```
//! use dhct_calibrate::{CheckOptions, calibrate_pair};
//! use dhct_lattice::{Hexagonal, Square};
//! use dhct_scan::{ImageChannel, ScanDirection, ScanGeometry, ScanPair};
//! use ndarray::Array2;
//!
//! // A hexagonal lattice (a = 10 px) on a 128² image whose file says 1 Å per pixel, while
//! // the truth is 1.1 Å along x: the lattice looks 1/1.1 as long along x.
//! let geometry = ScanGeometry::new(128, 128, 1e-10, 1e-10, 1e-4,
//!                                  ScanDirection::Right, ScanDirection::Down).unwrap();
//! let z = Array2::from_shape_fn((128, 128), |(r, c)| {
//!     let (x, y) = (c as f64 * 1.1, r as f64);
//!     (0..3).map(|k| {
//!         let t = std::f64::consts::PI / 3.0 * k as f64 + std::f64::consts::FRAC_PI_2;
//!         let g = 2.0 * std::f64::consts::PI / (10.0 * 3f64.sqrt() / 2.0);
//!         (g * (x * t.cos() + y * t.sin())).cos()
//!     }).sum::<f64>()
//! });
//! let pair = ScanPair::new(geometry, ImageChannel::new("Z", "m", z), None).unwrap();
//! let lattice = Hexagonal::new("hexagonal", 1e-9, dhct_lattice::PlaneGroup::P6mm).unwrap();
//! let found = calibrate_pair(&pair, &lattice, None, &CheckOptions::default()).unwrap();
//! let c = found.calibration;
//! assert!((c.scale[0] - 1.0 / 1.1).abs() < 0.01 && (c.scale[1] - 1.0).abs() < 0.01);
//! // A square lattice cannot be what this image shows.
//! let square = Square::new(1e-9).unwrap();
//! assert!(calibrate_pair(&pair, &square, None, &CheckOptions::default()).is_err());
//! ```

mod basis;
mod check;
mod decompose;
mod error;
mod image_lattice;
mod matching;
mod measure;
mod named_fit;
mod periodic_noise;
mod spectrum;
mod structure;

pub use check::{CheckOptions, SLOW_AXIS_SLACK, STRETCHED_MATCH, check_inputs};
pub use error::CalibrationError;
pub use image_lattice::{ImageLattice, LatticeMeasurement, LatticeShape, Reflection, length};
pub use matching::{Calibration, LatticeMatch, ShellCheck, match_lattice};
pub use measure::{
    MAX_MEASURED_SIDE, MIN_BINNED_NN_PX, binning_factor, measure_lattice, measure_lattice_binned,
};
pub use named_fit::{
    MIN_EXPLAINED_FRACTION, MIN_PRIMARY_COVERAGE, MapBounds, STRONG_POWER_FRACTION, UnexplainedPeak,
};
pub use periodic_noise::PeriodicNoise;
pub use spectrum::{Peak, PowerSpectrum, SpectrumError};

use dhct_lattice::Lattice;
use dhct_scan::{ScanPair, ScanPass};
use ndarray::Array2;
use serde::{Deserialize, Serialize};

/// One image's lattice and its match.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PassCalibration {
    /// Trace or retrace.
    pub pass: ScanPass,
    /// What the image shows, in file units.
    pub lattice: ImageLattice,
    /// Matched to the lattice given.
    pub matched: LatticeMatch,
    /// Periodic noise in time the image shows, whose peaks were left out, strongest first.
    #[serde(default)]
    pub periodic_noise: Vec<PeriodicNoise>,
}

impl PassCalibration {
    /// In words, e.g. "periodic noise in time left out of the lattice's measurement:
    /// 100.3 Hz (32 peaks)"; empty when there is none.
    pub fn periodic_noise_note(&self) -> String {
        if self.periodic_noise.is_empty() {
            return String::new();
        }
        let each: Vec<String> = self
            .periodic_noise
            .iter()
            .map(|n| format!("{:.1} Hz ({} peaks)", n.frequency_hz, n.peaks))
            .collect();
        format!(
            "periodic noise in time left out of the lattice's measurement: {}",
            each.join(", ")
        )
    }
}

/// The calibration of a scan pair.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PairCalibration {
    /// Per image (the first image first; the retrace when its lattice could be measured
    /// and agrees with the inputs).
    pub passes: Vec<PassCalibration>,
    /// The images' calibrations combined (inverse-variance weighted).
    pub calibration: Calibration,
}

/// Measures the lattice of the trace (and retrace) of `pair` inside `mask`, matches it to
/// `lattice` and checks it against `options`. The trace (or the only image) decides: its
/// failure is the error; a retrace whose lattice cannot be measured is left out.
pub fn calibrate_pair(
    pair: &ScanPair,
    lattice: &dyn Lattice,
    mask: Option<&Array2<bool>>,
    options: &CheckOptions,
) -> Result<PairCalibration, CalibrationError> {
    let geometry = pair.geometry();
    let factor = binning_factor(geometry, lattice.nearest_neighbour_distance());
    let measure = |pass: ScanPass| {
        pair.image(pass)
            .map(|image| measure_lattice_binned(image.z.view(), geometry, mask, factor))
    };
    let (trace, retrace) = rayon::join(|| measure(ScanPass::Trace), || measure(ScanPass::Retrace));
    // The first image present decides (the trace, unless the scan has only a retrace): its
    // failure is the error; a second image whose lattice cannot be measured, or that
    // contradicts the first, is not used to calibrate.
    let mut measured = [(ScanPass::Trace, trace), (ScanPass::Retrace, retrace)]
        .into_iter()
        .filter_map(|(pass, m)| m.map(|m| (pass, m)));
    let (first_pass, first) = measured.next().ok_or_else(|| CalibrationError::NoLattice {
        reason: "the scan has no image".into(),
    })?;
    let first = first?;
    let fast = geometry.fast_axis();
    let matched = check_inputs(&first, lattice, fast, options)?;
    let mut passes = vec![PassCalibration {
        pass: first_pass,
        lattice: first.lattice,
        matched,
        periodic_noise: first.periodic_noise,
    }];
    for (pass, measurement) in measured {
        let Ok(measurement) = measurement else {
            continue;
        };
        if let Ok(matched) = check_inputs(&measurement, lattice, fast, options) {
            passes.push(PassCalibration {
                pass,
                lattice: measurement.lattice,
                matched,
                periodic_noise: measurement.periodic_noise,
            });
        }
    }
    let calibration = passes
        .iter()
        .map(|p| p.matched.calibration)
        .reduce(|a, b| a.combined(&b))
        .expect("the first image is always kept");
    Ok(PairCalibration {
        passes,
        calibration,
    })
}
