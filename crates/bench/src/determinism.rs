//! Bit-level fingerprints of a pipeline result, to check that the same input gives
//! bit-identical output whatever the number of threads.
//!
//! Each part is hashed separately (64-bit FNV-1a over the IEEE-754 bit patterns of every
//! number), so a mismatch says which stage diverged. Wall times are left out.

use dhct_pipeline::Analysis;
use rayon::ThreadPoolBuilder;
use serde::Serialize;

/// FNV-1a, 64 bit.
#[derive(Debug, Clone, Copy)]
struct Fnv(u64);

impl Fnv {
    fn new() -> Fnv {
        Fnv(0xcbf2_9ce4_8422_2325)
    }

    fn bytes(&mut self, bytes: &[u8]) {
        for b in bytes {
            self.0 ^= u64::from(*b);
            self.0 = self.0.wrapping_mul(0x0000_0100_0000_01b3);
        }
    }

    fn f64(&mut self, v: f64) {
        self.bytes(&v.to_bits().to_le_bytes());
    }

    fn u64(&mut self, v: u64) {
        self.bytes(&v.to_le_bytes());
    }
}

/// Hashes of each part of an [`Analysis`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct Fingerprint {
    /// Features found (both passes).
    pub feature_count: usize,
    /// Every feature's fitted parameters, uncertainties and times.
    pub features: u64,
    /// The model's parameter values and uncertainties.
    pub model: u64,
    /// Corrected feature positions.
    pub corrected_features: u64,
    /// Every pixel of the corrected images.
    pub corrected_images: u64,
    /// Lattice fits and every feature's index and deviation.
    pub lattice: u64,
    /// The averaged and symmetrised unit cell (0 when there is none).
    pub unit_cell: u64,
}

/// The fingerprint of `analysis`.
pub fn fingerprint(analysis: &Analysis) -> Fingerprint {
    let (mut features, mut corrected, mut images, mut lattice) =
        (Fnv::new(), Fnv::new(), Fnv::new(), Fnv::new());
    let mut count = 0;
    for pass in &analysis.passes {
        for f in &pass.features.features {
            count += 1;
            for v in [
                f.x_px,
                f.y_px,
                f.x_m,
                f.y_m,
                f.x_sigma_px,
                f.y_sigma_px,
                f.sigma_major_px,
                f.sigma_minor_px,
                f.theta_rad,
                f.amplitude,
                f.height,
                f.z0,
                f.residual_rms,
                f.ncc_peak,
                f.time_s,
                f.line_time_s,
            ] {
                features.f64(v);
            }
            features.u64(f.pixel_count as u64);
            features.u64(f.fit_iterations as u64);
        }
        for c in &pass.corrected {
            corrected.u64(c.index as u64);
            for v in [c.x_m, c.y_m, c.x_px, c.y_px] {
                corrected.f64(v);
            }
        }
        for v in pass.corrected_image.iter() {
            images.f64(*v);
        }
        for index in pass.indices.iter().flatten() {
            lattice.u64(index.region as u64);
            lattice.u64(index.n as u64);
            lattice.u64(index.m as u64);
            lattice.u64(index.site as u64);
            lattice.f64(index.deviation_m[0]);
            lattice.f64(index.deviation_m[1]);
        }
    }
    for region in &analysis.regions {
        let fit = &region.fit;
        for v in [
            fit.origin_m[0],
            fit.origin_m[1],
            fit.angle_rad,
            fit.scale[0],
            fit.scale[1],
            fit.rms_deviation_m,
        ] {
            lattice.f64(v);
        }
    }
    let mut model = Fnv::new();
    for p in &analysis.dhct.model.parameters {
        model.bytes(p.name.as_bytes());
        model.f64(p.value);
        model.f64(p.sigma);
    }
    let mut cell = Fnv::new();
    if let Some(u) = &analysis.unit_cell {
        cell.u64(u.cells_selected as u64);
        for v in u.averaged.values.iter().chain(u.symmetrized.values.iter()) {
            cell.f64(*v);
        }
    }
    Fingerprint {
        feature_count: count,
        features: features.0,
        model: model.0,
        corrected_features: corrected.0,
        corrected_images: images.0,
        lattice: lattice.0,
        unit_cell: if analysis.unit_cell.is_some() {
            cell.0
        } else {
            0
        },
    }
}

/// Runs `work` inside a rayon pool of `threads` worker threads and returns its result.
pub fn with_threads<T: Send>(threads: usize, work: impl FnOnce() -> T + Send) -> T {
    ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("a rayon thread pool builds")
        .install(work)
}
