//! The measured peaks against a known [`Lattice`]: the map under which the lattice's
//! reflections land on them ([`crate::named_fit`]), the calibration that map implies, the
//! peaks it leaves unexplained, and whether reflections that the lattice's symmetry makes
//! equivalent are equally strong in the image (reported, not judged here).
//!
//! The calibration is the upper-triangular `K` of `A = K·Q`, where `A` maps the lattice's
//! (sample-frame) basis onto the measured one (file frame) and `Q` is a rotation, the
//! lattice's orientation in the image, which no calibration removes:
//! `x_file = kx·x + kxy·y`, `y_file = ky·y`. So `kx` and `ky` are how much longer a length
//! along x and y looks in the file than it is, and `kxy/ky` is the shear of the slow axis
//! (what a constant drift along the fast axis, or non-orthogonal piezo axes, produce).
//! One frame cannot tell a pixel-size error along the slow axis from a constant slow drift,
//! nor a shear from a constant fast drift: they are reported as measured.

use dhct_lattice::Lattice;
use nalgebra::{Matrix2, Vector2};
use serde::{Deserialize, Serialize};

use crate::basis::propagate;
use crate::decompose::{rq, singular_values};
use crate::image_lattice::{LatticeMeasurement, real_basis};
use crate::named_fit::{MapBounds, NamedFit, SpectrumWindow, UnexplainedPeak, file_map, fit_named};

/// How the file's frame relates to the sample's, measured against a known lattice.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Calibration {
    /// `K = [[kx, kxy], [0, ky]]` (row-major): file metres per sample metres.
    pub matrix: [[f64; 2]; 2],
    /// `[kx, ky]`: apparent over true length along x and y (1 = the file's pixel size is
    /// right).
    pub scale: [f64; 2],
    /// 1σ of `scale`.
    pub scale_sigma: [f64; 2],
    /// Shear of the slow axis, `atan(kxy/ky)`, degrees.
    pub shear_deg: f64,
    /// 1σ of `shear_deg`.
    pub shear_sigma_deg: f64,
    /// `√(kx·ky)`: the mean scale (the factor by which the file's pixel size is off).
    pub mean_scale: f64,
    /// 1σ of `mean_scale`.
    pub mean_scale_sigma: f64,
    /// Ratio of the principal stretches of `A` (≥ 1): how far from a similarity the match
    /// is.
    pub anisotropy: f64,
    /// Orientation of the lattice in the image: the rotation `Q`, degrees.
    pub rotation_deg: f64,
}

impl Calibration {
    /// No calibration (the file's pixel size taken as right).
    pub fn identity() -> Calibration {
        Calibration {
            matrix: [[1.0, 0.0], [0.0, 1.0]],
            scale: [1.0; 2],
            scale_sigma: [0.0; 2],
            shear_deg: 0.0,
            shear_sigma_deg: 0.0,
            mean_scale: 1.0,
            mean_scale_sigma: 0.0,
            anisotropy: 1.0,
            rotation_deg: 0.0,
        }
    }

    /// `K⁻¹` (row-major): file metres → sample metres (lattice orientation kept).
    pub fn file_to_sample(&self) -> [[f64; 2]; 2] {
        let [[kx, kxy], [_, ky]] = self.matrix;
        [[1.0 / kx, -kxy / (kx * ky)], [0.0, 1.0 / ky]]
    }

