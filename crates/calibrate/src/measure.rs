//! The lattice an image shows: two real-space cell vectors in file units with their
//! uncertainties, from the image's spectral peaks.

use dhct_scan::{Axis, ScanGeometry};
use nalgebra::{Matrix2, Vector2};
use ndarray::{Array2, ArrayView2};

use crate::CalibrationError;
use crate::basis::{FittedBasis, find_basis, reduce};
use crate::image_lattice::{
    ImageLattice, LatticeMeasurement, LatticeShape, Reflection, real_basis,
};
use crate::periodic_noise::{NoiseColumn, PeriodicNoise, periodic_noise};
use crate::spectrum::{Peak, PowerSpectrum};

/// Largest image side (pixels) measured at full resolution; larger images are binned.
pub const MAX_MEASURED_SIDE: usize = 1024;

/// Fewest pixels per expected nearest-neighbour distance kept when binning.
pub const MIN_BINNED_NN_PX: f64 = 5.0;

/// The binning factor (a power of 2) for measuring an image of `geometry` whose lattice has
/// its nearest neighbours `nn_m` metres apart: the image is shrunk to at most
/// [`MAX_MEASURED_SIDE`] px a side as long as the lattice keeps [`MIN_BINNED_NN_PX`] px
/// (the Fourier peaks then cost a sixteenth of the time at 2048² and lose no precision
/// that the seeds need).
pub fn binning_factor(geometry: &ScanGeometry, nn_m: f64) -> usize {
    let nn_px = nn_m / (geometry.pitch_x() * geometry.pitch_y()).sqrt();
    let side = geometry.columns().max(geometry.rows());
    let mut factor = 1;
    while side / factor > MAX_MEASURED_SIDE && nn_px / (2 * factor) as f64 >= MIN_BINNED_NN_PX {
        factor *= 2;
    }
    factor
}

/// [`measure_lattice`] on `z` averaged over `factor × factor` blocks (non-finite pixels
/// and pixels outside `mask` left out; a block with none left is left out).
pub fn measure_lattice_binned(
    z: ArrayView2<f64>,
    geometry: &ScanGeometry,
    mask: Option<&Array2<bool>>,
    factor: usize,
) -> Result<LatticeMeasurement, CalibrationError> {
    if factor <= 1 {
        return measure_lattice(z, geometry, mask);
    }
    let (rows, columns) = (z.nrows() / factor, z.ncols() / factor);
    let binned = Array2::from_shape_fn((rows, columns), |(r, c)| {
        let (mut sum, mut count) = (0.0, 0usize);
        for i in r * factor..(r + 1) * factor {
            for j in c * factor..(c + 1) * factor {
                let v = z[[i, j]];
                if v.is_finite() && mask.is_none_or(|m| m[[i, j]]) {
                    sum += v;
                    count += 1;
                }
            }
        }
        if count > 0 {
            sum / count as f64
        } else {
            f64::NAN
        }
    });
    let binned_geometry = geometry
        .binned(factor)
        .map_err(|_| CalibrationError::BadPitch {
            pitch_x: geometry.pitch_x(),
            pitch_y: geometry.pitch_y(),
        })?;
    measure_lattice(binned.view(), &binned_geometry, None)
}

