//! Simulated scans for validation: realistic base distortion (drift, acceleration, creep,
//! power-law fast hysteresis, randomised per seed) plus chosen extra effects.
//!
//! Two paths:
//! * [`simulate_positions`] (fast, used for the large sweep): the simulator's own
//!   displacement ([`dhct_simulate::raster::Displacer`]) and feature location
//!   ([`dhct_simulate::truth::locate`]) give every lattice site's true controller position
//!   in trace and retrace; Gaussian localisation noise of `noise_m` per axis is added and
//!   the acquisition time is taken at the noisy position, as the feature finder does.
//! * [`simulate_images`]: the full chain — rendered trace/retrace images with noise, then
//!   [`dhct_features::find_features_in_pair`].
//!
//! Vibration is simulated at 0.07–1.5 Hz (at least six cycles per frame); a faster one
//! moves the tip by more than a row
//! pitch between consecutive line pairs (0.24 s apart here), so the controller → sample
//! map folds along the slow axis, the simulator's feature location does not converge and
//! features are lost (a limitation of the continuous-time inversion, not of the diagnosis).

use dhct_features::{Feature, FeatureOptions, FeatureSet, FitStatus, find_features_in_pair};
use dhct_scan::{ScanDirection, ScanGeometry, ScanPair, ScanPass};
use dhct_simulate::effects::{
    AsymmetricHysteresis, ExponentialCreep, FastScanHysteresis, HeightCoupling, HysteresisLaw,
    LineDrift, LogCreep, PiezoNonlinearity, ScanCoupling, SlowScanHysteresis, StrainBubble,
    TelegraphTip, ThermalDrift, TipChange, Vibration,
};
use dhct_simulate::raster::Displacer;
use dhct_simulate::surface::Terrace;
use dhct_simulate::truth::locate;
use dhct_simulate::{
    Effect, EffectConfig, Lobe, NoiseConfig, ScanConfig, Simulation, SimulationConfig, StepEdge,
    presets,
};
use nalgebra::Vector2;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

use crate::{Candidate, DiagnoseError};

/// One validation scenario.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ValidationCase {
    /// Short name, e.g. `"tip-change #3"`.
    pub name: String,
    /// The withheld effects (empty = effect-free).
    pub truth: Vec<Candidate>,
    /// Effects outside the library in the scan (their right answer is "unexplained").
    #[serde(default)]
    pub foreign: Vec<ForeignEffect>,
    /// The simulation.
    pub config: SimulationConfig,
    /// Which validation set it belongs to.
    pub set: ValidationSet,
}

/// Effects outside the diagnosis's library.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ForeignEffect {
    /// A tip switching irregularly between two apexes.
    TelegraphTip,
    /// A local radial strain bubble.
    StrainBubble,
}

impl ForeignEffect {
    /// Both.
    pub const ALL: [ForeignEffect; 2] = [ForeignEffect::TelegraphTip, ForeignEffect::StrainBubble];

    /// Short name.
    pub fn name(self) -> &'static str {
        match self {
            ForeignEffect::TelegraphTip => "telegraph-tip",
            ForeignEffect::StrainBubble => "strain-bubble",
        }
    }
}

