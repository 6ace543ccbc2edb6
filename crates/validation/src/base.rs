//! The base scan every validation case starts from: graphite with randomised drift,
//! acceleration, creep and fast-scan hysteresis, drawn from a seed; other fast-scan laws
//! ([`BaseLaw`]); and what the image-path sets add to the images ([`rendered_look`]).

use dhct_scan::ScanDirection;
use dhct_simulate::effects::{FastScanHysteresis, HysteresisLaw, LogCreep, ThermalDrift};
use dhct_simulate::{EffectConfig, Lobe, NoiseConfig, ScanConfig, SimulationConfig, presets};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

pub(crate) fn sign(rng: &mut ChaCha8Rng) -> f64 {
    if rng.random::<bool>() { 1.0 } else { -1.0 }
}

pub(crate) fn uniform(rng: &mut ChaCha8Rng, lo: f64, hi: f64) -> f64 {
    lo + (hi - lo) * rng.random::<f64>()
}

/// The base scan: graphite, 384 × 384 px over 6 nm, 50 nm/s (line 0.12 s, frame 92 s),
/// randomised drift (2–10 pm/s), acceleration, creep (C 0.05–0.3 nm, t0 10–40 s) and
/// hysteresis (`S = k·τ^n`, k 0.93–0.97, n −0.04…−0.02), random lattice angle.
pub fn base_config(seed: u64) -> SimulationConfig {
    let mut rng = ChaCha8Rng::seed_from_u64(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ 0xD1A6);
    let mut config = presets::ci_small();
    config.name = format!("validation-{seed}");
    config.seed = seed;
    config.scan = ScanConfig {
        columns: 384,
        rows: 384,
        width_m: 6e-9,
        height_m: 6e-9,
        fast_speed_m_per_s: 50e-9,
        turnaround_s: 0.0,
        trace_fast: ScanDirection::Right,
        slow: ScanDirection::Down,
        memory_limit_gib: None,
    };
    config.surface.angle_rad = uniform(&mut rng, 0.0, std::f64::consts::FRAC_PI_3);
    config.surface.origin_m = [uniform(&mut rng, 0.0, 2e-10), uniform(&mut rng, 0.0, 2e-10)];
    let mut v = || sign(&mut rng) * uniform(&mut rng, 2e-12, 10e-12);
    let velocity = [v(), v()];
    let acceleration = [
        sign(&mut rng) * uniform(&mut rng, 0.0, 2e-15),
        sign(&mut rng) * uniform(&mut rng, 0.0, 2e-15),
    ];
    let creep = [
        sign(&mut rng) * uniform(&mut rng, 0.05e-9, 0.3e-9),
        sign(&mut rng) * uniform(&mut rng, 0.05e-9, 0.3e-9),
    ];
    config.effects = vec![
        EffectConfig::ThermalDrift(ThermalDrift {
            velocity_m_per_s: velocity,
            acceleration_m_per_s2: acceleration,
        }),
        EffectConfig::Creep(LogCreep {
            coefficient_m: creep,
            t0_s: uniform(&mut rng, 10.0, 40.0),
            start_s: 0.0,
        }),
        EffectConfig::FastHysteresis(FastScanHysteresis {
            law: HysteresisLaw::Power {
                k: uniform(&mut rng, 0.93, 0.97),
                n: uniform(&mut rng, -0.04, -0.02),
            },
        }),
    ];
    config.noise = NoiseConfig {
        white_sigma_m: 2e-12,
        ..NoiseConfig::default()
    };
    config
}

/// A fast-scan hysteresis law other than dhct's default power law, for base models that
/// differ from the one dhct fits by default.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum BaseLaw {
    /// `S = k·τ^n` (as [`base_config`]).
    Power,
    /// `S = 1 + h0·(1 − τ/T)³`, `T` the line scan time, `h0` 3–8 %.
    Cubic,
    /// `S = 1 + h0·(1 − τ/T)⁴`, `h0` 3–8 %.
    Quartic,
    /// `S = 1 + A·exp(−τ/τ_h)`, `A` 3–8 %, `τ_h` 5–20 % of `T`.
    Exponential,
}