    /// The inverse-variance weighted mean of two calibrations (e.g. trace and retrace).
    pub fn combined(&self, other: &Calibration) -> Calibration {
        let mean = |a: f64, sa: f64, b: f64, sb: f64| {
            let (wa, wb) = (weight(sa), weight(sb));
            ((a * wa + b * wb) / (wa + wb), (wa + wb).powf(-0.5))
        };
        let (kx, skx) = mean(
            self.scale[0],
            self.scale_sigma[0],
            other.scale[0],
            other.scale_sigma[0],
        );
        let (ky, sky) = mean(
            self.scale[1],
            self.scale_sigma[1],
            other.scale[1],
            other.scale_sigma[1],
        );
        let (shear, sshear) = mean(
            self.shear_deg,
            self.shear_sigma_deg,
            other.shear_deg,
            other.shear_sigma_deg,
        );
        let (mean_scale, smean) = mean(
            self.mean_scale,
            self.mean_scale_sigma,
            other.mean_scale,
            other.mean_scale_sigma,
        );
        Calibration {
            matrix: [[kx, ky * shear.to_radians().tan()], [0.0, ky]],
            scale: [kx, ky],
            scale_sigma: [skx, sky],
            shear_deg: shear,
            shear_sigma_deg: sshear,
            mean_scale,
            mean_scale_sigma: smean,
            anisotropy: 0.5 * (self.anisotropy + other.anisotropy),
            rotation_deg: self.rotation_deg,
        }
    }
}

fn weight(sigma: f64) -> f64 {
    // An unknown or zero uncertainty gets the weight of a 0.1 % one.
    let s = if sigma.is_finite() && sigma > 0.0 {
        sigma.max(1e-6)
    } else {
        1e-3
    };
    s.powi(-2)
}

/// The reflections of one shell of the lattice's reciprocal lattice (equal length, so
/// equivalent under its symmetry for a symmetric motif) and their power in the image.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ShellCheck {
    /// Spatial frequency of the shell in the lattice, cycles per metre.
    pub frequency_per_m: f64,
    /// Indices `(h, k)` in the lattice's basis (one of each ± pair).
    pub indices: Vec<[i64; 2]>,
    /// Power of each reflection over the background at its position.
    pub snr: Vec<f64>,
    /// Power of each reflection relative to the image's strongest peak.
    pub relative_power: Vec<f64>,
    /// Strongest over weakest power (the weakest floored at its background).
    pub spread: f64,
    /// Whether the strongest stands clearly out of the background (SNR ≥ 20) and is not
    /// mere window leakage of a stronger peak (≥ 10⁻³ of the strongest), so that the
    /// spread means something.
    pub significant: bool,
}

/// The measured lattice matched to a known one.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LatticeMatch {
    /// The lattice's name.
    pub lattice: String,
    /// `S`: the coarsest cell that indexes the image's peaks (measured without the named
    /// lattice) is `S` cells of the fitted lattice (row-major, rounded; the identity unless
    /// the image shows a superstructure of the lattice).
    pub supercell: [[i64; 2]; 2],
    /// The calibration.
    pub calibration: Calibration,
    /// The lattice's translation cell as the image shows it, in file units: vectors
    /// `[a1, a2]` (`[x, y]` each), metres, file frame.
    pub cell_in_file_m: [[f64; 2]; 2],
    /// The first reciprocal shells of the lattice and their powers in the image.
    pub shells: Vec<ShellCheck>,
    /// Fraction of the strong peaks' amplitude (√power) that lattice reflections explain,
    /// of the peaks at the lattice's periods or shorter (a strong peak at a longer period
    /// is a superstructure or moiré over it: in [`LatticeMatch::unexplained`], not counted
    /// against the lattice).
    pub explained_fraction: f64,
    /// Fraction of the reflections the lattice predicts strongest (those the spectrum can
    /// show) that are observed peaks.
    pub primary_coverage: f64,
    /// Whether the lattice explains the image: two independent strong peaks on its two
    /// strongest predicted shells, at least [`crate::MIN_EXPLAINED_FRACTION`] of the strong
    /// peaks' amplitude, and at least [`crate::MIN_PRIMARY_COVERAGE`] of its strongest
    /// predicted reflections seen in the spectrum.
    pub explains_image: bool,
    /// Strong peaks on no lattice reflection (satellites, a superstructure, a moiré),
    /// strongest first.
    pub unexplained: Vec<UnexplainedPeak>,
    /// The lattice's nearest-neighbour distance as the image shows it in file units
    /// (the lattice's times the mean scale), metres.
    pub nn_in_file_m: f64,
    /// Its 1σ, metres.
    pub nn_in_file_sigma_m: f64,
}