/// The validation sets (see [`crate::validate`] for the protocol).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ValidationSet {
    /// The method was developed on these: magnitudes 0.8–1.2 × nominal, vibration
    /// 0.3–1.2 Hz.
    Tuned,
    /// The first held-out set (magnitudes 0.6–0.8 or 1.2–1.6 ×, vibration 1.2–1.5 Hz). The
    /// method missed its targets there, and was then developed further with its cases in
    /// view, so it is development data now, reported but not evidence.
    Development,
    /// The second held-out set (magnitudes 0.6–0.75 or 1.25–1.5 ×, vibration 0.2–0.3 Hz):
    /// the method missed the identification target there too, was developed further with
    /// its cases in view, and it became development data as well.
    SecondDevelopment,
    /// The third held-out set (magnitudes 0.65–0.8 or 1.2–1.4 ×, vibration 0.1–0.2 Hz): the
    /// method met the targets there, then changed once more (for a case of the rendered-image
    /// path), so it is development data too.
    ThirdDevelopment,
    /// The fresh held-out set, fixed before it was first run and run once after the method
    /// was final: new seeds, magnitudes 0.7–0.8 or 1.2–1.35 ×, vibration 0.07–0.1 Hz (a
    /// band no other set has).
    HeldOut,
    /// The held-out set of issue 17, fixed before its first run: a base model that differs
    /// from dhct's default (fast-scan hysteresis law cubic, quartic, exponential or power by
    /// seed, see [`BaseLaw::of_seed`]), magnitudes 0.7–0.85 or 1.15–1.3 ×, vibration
    /// 0.4–0.6 Hz, and effects outside the library (telegraph tip, strain bubble) whose
    /// right answer is "unexplained".
    Foreign,
    /// Development cases of [`ValidationSet::SecondForeign`]'s forms (other fast-scan laws,
    /// correlated localisation noise, slow-scan hysteresis as a relaxation over 3–10 % of
    /// the frame): magnitudes 0.7–0.85 or 1.15–1.3 ×, vibration 0.6–0.9 Hz. Looked at while
    /// the method was checked on those forms, so not evidence.
    ForeignDevelopment,
    /// The second held-out set of issue 17, fixed before its first run: as
    /// [`ValidationSet::Foreign`] (other fast-scan laws, effects outside the library) plus
    /// localisation noise correlated in time within a pass ([`PositionNoise::of_set`]) and
    /// slow-scan hysteresis that relaxes over 3–10 % of the frame; magnitudes 0.7–0.8 or
    /// 1.2–1.3 ×, vibration 0.25–0.4 Hz.
    SecondForeign,
    /// Development cases of [`ValidationSet::Rendered`]'s forms: the base and effects of
    /// [`ValidationSet::SecondForeign`] rendered as images ([`rendered_look`]) and found
    /// by the feature finder; magnitudes 0.7–0.85 or 1.15–1.3 ×, vibration 0.5–0.7 Hz.
    RenderedDevelopment,
    /// Issue 17's held-out set on the image path, fixed before its first run: as
    /// [`ValidationSet::RenderedDevelopment`] with its own seeds, magnitudes 0.75–0.85 or
    /// 1.15–1.25 ×, vibration 0.3–0.45 Hz.
    Rendered,
    /// Issue 17's second held-out set on the image path, fixed (2026-11-27) after the
    /// first one was run and before any change made after that run: as
    /// [`ValidationSet::RenderedDevelopment`] with its own seeds, magnitudes 0.7–0.8 or
    /// 1.2–1.3 ×, vibration 0.8–1.0 Hz.
    SecondRendered,
    /// Issue 17's third held-out set on the image path, fixed (2026-11-27) after the second
    /// was run and the images below one feature joined the image-path validation, before
    /// its first run: as [`ValidationSet::RenderedDevelopment`] with its own seeds,
    /// magnitudes 0.75–0.85 or 1.15–1.3 ×, vibration 1.0–1.6 Hz (a band no image-path
    /// set has).
    ThirdRendered,
}

impl ValidationSet {
    /// Every set, in report order.
    pub const ALL: [ValidationSet; 12] = [
        ValidationSet::Tuned,
        ValidationSet::Development,
        ValidationSet::SecondDevelopment,
        ValidationSet::ThirdDevelopment,
        ValidationSet::HeldOut,
        ValidationSet::Foreign,
        ValidationSet::ForeignDevelopment,
        ValidationSet::SecondForeign,
        ValidationSet::RenderedDevelopment,
        ValidationSet::Rendered,
        ValidationSet::SecondRendered,
        ValidationSet::ThirdRendered,
    ];

    /// Short name.
    pub fn name(self) -> &'static str {
        match self {
            ValidationSet::Tuned => "tuned",
            ValidationSet::Development => "dev",
            ValidationSet::SecondDevelopment => "dev-2",
            ValidationSet::ThirdDevelopment => "dev-3",
            ValidationSet::HeldOut => "held-out",
            ValidationSet::Foreign => "foreign",
            ValidationSet::ForeignDevelopment => "foreign-dev",
            ValidationSet::SecondForeign => "foreign-2",
            ValidationSet::RenderedDevelopment => "rendered-dev",
            ValidationSet::Rendered => "rendered",
            ValidationSet::SecondRendered => "rendered-2",
            ValidationSet::ThirdRendered => "rendered-3",
        }
    }

    /// Whether the set's numbers are evidence (never looked at while the method changed).
    pub fn is_evidence(self) -> bool {
        matches!(
            self,
            ValidationSet::HeldOut
                | ValidationSet::Foreign
                | ValidationSet::SecondForeign
                | ValidationSet::Rendered
                | ValidationSet::SecondRendered
                | ValidationSet::ThirdRendered
        )
    }

    /// Whether the set's scans are rendered as images and found by the feature finder
    /// (else simulated as positions with localisation noise).
    pub fn renders_images(self) -> bool {
        matches!(
            self,
            ValidationSet::RenderedDevelopment
                | ValidationSet::Rendered
                | ValidationSet::SecondRendered
                | ValidationSet::ThirdRendered
        )
    }

    /// Whether slow-scan hysteresis relaxes over 3–10 % of the frame (else 1–3 %).
    fn has_long_slow_hysteresis(self) -> bool {
        matches!(
            self,
            ValidationSet::ForeignDevelopment
                | ValidationSet::SecondForeign
                | ValidationSet::RenderedDevelopment
                | ValidationSet::Rendered
                | ValidationSet::SecondRendered
                | ValidationSet::ThirdRendered
        )
    }

    /// Whether the set's base model differs from dhct's default (other fast-scan laws).
    pub fn has_foreign_base(self) -> bool {
        matches!(
            self,
            ValidationSet::Foreign
                | ValidationSet::ForeignDevelopment
                | ValidationSet::SecondForeign
                | ValidationSet::RenderedDevelopment
                | ValidationSet::Rendered
                | ValidationSet::SecondRendered
                | ValidationSet::ThirdRendered
        )
    }
}

