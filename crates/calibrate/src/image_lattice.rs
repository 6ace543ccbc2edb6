//! What a lattice measurement finds: the lattice an image shows ([`ImageLattice`], in
//! file units with uncertainties), its shape, its indexed reflections, and the measurement
//! with the spectrum it came from.

use nalgebra::{Matrix2, Matrix4, Vector2};
use serde::{Deserialize, Serialize};

use crate::basis::propagate;
use crate::periodic_noise::PeriodicNoise;
use crate::spectrum::{Peak, PowerSpectrum};

/// The shape of a 2-D lattice, judged from its reduced cell (tolerances: 3 % in length
/// ratio, 2° in angle).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum LatticeShape {
    /// Equal lengths, 60° apart.
    Hexagonal,
    /// Equal lengths, 90° apart.
    Square,
    /// Unequal lengths, 90° apart.
    Rectangular,
    /// Equal lengths at another angle: the rhombic primitive cell of a centred rectangle.
    CentredRectangular,
    /// Unequal lengths at another angle.
    Oblique,
}

impl LatticeShape {
    pub(crate) fn of(lengths: [f64; 2], angle_deg: f64) -> LatticeShape {
        let equal = (lengths[0] - lengths[1]).abs() <= 0.03 * lengths[0].max(lengths[1]);
        let near = |target: f64| (angle_deg - target).abs() <= 2.0;
        match (equal, near(90.0), near(60.0)) {
            (true, true, _) => LatticeShape::Square,
            (true, _, true) => LatticeShape::Hexagonal,
            (false, true, _) => LatticeShape::Rectangular,
            (true, false, false) => LatticeShape::CentredRectangular,
            _ => LatticeShape::Oblique,
        }
    }

    /// In words: "a hexagonal", "a square", …
    pub fn describe(self) -> &'static str {
        match self {
            LatticeShape::Hexagonal => "a hexagonal",
            LatticeShape::Square => "a square",
            LatticeShape::Rectangular => "a rectangular",
            LatticeShape::CentredRectangular => "a centred-rectangular",
            LatticeShape::Oblique => "an oblique",
        }
    }
}

/// How far (degrees) from 60° a centred-rectangular cell is still described as a
/// stretched hexagonal one.
const NEAR_HEXAGONAL_DEG: f64 = 10.0;

/// One spectral peak indexed by the measured lattice.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Reflection {
    /// Index `(h, k)` in the measured reciprocal basis.
    pub index: [i64; 2],
    /// Spatial frequency `[x, y]`, cycles per metre in file units.
    pub frequency_per_m: [f64; 2],
    /// Power over the median power at its radius.
    pub snr: f64,
}

/// The lattice an image shows, in the file's units (its nominal pixel size).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ImageLattice {
    /// Reduced cell vectors `[a1, a2]`, metres, file frame (x right, y down), the angle
    /// between them in 60°–90°.
    pub vectors_m: [[f64; 2]; 2],
    /// `|a1|`, `|a2|`, metres.
    pub lengths_m: [f64; 2],
    /// 1σ of the lengths, metres.
    pub lengths_sigma_m: [f64; 2],
    /// Angle between `a1` and `a2`, degrees.
    pub angle_deg: f64,
    /// Its 1σ, degrees.
    pub angle_sigma_deg: f64,
    /// The shape of the reduced cell.
    pub shape: LatticeShape,
    /// The indexed peaks, strongest first.
    pub reflections: Vec<Reflection>,
    /// Fraction of the detected peaks' power that the lattice indexes.
    pub indexed_power_fraction: f64,
    /// Peaks detected (indexed or not).
    pub peaks: usize,
}

impl ImageLattice {
    /// "a hexagonal lattice with cell vectors 2.470 Å and 2.466 Å at 60.1° (± 0.2°) in
    /// file units". A centred-rectangular cell within 10° of 60° is named for what it most
    /// likely is, a hexagonal lattice that the scan (or a wrong pixel size) has stretched.
    pub fn describe(&self) -> String {
        let shape = if self.shape == LatticeShape::CentredRectangular
            && (self.angle_deg - 60.0).abs() <= NEAR_HEXAGONAL_DEG
        {
            "a stretched hexagonal (centred-rectangular)"
        } else {
            self.shape.describe()
        };
        format!(
            "{} lattice with cell vectors {} ± {} and {} ± {} at {:.1}° ± {:.1}° in file units",
            shape,
            length(self.lengths_m[0]),
            length(self.lengths_sigma_m[0]),
            length(self.lengths_m[1]),
            length(self.lengths_sigma_m[1]),
            self.angle_deg,
            self.angle_sigma_deg
        )
    }