impl LatticeMatch {
    /// In words: how much of the image's strong Fourier peaks the lattice explains and the
    /// strongest it leaves, e.g. "the hexagonal lattice explains 55 % of the strong Fourier
    /// peaks' amplitude; 6 strong peaks lie on none of its reflections (a superstructure,
    /// satellites or a moiré; the strongest: 2.192 nm period, 41 % of the strongest power,
    /// index (-0.34, -0.66))".
    pub fn explanation(&self) -> String {
        let explained = format!(
            "the {} lattice explains {:.0} % of the strong Fourier peaks' amplitude \
             (of those at its periods or shorter)",
            self.lattice,
            100.0 * self.explained_fraction
        );
        match self.unexplained.first() {
            None => explained,
            Some(p) => format!(
                "{explained}; {} strong peak{} on none of its reflections (a superstructure, \
                 satellites or a moiré; the strongest: {} period, {:.0} % of the strongest \
                 power, index ({:.2}, {:.2}))",
                self.unexplained.len(),
                if self.unexplained.len() == 1 {
                    " lies"
                } else {
                    "s lie"
                },
                crate::length(p.period_m),
                100.0 * p.relative_power,
                p.fractional_index[0],
                p.fractional_index[1]
            ),
        }
    }
}

/// The lattice's translation cell as columns: what the image's spectrum shows (the
/// primitive cell of a centred lattice, not its conventional one).
fn lattice_matrix(lattice: &dyn Lattice) -> Matrix2<f64> {
    let [a1, a2] = lattice.translation_cell();
    Matrix2::from_columns(&[a1, a2])
}

/// Fits `lattice` to the measured peaks within `bounds` ([`crate::named_fit`]): the map
/// under which its predicted reflections best explain the peaks' positions, the
/// calibration it implies, the peaks it leaves unexplained and the power of its
/// equivalent reflections. `None` when no map inside the bounds puts lattice reflections
/// on two independent peaks.
pub fn match_lattice(
    measurement: &LatticeMeasurement,
    lattice: &dyn Lattice,
    bounds: &MapBounds,
) -> Option<LatticeMatch> {
    let peaks = measurement.peaks();
    let bin_per_m = measurement.bin_per_m;
    let contrast = |k: [f64; 2]| measurement.spectrum.contrast_near(k);
    let window = SpectrumWindow {
        half: measurement.spectrum_half(),
        fast_axis: bounds.fast_axis,
        contrast: &contrast,
    };
    let fit = fit_named(lattice, peaks, bin_per_m, &window, bounds)?;
    let ideal = lattice_matrix(lattice);
    let a = file_map(&fit.basis, bin_per_m, &ideal)?;
    let file_cell = a * ideal;
    let calibration = calibration_of(&a, &fit, bin_per_m, &ideal);
    let measured = measurement.lattice.matrix();
    let supercell = file_cell
        .try_inverse()
        .map(|inverse| (inverse * measured).map(f64::round))
        .unwrap_or_else(Matrix2::identity);
    let nn = lattice.nearest_neighbour_distance();
    Some(LatticeMatch {
        lattice: lattice.name().to_string(),
        supercell: [
            [supercell[(0, 0)] as i64, supercell[(0, 1)] as i64],
            [supercell[(1, 0)] as i64, supercell[(1, 1)] as i64],
        ],
        calibration,
        cell_in_file_m: [
            [file_cell[(0, 0)], file_cell[(1, 0)]],
            [file_cell[(0, 1)], file_cell[(1, 1)]],
        ],
        shells: shells(measurement, &file_cell, &ideal),
        explained_fraction: fit.explained_fraction,
        primary_coverage: fit.primary_coverage,
        explains_image: fit.explains_image(),
        unexplained: fit.unexplained(peaks, bin_per_m),
        nn_in_file_m: nn * calibration.mean_scale,
        nn_in_file_sigma_m: nn * calibration.mean_scale_sigma,
    })
}