fn sign(rng: &mut ChaCha8Rng) -> f64 {
    if rng.random::<bool>() { 1.0 } else { -1.0 }
}

fn uniform(rng: &mut ChaCha8Rng, lo: f64, hi: f64) -> f64 {
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
    /// The law of seed `seed` in the [`ValidationSet::Foreign`] set (cubic, quartic,
    /// exponential, power in turn).
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

/// What the image-path sets ([`ValidationSet::renders_images`]) add to a scan so that its
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

/// Magnitude factor of an effect (see [`ValidationSet`]).
fn magnitude(rng: &mut ChaCha8Rng, set: ValidationSet) -> f64 {
    // The tuned set draws one number, the others first draw which side of it they lie on.
    let (low, high) = match set {
        ValidationSet::Tuned => return uniform(rng, 0.8, 1.2),
        ValidationSet::Development => ((0.6, 0.8), (1.2, 1.6)),
        ValidationSet::SecondDevelopment => ((0.6, 0.75), (1.25, 1.5)),
        ValidationSet::ThirdDevelopment => ((0.65, 0.8), (1.2, 1.4)),
        ValidationSet::HeldOut => ((0.7, 0.8), (1.2, 1.35)),
        ValidationSet::Foreign
        | ValidationSet::ForeignDevelopment
        | ValidationSet::RenderedDevelopment => ((0.7, 0.85), (1.15, 1.3)),
        ValidationSet::SecondForeign => ((0.7, 0.8), (1.2, 1.3)),
        ValidationSet::Rendered => ((0.75, 0.85), (1.15, 1.25)),
        ValidationSet::SecondRendered => ((0.7, 0.8), (1.2, 1.3)),
        ValidationSet::ThirdRendered => ((0.75, 0.85), (1.15, 1.3)),
    };
    let (lo, hi) = if rng.random::<bool>() { low } else { high };
    uniform(rng, lo, hi)
}

/// Slow-scan hysteresis of magnitude factor `m` in a frame of `frame_s` seconds scanned at
/// `slow_speed` m/s along the slow axis. The first sets relax within 1–3 % of the frame,
/// i.e. mostly within the first row of features (their stretch excess is 0.6·`m`); the
/// sets with a foreign base from [`ValidationSet::ForeignDevelopment`] on relax over
/// 3–10 % of the frame (as the exponential creep: a transient that spans rows of features)
/// and move the slow axis by `m` × 40 pm in all (as the exponential creep's amplitude).
fn slow_hysteresis(
    rng: &mut ChaCha8Rng,
    m: f64,
    frame_s: f64,
    slow_speed: f64,
    set: ValidationSet,
) -> SlowScanHysteresis {
    let law = match set {
        _ if set.has_long_slow_hysteresis() => {
            let tau = uniform(rng, 0.03, 0.10) * frame_s;
            HysteresisLaw::Exponential {
                amplitude: m * 40e-12 / (slow_speed * tau),
                time_constant_s: tau,
            }
        }
        _ => HysteresisLaw::Exponential {
            amplitude: m * 0.6,
            time_constant_s: uniform(rng, 0.01, 0.03) * frame_s,
        },
    };
    SlowScanHysteresis { law }
}

/// Adds `candidate`'s effect to `config` (magnitudes from `rng`); `false` if it has no
/// simulator effect (higher-order drift, local strain).
fn add_effect(
    config: &mut SimulationConfig,
    candidate: Candidate,
    rng: &mut ChaCha8Rng,
    set: ValidationSet,
) -> bool {
    let m = magnitude(rng, set);
    let frame =
        2.0 * config.scan.rows as f64 * config.scan.width_m / config.scan.fast_speed_m_per_s;
    let base_law = config.effects.iter().find_map(|e| match e {
        EffectConfig::FastHysteresis(h) => Some(h.law.clone()),
        _ => None,
    });
    let effect = match candidate {
        Candidate::LineDrift => EffectConfig::LineDrift(LineDrift {
            velocity_m_per_s: [sign(rng) * m * 150e-12, sign(rng) * m * 100e-12],
        }),
        Candidate::ExponentialCreep => EffectConfig::ExponentialCreep(ExponentialCreep {
            amplitude_m: [sign(rng) * m * 40e-12, sign(rng) * m * 30e-12],
            time_constant_s: uniform(rng, 0.03, 0.13) * frame,
            start_s: uniform(rng, 0.2, 0.65) * frame,
        }),
        Candidate::SecondCreep => EffectConfig::Creep(LogCreep {
            coefficient_m: [sign(rng) * m * 15e-12, sign(rng) * m * 20e-12],
            t0_s: uniform(rng, 0.01, 0.04) * frame,
            start_s: uniform(rng, 0.2, 0.65) * frame,
        }),
        Candidate::AsymmetricHysteresis => {
            let retrace = match &base_law {
                Some(HysteresisLaw::Power { k, n }) => HysteresisLaw::Power {
                    k: k - m * 0.04,
                    n: n - m * 0.012,
                },
                // Other laws: the retrace's excess scale half as large again or half as
                // small (1.5–4 % of scale at the line start).
                Some(law) => {
                    let f = 1.0 + sign(rng) * 0.5 * m;
                    let p = law.parameters();
                    let scaled: Vec<f64> = match law {
                        HysteresisLaw::Exponential { .. } => vec![p[0] * f, p[1]],
                        _ => p.iter().map(|v| v * f).collect(),
                    };
                    let Some(l) = law.with_parameters(&scaled) else {
                        return false;
                    };
                    l
                }
                None => return false,
            };
            let Some(trace) = base_law else {
                return false;
            };
            config
                .effects
                .retain(|e| !matches!(e, EffectConfig::FastHysteresis(_)));
            EffectConfig::AsymmetricHysteresis(AsymmetricHysteresis { trace, retrace })
        }
        Candidate::SlowHysteresis => EffectConfig::SlowHysteresis(slow_hysteresis(
            rng,
            m,
            frame,
            config.scan.height_m / frame,
            set,
        )),
        Candidate::Vibration => EffectConfig::Vibration(Vibration {
            // Slow enough that the image stays one-to-one along the slow axis (faster
            // vibration folds it: see the module docs).
            frequency_hz: match set {
                ValidationSet::Tuned => uniform(rng, 0.3, 1.2),
                ValidationSet::Development => uniform(rng, 1.2, 1.5),
                ValidationSet::SecondDevelopment => uniform(rng, 0.2, 0.3),
                ValidationSet::ThirdDevelopment => uniform(rng, 0.1, 0.2),
                ValidationSet::HeldOut => uniform(rng, 0.07, 0.1),
                ValidationSet::Foreign => uniform(rng, 0.4, 0.6),
                ValidationSet::ForeignDevelopment => uniform(rng, 0.6, 0.9),
                ValidationSet::SecondForeign => uniform(rng, 0.25, 0.4),
                ValidationSet::RenderedDevelopment => uniform(rng, 0.5, 0.7),
                ValidationSet::Rendered => uniform(rng, 0.3, 0.45),
                ValidationSet::SecondRendered => uniform(rng, 0.8, 1.0),
                ValidationSet::ThirdRendered => uniform(rng, 1.0, 1.6),
            },
            amplitude_m: [m * 4e-12, m * 3e-12],
            phase_rad: [
                uniform(rng, 0.0, std::f64::consts::TAU),
                uniform(rng, 0.0, std::f64::consts::TAU),
            ],
        }),
        Candidate::TipChange => EffectConfig::TipChange(TipChange {
            time_s: uniform(rng, 0.15, 0.85) * frame,
            jump_m: [sign(rng) * m * 25e-12, sign(rng) * m * 20e-12],
            height_offset_m: 0.0,
            contrast: 1.0,
        }),
        Candidate::HeightCoupling => {
            let angle = uniform(rng, 0.0, std::f64::consts::TAU);
            let centre = [
                uniform(rng, 0.35, 0.65) * config.scan.width_m,
                uniform(rng, 0.35, 0.65) * config.scan.height_m,
            ];
            config.surface.steps.push(StepEdge {
                region: dhct_simulate::Region::HalfPlane {
                    point_m: centre,
                    normal: [angle.cos(), angle.sin()],
                },
                height_m: 3.35e-10,
            });
            EffectConfig::HeightCoupling(HeightCoupling {
                lateral_per_height: [sign(rng) * m * 0.06, sign(rng) * m * 0.04],
            })
        }
        Candidate::ScanCoupling => EffectConfig::ScanCoupling(ScanCoupling {
            slow_to_fast: sign(rng) * m * 0.01,
            fast_to_slow: sign(rng) * m * 0.01,
        }),
        // About 0.5 % of the 6 nm frame at its edges, quadratic and cubic in each axis.
        Candidate::PiezoNonlinearity => EffectConfig::PiezoNonlinearity(PiezoNonlinearity {
            quadratic_m: [sign(rng) * m * 30e-12, sign(rng) * m * 20e-12],
            cubic_m: [sign(rng) * m * 40e-12, sign(rng) * m * 25e-12],
        }),
        Candidate::HigherOrderDrift | Candidate::LocalStrain => return false,
    };
    config.effects.push(effect);
    true
}

impl ValidationCase {
    fn rng(seed: u64, salt: u64) -> ChaCha8Rng {
        ChaCha8Rng::seed_from_u64(seed.wrapping_mul(0x2545_F491_4F6C_DD1D) ^ salt)
    }

    /// The base scan with `effects` added.
    pub fn with_effects(effects: &[Candidate], seed: u64, set: ValidationSet) -> ValidationCase {
        let mut config = match set {
            _ if set.has_foreign_base() => base_config_with_law(seed, BaseLaw::of_seed(seed)),
            _ => base_config(seed),
        };
        if set.renders_images() {
            rendered_look(&mut config, seed);
        }
        let mut rng = Self::rng(seed, 0x5EED);
        let mut truth = Vec::new();
        for &c in effects {
            if add_effect(&mut config, c, &mut rng, set) {
                truth.push(c);
            }
        }
        let name = if truth.is_empty() {
            format!("none #{seed}")
        } else {
            format!(
                "{} #{seed}",
                truth.iter().map(|c| c.name()).collect::<Vec<_>>().join("+")
            )
        };
        config.name = name.clone();
        ValidationCase {
            name,
            truth,
            foreign: Vec::new(),
            config,
            set,
        }
    }

    /// The base scan plus one effect outside the library (magnitudes from the seed):
    /// a telegraph tip (jumps 20–35 pm, 0.05–0.15 Hz) or a strain bubble (radius
    /// 0.5–0.9 nm, amplitude 25–45 pm, centre in the middle half of the image).
    pub fn out_of_library(effect: ForeignEffect, seed: u64, set: ValidationSet) -> ValidationCase {
        let mut case = Self::with_effects(&[], seed, set);
        let mut rng = Self::rng(seed, 0x0FF1);
        let s = &case.config.scan;
        let (w, h) = (s.width_m, s.height_m);
        let entry = match effect {
            ForeignEffect::TelegraphTip => EffectConfig::TelegraphTip(TelegraphTip {
                jump_m: [
                    sign(&mut rng) * uniform(&mut rng, 20e-12, 35e-12),
                    sign(&mut rng) * uniform(&mut rng, 20e-12, 35e-12),
                ],
                rate_hz: uniform(&mut rng, 0.05, 0.15),
            }),
            ForeignEffect::StrainBubble => EffectConfig::StrainBubble(StrainBubble {
                centre_m: [
                    uniform(&mut rng, 0.25, 0.75) * w,
                    uniform(&mut rng, 0.25, 0.75) * h,
                ],
                radius_m: uniform(&mut rng, 0.5e-9, 0.9e-9),
                amplitude_m: sign(&mut rng) * uniform(&mut rng, 25e-12, 45e-12),
            }),
        };
        case.config.effects.push(entry);
        case.name = format!("{} #{seed}", effect.name());
        case.config.name = case.name.clone();
        case.foreign = vec![effect];
        case
    }

    /// The base scan plus one effect.
    pub fn single(candidate: Candidate, seed: u64, set: ValidationSet) -> ValidationCase {
        Self::with_effects(&[candidate], seed, set)
    }

    /// The base scan alone.
    pub fn effect_free(seed: u64, set: ValidationSet) -> ValidationCase {
        Self::with_effects(&[], seed, set)
    }
}

/// A simulated pair of feature sets.
#[derive(Debug, Clone)]
pub struct SimulatedScan {
    /// The scan.
    pub geometry: ScanGeometry,
    /// Trace features (controller frame, with times).
    pub trace: Vec<Feature>,
    /// Retrace features.
    pub retrace: Vec<Feature>,
}

#[allow(clippy::too_many_arguments)]
fn feature(
    id: usize,
    pass: ScanPass,
    geometry: &ScanGeometry,
    x_px: f64,
    y_px: f64,
    sigma_m: f64,
    height: f64,
    z0: f64,
) -> Feature {
    let time = geometry.acquisition_time(pass, x_px, y_px);
    Feature {
        id,
        pass,
        x_px,
        y_px,
        x_m: x_px * geometry.pitch_x(),
        y_m: y_px * geometry.pitch_y(),
        x_sigma_px: sigma_m / geometry.pitch_x(),
        y_sigma_px: sigma_m / geometry.pitch_y(),
        sigma_major_px: 4.0,
        sigma_minor_px: 4.0,
        theta_rad: 0.0,
        amplitude: height.abs(),
        height,
        z0,
        removed_level: 0.0,
        residual_rms: 0.0,
        pixel_count: 100,
        ncc_peak: 1.0,
        status: FitStatus::Converged,
        fit_iterations: 1,
        time_s: time.since_frame_start,
        line_time_s: time.since_line_start,
    }
}

impl SimulatedScan {
    /// The diagnosis of this scan of `config` (its lattice) with `options`.
    pub fn diagnosed(
        &self,
        config: &SimulationConfig,
        options: &crate::DiagnoseOptions,
    ) -> Result<crate::DiagnosisReport, DiagnoseError> {
        let lattice = config.surface.lattice.build()?;
        crate::diagnose(&self.inputs(), &self.geometry, lattice.as_ref(), options)
    }

    /// Both passes as inputs of [`crate::diagnose`] (no masks).
    pub fn inputs(&self) -> [dhct_distortion::PassInput<'_>; 2] {
        [
            dhct_distortion::PassInput {
                features: &self.trace,
                mask: None,
            },
            dhct_distortion::PassInput {
                features: &self.retrace,
                mask: None,
            },
        ]
    }
}

/// Localisation noise of the position-only path, metres per axis: white, plus a part
/// correlated in time within each pass (an Ornstein–Uhlenbeck process in acquisition time:
/// image noise correlated over lines, 1/f noise, moves neighbouring features of one pass
/// alike; the two passes' image noise is independent). Every feature's reported
/// uncertainty is the total σ.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PositionNoise {
    /// σ of the independent part, metres.
    pub white_m: f64,
    /// σ of the part correlated in time, metres.
    pub correlated_m: f64,
    /// Its correlation time, seconds.
    pub correlation_time_s: f64,
}