    /// The real-space basis as a matrix (columns `a1`, `a2`), metres.
    pub fn matrix(&self) -> Matrix2<f64> {
        let [a1, a2] = self.vectors_m;
        Matrix2::new(a1[0], a2[0], a1[1], a2[1])
    }
}

/// A length in the unit a surface scientist reads it in (pm, Å, nm, µm).
pub fn length(metres: f64) -> String {
    let a = metres.abs();
    if !a.is_finite() {
        format!("{metres} m")
    } else if a < 1e-10 {
        format!("{:.2} pm", metres * 1e12)
    } else if a < 1e-9 {
        format!("{:.3} Å", metres * 1e10)
    } else if a < 1e-6 {
        format!("{:.3} nm", metres * 1e9)
    } else {
        format!("{:.3} µm", metres * 1e6)
    }
}

/// A measurement with the spectrum it came from (to look up predicted reflections).
#[derive(Debug, Clone)]
pub struct LatticeMeasurement {
    /// The lattice.
    pub lattice: ImageLattice,
    pub(crate) spectrum: PowerSpectrum,
    /// Bins → cycles per metre, per axis.
    pub(crate) bin_per_m: [f64; 2],
    /// The measured reciprocal basis (bins, reduced) and its covariance.
    pub(crate) reciprocal: Matrix2<f64>,
    pub(crate) covariance: Matrix4<f64>,
    /// Every peak detected (bins), strongest first, but those of periodic noise.
    pub(crate) peaks: Vec<Peak>,
    /// Periodic noise in time whose peaks were left out, strongest first.
    pub periodic_noise: Vec<PeriodicNoise>,
}

impl LatticeMeasurement {
    /// Power of the strongest detected peak.
    pub fn strongest_power(&self) -> f64 {
        self.peaks.first().map_or(0.0, |p| p.power)
    }

    /// The largest `|kx|`, `|ky|` of the spectrum, bins.
    pub(crate) fn spectrum_half(&self) -> [f64; 2] {
        [
            (self.spectrum.columns / 2) as f64,
            (self.spectrum.rows / 2) as f64,
        ]
    }

    /// The peaks detected (frequencies in bins of the spectrum), strongest first.
    pub fn peaks(&self) -> &[Peak] {
        &self.peaks
    }

    /// Power and background (summed over 5 × 5 bins) at spatial frequency `g` (cycles per metre, file units).
    pub fn power_at(&self, g: Vector2<f64>) -> (f64, f64) {
        self.spectrum
            .power_near([g.x / self.bin_per_m[0], g.y / self.bin_per_m[1]])
    }

    /// The real-space basis (metres, columns) dual to the fitted reciprocal basis, before
    /// real-space reduction: the argument [`LatticeMeasurement::sigma_of`] perturbs.
    pub fn sigma_basis(&self) -> Matrix2<f64> {
        let to_per_m = Matrix2::from_diagonal(&Vector2::new(self.bin_per_m[0], self.bin_per_m[1]));
        real_basis(&(to_per_m * self.reciprocal)).unwrap_or_else(Matrix2::identity)
    }

    /// 1σ of `f(A)`, `A` the real-space basis (metres, columns) of the measured reciprocal
    /// basis (as measured, before real-space reduction).
    pub fn sigma_of(&self, f: impl Fn(&Matrix2<f64>) -> f64) -> f64 {
        let to_per_m = Matrix2::from_diagonal(&Vector2::new(self.bin_per_m[0], self.bin_per_m[1]));
        propagate(&self.reciprocal, &self.covariance, |b| {
            real_basis(&(to_per_m * b)).map_or(f64::NAN, |a| f(&a))
        })
    }
}

/// `A = B⁻ᵀ`: the real-space basis dual to reciprocal basis `B` (`aᵢ·bⱼ = δᵢⱼ`).
pub fn real_basis(reciprocal: &Matrix2<f64>) -> Option<Matrix2<f64>> {
    reciprocal.try_inverse().map(|b| b.transpose())
}