impl BaseLaw {
    /// The law of seed `seed` in the sets whose base is [`crate::BaseForm::LawBySeed`]
    /// (cubic, quartic, exponential, power in turn).
    pub fn of_seed(seed: u64) -> BaseLaw {
        [
            BaseLaw::Cubic,
            BaseLaw::Quartic,
            BaseLaw::Exponential,
            BaseLaw::Power,
        ][(seed % 4) as usize]
    }

    /// Every law.
    pub const ALL: [BaseLaw; 4] = [
        BaseLaw::Power,
        BaseLaw::Cubic,
        BaseLaw::Quartic,
        BaseLaw::Exponential,
    ];

    /// The law with its parameters drawn from `seed`, for a line scan time `line_s`.
    pub fn draw(self, seed: u64, line_s: f64) -> HysteresisLaw {
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x1A57);
        let h0 = uniform(&mut rng, 0.03, 0.08);
        let binomial = |n: i32| {
            let mut c = [0.0; 5];
            let mut b = 1.0;
            for (k, v) in c.iter_mut().enumerate().take(n as usize + 1) {
                *v = h0 * b * if k % 2 == 0 { 1.0 } else { -1.0 };
                b = b * (n - k as i32) as f64 / (k + 1) as f64;
            }
            HysteresisLaw::Quartic {
                coefficients: c,
                time_scale_s: line_s,
            }
        };
        match self {
            BaseLaw::Power => HysteresisLaw::Power {
                k: uniform(&mut rng, 0.93, 0.97),
                n: uniform(&mut rng, -0.04, -0.02),
            },
            BaseLaw::Cubic => binomial(3),
            BaseLaw::Quartic => binomial(4),
            BaseLaw::Exponential => HysteresisLaw::Exponential {
                amplitude: h0,
                time_constant_s: uniform(&mut rng, 0.05, 0.2) * line_s,
            },
        }
    }
}

/// [`base_config`] with its fast-scan hysteresis replaced by `law` (drawn from `seed`).
pub fn base_config_with_law(seed: u64, law: BaseLaw) -> SimulationConfig {
    let mut config = base_config(seed);
    let line_s = config.scan.width_m / config.scan.fast_speed_m_per_s;
    for e in &mut config.effects {
        if let EffectConfig::FastHysteresis(h) = e {
            h.law = law.draw(seed, line_s);
        }
    }
    config
}

/// What the image-path sets ([`crate::ScanForm::images`]) add to a scan so that its
/// images differ from the ones dhct's fits assume, drawn from `seed`: white pixel noise
/// 1.5–3 pm, 1/f noise over the acquisition 0.5–2 pm, an offset per scan line 2–8 pm, and
/// atoms that are not one round Gaussian (widths 1–1.2 × apart along a random axis, plus a
/// halo twice as wide of 15–30 % of the height).
pub fn rendered_look(config: &mut SimulationConfig, seed: u64) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ 0x100C);
    config.noise.white_sigma_m = uniform(&mut rng, 1.5e-12, 3e-12);
    config.noise.pink_sigma_m = uniform(&mut rng, 0.5e-12, 2e-12);
    config.noise.line_offset_sigma_m = uniform(&mut rng, 2e-12, 8e-12);
    let feature = &mut config.surface.feature;
    let sigma = feature.sigma_m[0];
    feature.sigma_m = [sigma * uniform(&mut rng, 1.0, 1.2), sigma];
    feature.angle_rad = uniform(&mut rng, 0.0, std::f64::consts::PI);
    feature.lobes = vec![
        Lobe {
            offset_m: [0.0, 0.0],
            relative_height: 1.0,
            sigma_m: None,
            angle_rad: None,
        },
        Lobe {
            offset_m: [0.0, 0.0],
            relative_height: uniform(&mut rng, 0.15, 0.3),
            sigma_m: Some([2.0 * feature.sigma_m[0], 2.0 * sigma]),
            angle_rad: None,
        },
    ];
}