impl PositionNoise {
    /// White noise of `sigma_m` only.
    pub fn white(sigma_m: f64) -> PositionNoise {
        PositionNoise {
            white_m: sigma_m,
            correlated_m: 0.0,
            correlation_time_s: 1.0,
        }
    }

    /// The noise of `set` with a total σ of `sigma_m`: white, except in
    /// [`ValidationSet::ForeignDevelopment`] and [`ValidationSet::SecondForeign`], where
    /// 36 % of the variance (1.2 pm of 2 pm) is correlated over one second (about four
    /// lines pairs, a third of a row of features: the features of one row, acquired in the
    /// same lines, share it).
    pub fn of_set(set: ValidationSet, sigma_m: f64) -> PositionNoise {
        match set {
            ValidationSet::ForeignDevelopment | ValidationSet::SecondForeign => PositionNoise {
                white_m: 0.8 * sigma_m,
                correlated_m: 0.6 * sigma_m,
                correlation_time_s: 1.0,
            },
            _ => PositionNoise::white(sigma_m),
        }
    }

    /// The total σ, metres.
    pub fn total_m(&self) -> f64 {
        self.white_m.hypot(self.correlated_m)
    }
}

/// Feature positions only (fast path): true controller positions of every lattice site
/// plus Gaussian noise of `noise_m` (metres, per axis), drawn from `noise_seed`.
pub fn simulate_positions(
    config: &SimulationConfig,
    noise_m: f64,
    noise_seed: u64,
) -> Result<SimulatedScan, DiagnoseError> {
    simulate_positions_with(config, &PositionNoise::white(noise_m), noise_seed)
}