/// Measures the lattice of `z` (rows × columns of `geometry`), optionally inside `mask`.
pub fn measure_lattice(
    z: ArrayView2<f64>,
    geometry: &ScanGeometry,
    mask: Option<&Array2<bool>>,
) -> Result<LatticeMeasurement, CalibrationError> {
    let (pitch_x, pitch_y) = (geometry.pitch_x(), geometry.pitch_y());
    if !(pitch_x.is_finite() && pitch_y.is_finite() && pitch_x > 0.0 && pitch_y > 0.0) {
        return Err(CalibrationError::BadPitch { pitch_x, pitch_y });
    }
    let spectrum = PowerSpectrum::of(z, mask, geometry.fast_axis())?;
    let mut peaks = spectrum.peaks();
    if peaks.len() < 2 {
        return Err(CalibrationError::NoLattice {
            reason: format!(
                "{} peak(s) stand out of the background (two independent ones are needed)",
                peaks.len()
            ),
        });
    }
    let fitted = find_basis(&peaks).ok_or_else(|| CalibrationError::NoLattice {
        reason: format!(
            "{} peaks stand out, but no two independent ones index the others",
            peaks.len()
        ),
    })?;
    let (
        FittedBasis {
            basis,
            covariance,
            indices,
            indexed_power,
        },
        noise,
    ) = without_periodic_noise(&mut peaks, fitted, geometry.fast_axis());
    let bin_per_m = [
        1.0 / (spectrum.columns as f64 * pitch_x),
        1.0 / (spectrum.rows as f64 * pitch_y),
    ];
    let to_per_m = Matrix2::from_diagonal(&Vector2::new(bin_per_m[0], bin_per_m[1]));
    let real = real_basis(&(to_per_m * basis)).ok_or_else(|| CalibrationError::NoLattice {
        reason: "the peaks are collinear".into(),
    })?;
    let cell = conventional(reduce(real));
    let mut reflections: Vec<Reflection> = peaks
        .iter()
        .zip(&indices)
        .filter_map(|(p, index)| {
            index.map(|index| Reflection {
                index,
                frequency_per_m: [p.k[0] * bin_per_m[0], p.k[1] * bin_per_m[1]],
                snr: p.snr,
            })
        })
        .collect();
    reflections.sort_by(|a, b| b.snr.total_cmp(&a.snr));
    let periodic_noise = noise
        .iter()
        .map(|column| periodic_noise_in_time(column, &spectrum, geometry))
        .collect();
    let mut measurement = LatticeMeasurement {
        lattice: ImageLattice {
            vectors_m: [[cell[(0, 0)], cell[(1, 0)]], [cell[(0, 1)], cell[(1, 1)]]],
            lengths_m: [cell.column(0).norm(), cell.column(1).norm()],
            lengths_sigma_m: [0.0; 2],
            angle_deg: angle_deg(&cell),
            angle_sigma_deg: 0.0,
            shape: LatticeShape::Oblique,
            reflections,
            indexed_power_fraction: indexed_power,
            peaks: peaks.len(),
        },
        spectrum,
        bin_per_m,
        reciprocal: basis,
        covariance,
        peaks,
        periodic_noise,
    };
    // Uncertainties of the reduced cell's lengths and angle: invariant quantities, so they
    // are computed from the conventional cell of each perturbed basis.
    let cell_of = |a: &Matrix2<f64>| conventional(reduce(*a));
    let lengths_sigma_m = [
        measurement.sigma_of(|a| cell_of(a).column(0).norm()),
        measurement.sigma_of(|a| cell_of(a).column(1).norm()),
    ];
    let angle_sigma_deg = measurement.sigma_of(|a| angle_deg(&cell_of(a)));
    let lattice = &mut measurement.lattice;
    lattice.lengths_sigma_m = lengths_sigma_m;
    lattice.angle_sigma_deg = angle_sigma_deg;
    lattice.shape = LatticeShape::of(lattice.lengths_m, lattice.angle_deg);
    Ok(measurement)
}

/// `peaks` without the periodic noise in time that `fitted` (the lattice found with it)
/// leaves unindexed, and the lattice found again without it (`fitted` itself when there is
/// none, or when nothing is found without it).
fn without_periodic_noise(
    peaks: &mut Vec<Peak>,
    fitted: FittedBasis,
    fast_axis: Axis,
) -> (FittedBasis, Vec<NoiseColumn>) {
    let (noise, in_noise) = periodic_noise(peaks, &fitted.indices, fast_axis);
    if noise.is_empty() {
        return (fitted, noise);
    }
    let kept: Vec<Peak> = peaks
        .iter()
        .zip(&in_noise)
        .filter(|(_, noise)| !**noise)
        .map(|(p, _)| *p)
        .collect();
    match (kept.len() >= 2).then(|| find_basis(&kept)).flatten() {
        Some(again) => {
            *peaks = kept;
            (again, noise)
        }
        None => (fitted, Vec::new()),
    }
}

/// A noise column of `spectrum` (the image's, of `geometry`) in time and along the fast
/// axis.
fn periodic_noise_in_time(
    column: &NoiseColumn,
    spectrum: &PowerSpectrum,
    geometry: &ScanGeometry,
) -> PeriodicNoise {
    let (padded, pitch) = match geometry.fast_axis() {
        Axis::Horizontal => (spectrum.columns, geometry.pitch_x()),
        Axis::Vertical => (spectrum.rows, geometry.pitch_y()),
    };
    let cycles_per_pixel = column.fast_bins / padded as f64;
    PeriodicNoise {
        frequency_hz: cycles_per_pixel / geometry.pixel_period(),
        period_m: pitch / cycles_per_pixel,
        peaks: column.peaks,
        relative_power: column.relative_power,
    }
}

/// Angle between the columns of `a`, degrees.
pub fn angle_deg(a: &Matrix2<f64>) -> f64 {
    let (u, v) = (a.column(0), a.column(1));
    (u.dot(&v) / (u.norm() * v.norm()))
        .clamp(-1.0, 1.0)
        .acos()
        .to_degrees()
}

