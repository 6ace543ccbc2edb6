//! Position precision against the Cramér–Rao lower bound.
//!
//! Images are lattices of isolated 2-D Gaussians at known random sub-pixel positions plus
//! white noise, so the truth and the bound are exact: the CRLB of x0 is the (x0, x0) element
//! of the inverse Fisher matrix `(1/σ_n²) Σ ∇f ∇fᵀ` of the 7-parameter model, summed over
//! the pixels the fit uses (the disc of radius 0.4·NN around the feature).

use dhct_features::{Background, FeatureOptions, find_features};
use dhct_numerics::crlb::{GaussianSpot, centre_variance_x};
use dhct_scan::{ImageChannel, ScanDirection, ScanGeometry, ScanPass};
use ndarray::Array2;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

const SPACING_PX: f64 = 16.0;
const SIGMA_PX: f64 = 2.5;
const AMPLITUDE: f64 = 2e-11;
const PITCH: f64 = 1e-11;

struct Truth {
    x: f64,
    y: f64,
}

fn image_with_noise(seed: u64, noise: f64, size: usize) -> (ImageChannel, Vec<Truth>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let cells = (size as f64 / SPACING_PX) as usize;
    let truths: Vec<Truth> = (0..cells * cells)
        .map(|k| {
            let (i, j) = (k % cells, k / cells);
            Truth {
                x: (i as f64 + 0.5) * SPACING_PX + rng.random_range(-0.5..0.5),
                y: (j as f64 + 0.5) * SPACING_PX + rng.random_range(-0.5..0.5),
            }
        })
        .collect();
    let normal = Normal::new(0.0, noise).unwrap();
    let mut z = Array2::zeros((size, size));
    for ((r, c), value) in z.indexed_iter_mut() {
        // Only the own cell's Gaussian matters at this spacing (neighbours < 1e-8 A).
        let (i, j) = (
            (c as f64 / SPACING_PX) as usize,
            (r as f64 / SPACING_PX) as usize,
        );
        let mut sum = 0.0;
        for dj in -1i64..=1 {
            for di in -1i64..=1 {
                let (ii, jj) = (i as i64 + di, j as i64 + dj);
                if ii < 0 || jj < 0 || ii >= cells as i64 || jj >= cells as i64 {
                    continue;
                }
                let t = &truths[jj as usize * cells + ii as usize];
                let d2 = (c as f64 - t.x).powi(2) + (r as f64 - t.y).powi(2);
                sum += AMPLITUDE * (-d2 / (2.0 * SIGMA_PX * SIGMA_PX)).exp();
            }
        }
        *value = 1e-9 + sum + normal.sample(&mut rng);
    }
    (ImageChannel::new("Topography", "m", z), truths)
}

/// CRLB of x0 (px²) for the Gaussian at `truth` observed on the disc the fit uses
/// (radius 0.4·NN, the default `fit_radius_fraction`).
fn crlb_x(truth: &Truth, noise: f64) -> f64 {
    let spot = GaussianSpot {
        sigma_px: SIGMA_PX,
        amplitude: AMPLITUDE,
        noise,
        radius_px: 0.4 * SPACING_PX,
    };
    let offset = [truth.x - truth.x.round(), truth.y - truth.y.round()];
    centre_variance_x(&spot, offset).unwrap()
}

#[test]
fn position_error_is_within_1_2_times_the_cramer_rao_bound_at_every_snr() {
    let size = 256;
    let geometry = ScanGeometry::new(
        size,
        size,
        PITCH,
        PITCH,
        1e-4,
        ScanDirection::Right,
        ScanDirection::Down,
    )
    .unwrap();
    let options = FeatureOptions {
        background: Background::None,
        ..FeatureOptions::for_neighbour_distance(SPACING_PX * PITCH)
    };
    for snr in [5.0, 10.0, 20.0, 50.0] {
        let noise = AMPLITUDE / snr;
        let (mut sq_error, mut sum_error, mut bound, mut matched) = (0.0, [0.0, 0.0], 0.0, 0usize);
        for seed in 0..5 {
            let (image, truths) = image_with_noise(seed, noise, size);
            let set = find_features(&image, &geometry, ScanPass::Trace, &options, None).unwrap();
            for truth in &truths {
                let Some(found) = set
                    .features
                    .iter()
                    .find(|f| (f.x_px - truth.x).abs() < 2.0 && (f.y_px - truth.y).abs() < 2.0)
                else {
                    continue;
                };
                let (ex, ey) = (found.x_px - truth.x, found.y_px - truth.y);
                sq_error += 0.5 * (ex * ex + ey * ey);
                sum_error[0] += ex;
                sum_error[1] += ey;
                bound += crlb_x(truth, noise);
                matched += 1;
            }
        }
        let n = matched as f64;
        let rms = (sq_error / n).sqrt();
        let crlb = (bound / n).sqrt();
        let bias = [sum_error[0] / n, sum_error[1] / n];
        println!(
            "SNR {snr}: {matched} features, rms {rms:.4} px, CRLB {crlb:.4} px, ratio {:.3}, bias {bias:.4?}",
            rms / crlb
        );
        assert!(
            matched >= 5 * 14 * 14,
            "edge-cut aside, every feature must be found: {matched}"
        );
        assert!(
            rms <= 1.2 * crlb,
            "SNR {snr}: rms {rms} px > 1.2 x CRLB {crlb} px"
        );
        assert!(
            bias[0].abs() < 0.02 && bias[1].abs() < 0.02,
            "SNR {snr}: bias {bias:?}"
        );
    }
}