/// A lattice site as one pass acquires it: true controller position (pixels) and terrace
/// height (metres).
struct TrueSite {
    pass: ScanPass,
    x_px: f64,
    y_px: f64,
    z_m: f64,
}

/// [`simulate_positions`] with any [`PositionNoise`].
pub fn simulate_positions_with(
    config: &SimulationConfig,
    noise: &PositionNoise,
    noise_seed: u64,
) -> Result<SimulatedScan, DiagnoseError> {
    config.validate()?;
    let geometry = config.scan.geometry()?;
    let sites = true_sites(config, &geometry)?;
    // Drawn in the sites' order, trace and retrace interleaved (as before correlated noise
    // existed, so that white-noise sets keep their scans); the correlated part has its own
    // stream.
    let mut rng = ChaCha8Rng::seed_from_u64(noise_seed ^ 0xF00D);
    let mut correlated_rng = ChaCha8Rng::seed_from_u64(noise_seed ^ 0xC0AA_E1A7);
    let correlated = ScanPass::BOTH
        .map(|pass| correlated_noise(&sites, pass, &geometry, noise, &mut correlated_rng));
    let mut out = [Vec::new(), Vec::new()];
    for (i, site) in sites.iter().enumerate() {
        let k = usize::from(site.pass == ScanPass::Retrace);
        let c = correlated[k][i];
        let nx: f64 = StandardNormal.sample(&mut rng);
        let ny: f64 = StandardNormal.sample(&mut rng);
        let xp = site.x_px + (nx * noise.white_m + c[0]) / geometry.pitch_x();
        let yp = site.y_px + (ny * noise.white_m + c[1]) / geometry.pitch_y();
        let id = out[k].len();
        out[k].push(feature(
            id,
            site.pass,
            &geometry,
            xp,
            yp,
            noise.total_m(),
            config.surface.feature.height_m,
            site.z_m,
        ));
    }
    let [trace, retrace] = out;
    Ok(SimulatedScan {
        geometry,
        trace,
        retrace,
    })
}