/// A reduced basis with the angle between its vectors at most 90° (`a2` negated if not)
/// and `a1` the shorter.
pub fn conventional(reduced: Matrix2<f64>) -> Matrix2<f64> {
    let (u, mut v) = (
        reduced.column(0).into_owned(),
        reduced.column(1).into_owned(),
    );
    if u.dot(&v) < 0.0 {
        v = -v;
    }
    Matrix2::from_columns(&[u, v])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lattice(lengths_m: [f64; 2], angle_deg: f64) -> ImageLattice {
        ImageLattice {
            vectors_m: [[lengths_m[0], 0.0], [0.0, lengths_m[1]]],
            lengths_m,
            lengths_sigma_m: [1e-12; 2],
            angle_deg,
            angle_sigma_deg: 0.3,
            shape: LatticeShape::of(lengths_m, angle_deg),
            reflections: Vec::new(),
            indexed_power_fraction: 1.0,
            peaks: 6,
        }
    }

    #[test]
    fn a_faint_modulation_of_a_large_image_is_no_larger_cell() {
        // Hexagonal, a = 20 px, one set of rows exactly along the fast axis (its reflection
        // is in the scan-line band and is left out), modulated along y by 3e-4 in
        // amplitude (sidebands ~1e-8 of the strongest peak's power: far above a noise-free
        // background, far below any real superstructure).
        let (n, a_px, pitch) = (1024, 20.0, 1e-11);
        let k = 4.0 * std::f64::consts::PI / (3f64.sqrt() * a_px);
        let waves: Vec<[f64; 2]> = [90.0f64, 30.0, -30.0]
            .iter()
            .map(|d| [k * d.to_radians().cos(), k * d.to_radians().sin()])
            .collect();
        let z = Array2::from_shape_fn((n, n), |(r, c)| {
            let (x, y) = (c as f64, r as f64);
            let atoms: f64 = waves.iter().map(|w| (w[0] * x + w[1] * y).cos()).sum();
            let modulation = 1.0 + 3e-4 * (2.0 * std::f64::consts::PI * y / 164.0).cos();
            1e-11 * atoms * modulation
        });
        let geometry = ScanGeometry::new(
            n,
            n,
            pitch,
            pitch,
            1e-4,
            dhct_scan::ScanDirection::Right,
            dhct_scan::ScanDirection::Down,
        )
        .unwrap();
        let measured = measure_lattice(z.view(), &geometry, None).unwrap().lattice;
        let a_m = a_px * pitch;
        assert_eq!(measured.shape, LatticeShape::Hexagonal, "{measured:?}");
        for length in measured.lengths_m {
            assert!((length / a_m - 1.0).abs() < 0.002, "{measured:?}");
        }
    }

    /// A hexagonal lattice of `a_px` pixels with mains hum along the scan lines at
    /// `hum_cycles_per_px`, its phase wandering from line to line (a random walk).
    fn lattice_with_hum(n: usize, a_px: f64, hum_cycles_per_px: f64, hum: f64) -> Array2<f64> {
        let k = 4.0 * std::f64::consts::PI / (3f64.sqrt() * a_px);
        let waves: Vec<[f64; 2]> = [75.0f64, 15.0, -45.0]
            .iter()
            .map(|d| [k * d.to_radians().cos(), k * d.to_radians().sin()])
            .collect();
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut uniform = move || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut phase = 0.0;
        let phases: Vec<f64> = (0..n)
            .map(|_| {
                phase += 1.2 * (uniform() - 0.5);
                phase
            })
            .collect();
        Array2::from_shape_fn((n, n), |(r, c)| {
            let (x, y) = (c as f64, r as f64);
            let atoms: f64 = waves.iter().map(|w| (w[0] * x + w[1] * y).cos()).sum();
            let wave = (2.0 * std::f64::consts::PI * hum_cycles_per_px * x + phases[r]).cos();
            1e-11 * ((0.8 * atoms).exp() + hum * wave)
        })
    }

    #[test]
    fn mains_hum_along_the_lines_is_left_out_of_the_lattice() {
        let (n, a_px, pitch, pixel_period) = (512, 32.0, 1e-11, 3.9e-3);
        let z = lattice_with_hum(n, a_px, 0.358, 0.15);
        let geometry = ScanGeometry::new(
            n,
            n,
            pitch,
            pitch,
            pixel_period,
            dhct_scan::ScanDirection::Right,
            dhct_scan::ScanDirection::Down,
        )
        .unwrap();
        let measured = measure_lattice(z.view(), &geometry, None).unwrap();
        let lattice = &measured.lattice;
        let a_m = a_px * pitch;
        // With the hum's peaks in the fit: 0.33 % short and 0.085° off.
        for length in lattice.lengths_m {
            assert!((length / a_m - 1.0).abs() < 0.001, "{lattice:?}");
        }
        assert!((lattice.angle_deg - 60.0).abs() < 0.03, "{lattice:?}");
        let hum = measured.periodic_noise.first().expect("the hum is found");
        let hz = 0.358 / pixel_period;
        assert!(
            (hum.frequency_hz / hz - 1.0).abs() < 0.01,
            "{hum:?} against {hz} Hz"
        );
        assert!(hum.peaks >= 4, "{hum:?}");
    }

    #[test]
    fn a_stretched_hexagonal_lattice_is_named_as_one() {
        let stretched = lattice([5.09e-10, 5.18e-10], 64.2);
        assert_eq!(stretched.shape, LatticeShape::CentredRectangular);
        assert!(
            stretched.describe().starts_with("a stretched hexagonal"),
            "{}",
            stretched.describe()
        );
        let centred = lattice([5.0e-10, 5.0e-10], 75.0);
        assert!(centred.describe().starts_with("a centred-rectangular"));
        assert!(
            lattice([2.46e-10, 2.46e-10], 60.5)
                .describe()
                .starts_with("a hexagonal")
        );
    }
}