/// The calibration `K` of the fitted map `a` = `A = K·Q`, with uncertainties propagated from the
/// fitted reciprocal basis' covariance.
fn calibration_of(
    a: &Matrix2<f64>,
    fit: &NamedFit,
    bin_per_m: [f64; 2],
    ideal: &Matrix2<f64>,
) -> Calibration {
    let (k, rotation) = rq(a);
    let (s1, s2) = singular_values(a);
    let k_of = |n: &Matrix2<f64>| {
        file_map(n, bin_per_m, ideal).map_or(Matrix2::from_element(f64::NAN), |a| rq(&a).0)
    };
    let sigma =
        |f: &dyn Fn(&Matrix2<f64>) -> f64| propagate(&fit.basis, &fit.covariance, |n| f(&k_of(n)));
    let shear = |k: &Matrix2<f64>| (k[(0, 1)] / k[(1, 1)]).atan().to_degrees();
    Calibration {
        matrix: [[k[(0, 0)], k[(0, 1)]], [0.0, k[(1, 1)]]],
        scale: [k[(0, 0)], k[(1, 1)]],
        scale_sigma: [sigma(&|k| k[(0, 0)]), sigma(&|k| k[(1, 1)])],
        shear_deg: shear(&k),
        shear_sigma_deg: sigma(&shear),
        mean_scale: (k[(0, 0)] * k[(1, 1)]).sqrt(),
        mean_scale_sigma: sigma(&|k| (k[(0, 0)] * k[(1, 1)]).sqrt()),
        anisotropy: s1 / s2,
        rotation_deg: rotation.to_degrees(),
    }
}

/// Frequency of index `(h, k)` of basis `cell` (columns), cycles per metre.
fn frequency(cell: &Matrix2<f64>, index: [i64; 2]) -> Option<Vector2<f64>> {
    let reciprocal = real_basis(cell)?;
    Some(reciprocal * Vector2::new(index[0] as f64, index[1] as f64))
}

/// The first two shells of the lattice (basis `target`) and the power in the image at the
/// measured position of each reflection (same index in the measured basis).
fn shells(
    measurement: &LatticeMeasurement,
    measured: &Matrix2<f64>,
    target: &Matrix2<f64>,
) -> Vec<ShellCheck> {
    let mut reflections: Vec<([i64; 2], f64)> = Vec::new();
    for h in -3i64..=3 {
        for k in -3i64..=3 {
            if (h > 0 || (h == 0 && k > 0))
                && let Some(g) = frequency(target, [h, k])
            {
                reflections.push(([h, k], g.norm()));
            }
        }
    }
    reflections.sort_by(|a, b| a.1.total_cmp(&b.1));
    let strongest = measurement.strongest_power().max(f64::MIN_POSITIVE);
    let mut result: Vec<ShellCheck> = Vec::new();
    // Per shell: (power, background) of each reflection.
    let mut powers: Vec<Vec<(f64, f64)>> = Vec::new();
    for (index, g) in reflections {
        let (power, background) = frequency(measured, index)
            .map(|g| measurement.power_at(g))
            .unwrap_or((0.0, 0.0));
        let snr = power / background.max(f64::MIN_POSITIVE);
        match result.last_mut() {
            Some(shell) if (g - shell.frequency_per_m).abs() <= 0.02 * g => {
                shell.indices.push(index);
                shell.snr.push(snr);
                shell.relative_power.push(power / strongest);
                powers
                    .last_mut()
                    .expect("one list per shell")
                    .push((power, background));
            }
            _ => {
                if result.len() == 2 {
                    break;
                }
                result.push(ShellCheck {
                    frequency_per_m: g,
                    indices: vec![index],
                    snr: vec![snr],
                    relative_power: vec![power / strongest],
                    spread: 1.0,
                    significant: false,
                });
                powers.push(vec![(power, background)]);
            }
        }
    }
    for (shell, powers) in result.iter_mut().zip(&powers) {
        let top = powers.iter().map(|p| p.0).fold(0.0, f64::max);
        let weakest = powers
            .iter()
            .map(|&(p, background)| p.max(background))
            .fold(f64::INFINITY, f64::min)
            .max(f64::MIN_POSITIVE);
        shell.spread = top / weakest;
        shell.significant =
            shell.snr.iter().copied().fold(0.0, f64::max) >= 20.0 && top >= 1e-3 * strongest;
    }
    result
}