/// The correlated part of the noise at the sites of `pass` (zero at the others'), metres
/// `[x, y]`: an Ornstein–Uhlenbeck process sampled at the sites' acquisition times.
fn correlated_noise(
    sites: &[TrueSite],
    pass: ScanPass,
    geometry: &ScanGeometry,
    noise: &PositionNoise,
    rng: &mut ChaCha8Rng,
) -> Vec<[f64; 2]> {
    let mut out = vec![[0.0; 2]; sites.len()];
    if noise.correlated_m <= 0.0 {
        return out;
    }
    let time = |s: &TrueSite| {
        geometry
            .acquisition_time(pass, s.x_px, s.y_px)
            .since_frame_start
    };
    let mut order: Vec<(f64, usize)> = sites
        .iter()
        .enumerate()
        .filter(|(_, s)| s.pass == pass)
        .map(|(i, s)| (time(s), i))
        .collect();
    order.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut state = [0.0; 2];
    let mut last: Option<f64> = None;
    for (t, i) in order {
        let rho = last.map_or(0.0, |l| (-(t - l) / noise.correlation_time_s).exp());
        let fresh = (1.0 - rho * rho).sqrt() * noise.correlated_m;
        for v in &mut state {
            let n: f64 = StandardNormal.sample(rng);
            *v = rho * *v + fresh * n;
        }
        out[i] = state;
        last = Some(t);
    }
    out
}

