//! Random height noise (effect 12) and the seeded random streams of the simulator.
//!
//! Every random number comes from a ChaCha8 generator seeded with the config's seed and set
//! to a stream that names what it is for, the pass and a row or line index. So
//! every row draws the same numbers whichever thread renders it, and the output is
//! bit-identical for any number of threads.
//!
//! * white noise: independent `N(0, σ_w)` per pixel;
//! * spikes: each pixel with probability `p` gets `±(0.5 … 1.5)·h`;
//! * line offsets: one `N(0, σ_l)` per scan line and pass;
//! * 1/f noise: a Voss–McCartney sum of octave generators run over the acquisition order
//!   (trace line 0, retrace line 0, trace line 1, …; turnaround gaps not counted), so the
//!   noise is correlated across lines and between trace and retrace as in a real
//!   acquisition; RMS `σ_p`.

use dhct_scan::{ScanGeometry, ScanPass};
use ndarray::Array2;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

use crate::config::NoiseConfig;

/// What a random stream is used for (part of its stream number).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Stream {
    /// Random adatom positions.
    Surface = 1,
    /// White noise and spikes of one row.
    Pixels = 2,
    /// Line offsets of one pass.
    LineOffsets = 3,
    /// The 1/f noise sequence.
    Pink = 4,
}

fn pass_index(pass: ScanPass) -> u64 {
    match pass {
        ScanPass::Trace => 0,
        ScanPass::Retrace => 1,
    }
}

/// The ChaCha8 generator for `(seed, purpose, pass, index)`.
pub(crate) fn stream_rng(seed: u64, purpose: Stream, pass: u64, index: u64) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(((purpose as u64) << 56) | (pass << 48) | (index & ((1 << 48) - 1)));
    rng
}

/// The noise of one simulation: config, seed and the precomputed correlated parts.
#[derive(Debug, Clone)]
pub(crate) struct NoiseModel {
    config: NoiseConfig,
    seed: u64,
}

/// Noise parts that span rows, precomputed per pass.
#[derive(Debug, Clone, Default)]
pub(crate) struct CorrelatedNoise {
    /// Offset of each scan line (indexed by slow index), metres.
    pub line_offsets: Vec<f64>,
    /// 1/f noise per pixel, display orientation, metres.
    pub pink: Option<Array2<f64>>,
}

impl NoiseModel {
    pub(crate) fn new(config: &NoiseConfig, seed: u64) -> NoiseModel {
        NoiseModel {
            config: config.clone(),
            seed,
        }
    }

    /// Line offsets and 1/f noise of both passes (trace, retrace).
    pub(crate) fn correlated(&self, geometry: &ScanGeometry) -> [CorrelatedNoise; 2] {
        let mut parts = [CorrelatedNoise::default(), CorrelatedNoise::default()];
        if self.config.line_offset_sigma_m > 0.0 {
            for pass in ScanPass::BOTH {
                let mut rng = stream_rng(self.seed, Stream::LineOffsets, pass_index(pass), 0);
                parts[pass_index(pass) as usize].line_offsets = (0..geometry.slow_len())
                    .map(|_| {
                        let n: f64 = StandardNormal.sample(&mut rng);
                        n * self.config.line_offset_sigma_m
                    })
                    .collect();
            }
        }
        if self.config.pink_sigma_m > 0.0 {
            let [trace, retrace] = self.pink(geometry);
            parts[0].pink = Some(trace);
            parts[1].pink = Some(retrace);
        }
        parts
    }

    /// Voss–McCartney 1/f noise over the acquisition order of both passes.
    fn pink(&self, geometry: &ScanGeometry) -> [Array2<f64>; 2] {
        let shape = (geometry.rows(), geometry.columns());
        let mut out = [Array2::zeros(shape), Array2::zeros(shape)];
        let total = 2 * geometry.rows() * geometry.columns();
        let octaves = (usize::BITS - total.leading_zeros()).clamp(1, 48) as usize;
        let sigma = self.config.pink_sigma_m / ((octaves + 1) as f64).sqrt();
        let mut rng = stream_rng(self.seed, Stream::Pink, 0, 0);
        let normal = |rng: &mut ChaCha8Rng| -> f64 {
            let n: f64 = StandardNormal.sample(rng);
            n * sigma
        };
        let mut generators: Vec<f64> = (0..octaves).map(|_| normal(&mut rng)).collect();
        let mut counter: u64 = 0;
        for line in 0..geometry.slow_len() {
            for pass in ScanPass::BOTH {
                let image = &mut out[pass_index(pass) as usize];
                for fast in 0..geometry.fast_len() {
                    counter += 1;
                    let octave = counter.trailing_zeros() as usize;
                    if octave < octaves {
                        generators[octave] = normal(&mut rng);
                    }
                    let value = generators.iter().sum::<f64>() + normal(&mut rng);
                    let (x, y) = geometry.position_of(pass, fast as f64, line as f64);
                    image[[y.round() as usize, x.round() as usize]] = value;
                }
            }
        }
        out
    }

    /// True if there is no per-pixel noise (white or spikes).
    fn pixel_noise_free(&self) -> bool {
        self.config.white_sigma_m == 0.0
            && (self.config.spike_probability == 0.0 || self.config.spike_height_m == 0.0)
    }

    /// Adds white noise, spikes, line offsets and 1/f noise to display row `row` of `pass`.
    pub(crate) fn add_to_row(
        &self,
        geometry: &ScanGeometry,
        pass: ScanPass,
        row: usize,
        z: &mut [f64],
        correlated: &CorrelatedNoise,
    ) {
        if !correlated.line_offsets.is_empty() {
            for (column, value) in z.iter_mut().enumerate() {
                let line = geometry.slow_index(column as f64, row as f64).round() as usize;
                *value += correlated.line_offsets[line];
            }
        }
        if let Some(pink) = &correlated.pink {
            for (value, noise) in z.iter_mut().zip(pink.row(row)) {
                *value += noise;
            }
        }
        if self.pixel_noise_free() {
            return;
        }
        let mut rng = stream_rng(self.seed, Stream::Pixels, pass_index(pass), row as u64);
        let white = self.config.white_sigma_m;
        let spikes = self.config.spike_probability > 0.0 && self.config.spike_height_m > 0.0;
        for value in z.iter_mut() {
            if white > 0.0 {
                let n: f64 = StandardNormal.sample(&mut rng);
                *value += white * n;
            }
            if spikes && rng.random::<f64>() < self.config.spike_probability {
                let magnitude = self.config.spike_height_m * (0.5 + rng.random::<f64>());
                *value += if rng.random::<bool>() {
                    magnitude
                } else {
                    -magnitude
                };
            }
        }
    }
}