/// Every lattice site as each pass acquires it inside the image (4 px from its edges), in
/// lattice order, trace before retrace.
fn true_sites(
    config: &SimulationConfig,
    geometry: &ScanGeometry,
) -> Result<Vec<TrueSite>, DiagnoseError> {
    let lattice = config.surface.lattice.build()?;
    let effects: Vec<Box<dyn Effect>> = config
        .effects
        .iter()
        .enumerate()
        .map(|(k, e)| e.build(&format!("effects[{k}]")))
        .collect::<Result<_, _>>()?;
    let terrace = Terrace::new(&config.surface, config.tip.sigma_m);
    let displacer = Displacer::new(geometry, &effects, &terrace);
    let [a1, a2] = lattice.primitive_vectors();
    let (s, c) = config.surface.angle_rad.sin_cos();
    let rot = |v: Vector2<f64>| Vector2::new(c * v.x - s * v.y, s * v.x + c * v.y);
    let (r1, r2) = (rot(a1), rot(a2));
    let origin = Vector2::from(config.surface.origin_m);
    let (w, h) = (geometry.width(), geometry.height());
    let margin = 3.0 * lattice.nearest_neighbour_distance();
    let reach = ((w + h) / r1.norm().min(r2.norm())).ceil() as i64 + 2;
    let mut out = Vec::new();
    let border = 4.0;
    for n in -reach..=reach {
        for m in -reach..=reach {
            for site in 0..lattice.motif().len() {
                let p = origin + r1 * n as f64 + r2 * m as f64 + rot(lattice.site_position(site));
                if p.x < -margin || p.y < -margin || p.x > w + margin || p.y > h + margin {
                    continue;
                }
                let z_m = terrace.height(p);
                for pass in ScanPass::BOTH {
                    let a = locate(&displacer, pass, p);
                    let [x_px, y_px] = a.controller_position_px;
                    if a.converged
                        && x_px >= border
                        && y_px >= border
                        && x_px <= geometry.columns() as f64 - 1.0 - border
                        && y_px <= geometry.rows() as f64 - 1.0 - border
                    {
                        out.push(TrueSite {
                            pass,
                            x_px,
                            y_px,
                            z_m,
                        });
                    }
                }
            }
        }
    }
    Ok(out)
}

/// The full chain: rendered images, then feature finding with the pipeline's default line
/// levelling (`"lattice"`, as `PipelineOptions::for_lattice` sets it).
pub fn simulate_images(config: &SimulationConfig) -> Result<SimulatedScan, DiagnoseError> {
    let (pair, sets, _) = render_and_find(config)?;
    Ok(scan_of(&pair, sets))
}

/// A rendered scan: its images, its features and how they were found.
#[derive(Debug, Clone)]
pub struct RenderedScan {
    /// The rendered images.
    pub pair: ScanPair,
    /// The features of each image.
    pub sets: Vec<FeatureSet>,
    /// The options they were found with.
    pub options: FeatureOptions,
}

impl RenderedScan {
    /// The diagnosis of this scan of `config` with `options`, as `dhct diagnose` makes
    /// it: the feature positions, then what only the images show
    /// ([`crate::with_pair_views`]).
    pub fn diagnosed(
        &self,
        config: &SimulationConfig,
        options: &crate::DiagnoseOptions,
    ) -> Result<crate::DiagnosisReport, DiagnoseError> {
        let report = scan_of(&self.pair, self.sets.clone()).diagnosed(config, options)?;
        let sets: Vec<&FeatureSet> = self.sets.iter().collect();
        Ok(crate::with_pair_views(
            report,
            &self.pair,
            &sets,
            &self.options,
            None,
        ))
    }
}

/// [`simulate_images`], keeping the images, so that a validation sees what `dhct
/// diagnose` reports ([`RenderedScan::diagnosed`]).
pub fn simulate_rendered(config: &SimulationConfig) -> Result<RenderedScan, DiagnoseError> {
    let (pair, sets, options) = render_and_find(config)?;
    Ok(RenderedScan {
        pair,
        sets,
        options,
    })
}

/// Renders `config`'s images and finds their features.
fn render_and_find(
    config: &SimulationConfig,
) -> Result<(ScanPair, Vec<FeatureSet>, FeatureOptions), DiagnoseError> {
    let output = Simulation::from_config(config)?.run()?;
    let lattice = config.surface.lattice.build()?;
    let options = FeatureOptions {
        line_correction: dhct_features::LineCorrection::Lattice,
        ..FeatureOptions::for_neighbour_distance(lattice.nearest_neighbour_distance())
    };
    let sets = find_features_in_pair(&output.pair, &options)?;
    Ok((output.pair, sets, options))
}

/// The pair's features as a [`SimulatedScan`].
fn scan_of(pair: &ScanPair, sets: Vec<FeatureSet>) -> SimulatedScan {
    let mut trace = Vec::new();
    let mut retrace = Vec::new();
    for set in sets {
        match set.pass {
            ScanPass::Trace => trace = set.features,
            ScanPass::Retrace => retrace = set.features,
        }
    }
    SimulatedScan {
        geometry: pair.geometry().clone(),
        trace,
        retrace,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Noise of each trace feature (noisy minus noise-free position, metres along x), in
    /// acquisition order.
    fn trace_noise_x(noise: &PositionNoise) -> Vec<f64> {
        let case = ValidationCase::effect_free(7, ValidationSet::Tuned);
        let exact = simulate_positions(&case.config, 0.0, 7).expect("simulates");
        let noisy = simulate_positions_with(&case.config, noise, 7).expect("simulates");
        let pitch = exact.geometry.pitch_x();
        let mut pairs: Vec<(f64, f64)> = exact
            .trace
            .iter()
            .zip(&noisy.trace)
            .map(|(a, b)| (a.time_s, (b.x_px - a.x_px) * pitch))
            .collect();
        pairs.sort_by(|a, b| a.0.total_cmp(&b.0));
        pairs.into_iter().map(|p| p.1).collect()
    }

    /// Mean square of the noise, and of the difference between features acquired one after
    /// the other.
    fn spreads(d: &[f64]) -> (f64, f64) {
        let ms = d.iter().map(|v| v * v).sum::<f64>() / d.len() as f64;
        let diff = d.windows(2).map(|w| (w[1] - w[0]).powi(2)).sum::<f64>() / (d.len() - 1) as f64;
        (ms, diff)
    }

    #[test]
    fn correlated_position_noise_is_shared_by_features_acquired_together() {
        let sigma = 2e-12;
        let (ms, diff) = spreads(&trace_noise_x(&PositionNoise::white(sigma)));
        // White: successive differences carry twice the variance.
        assert!((ms / (sigma * sigma) - 1.0).abs() < 0.15, "{ms:e}");
        assert!((diff / ms - 2.0).abs() < 0.3, "{}", diff / ms);
        let noise = PositionNoise::of_set(ValidationSet::SecondForeign, sigma);
        assert!((noise.total_m() - sigma).abs() < 1e-18);
        let (ms, diff) = spreads(&trace_noise_x(&noise));
        assert!((ms / (sigma * sigma) - 1.0).abs() < 0.25, "{ms:e}");
        // Correlated: the shared part (36 % of the variance) cancels in the differences of
        // features acquired within a fraction of the correlation time.
        assert!(diff / ms < 1.5, "{}", diff / ms);
    }
}
