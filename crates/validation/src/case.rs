//! One validation case: a base scan drawn from a seed with the set's physics
//! ([`crate::ScanForm`]), plus the effects withheld from the diagnosis's base model (or an
//! effect outside its library).

use dhct_diagnose::Candidate;
use dhct_simulate::effects::{
    AsymmetricHysteresis, ExponentialCreep, HeightCoupling, HysteresisLaw, LineDrift, LogCreep,
    PiezoNonlinearity, ScanCoupling, SlowScanHysteresis, StrainBubble, TelegraphTip, TipChange,
    Vibration,
};
use dhct_simulate::{EffectConfig, SimulationConfig, StepEdge};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::base::{BaseLaw, base_config, base_config_with_law, rendered_look, sign, uniform};
use crate::set::{BaseForm, ScanForm, SlowRelaxation, ValidationSet};

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
    /// The name of the validation set it belongs to.
    pub set: String,
    /// The set's scan physics it was drawn with.
    pub scans: ScanForm,
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

/// Magnitude factor of an effect (× nominal) from the set's bands: with one band one
/// draw; with a low and a high band, first which side, then where in it.
fn magnitude(rng: &mut ChaCha8Rng, scans: &ScanForm) -> f64 {
    let [lo, hi] = match scans.magnitude.as_slice() {
        [low, high] => {
            if rng.random::<bool>() {
                *low
            } else {
                *high
            }
        }
        [only, ..] => *only,
        [] => [1.0, 1.0],
    };
    uniform(rng, lo, hi)
}

/// Slow-scan hysteresis of magnitude factor `m` in a frame of `frame_s` seconds scanned at
/// `slow_speed` m/s along the slow axis. The first sets relax within 1–3 % of the frame,
/// i.e. mostly within the first row of features (their stretch excess is 0.6·`m`); the
/// sets whose slow hysteresis is [`SlowRelaxation::OverRows`] relax over
/// 3–10 % of the frame (as the exponential creep: a transient that spans rows of features)
/// and move the slow axis by `m` × 40 pm in all (as the exponential creep's amplitude):
/// [`SlowRelaxation`].
fn slow_hysteresis(
    rng: &mut ChaCha8Rng,
    m: f64,
    frame_s: f64,
    slow_speed: f64,
    relaxation: SlowRelaxation,
) -> SlowScanHysteresis {
    let law = match relaxation {
        SlowRelaxation::OverRows => {
            let tau = uniform(rng, 0.03, 0.10) * frame_s;
            HysteresisLaw::Exponential {
                amplitude: m * 40e-12 / (slow_speed * tau),
                time_constant_s: tau,
            }
        }
        SlowRelaxation::FirstRows => HysteresisLaw::Exponential {
            amplitude: m * 0.6,
            time_constant_s: uniform(rng, 0.01, 0.03) * frame_s,
        },
    };
    SlowScanHysteresis { law }
}

/// A height gradient of magnitude in `band` (metres per metre) in a direction drawn from
/// `seed`.
fn tilted_plane(seed: u64, [lo, hi]: [f64; 2]) -> [f64; 2] {
    let mut rng = ChaCha8Rng::seed_from_u64(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ 0x71_17);
    let slope = uniform(&mut rng, lo, hi);
    let azimuth = uniform(&mut rng, 0.0, std::f64::consts::TAU);
    [slope * azimuth.cos(), slope * azimuth.sin()]
}

/// Adds `candidate`'s effect to `config` (magnitudes from `rng`); `false` if it has no
/// simulator effect (higher-order drift, local strain).
fn add_effect(
    config: &mut SimulationConfig,
    candidate: Candidate,
    rng: &mut ChaCha8Rng,
    scans: &ScanForm,
) -> bool {
    let m = magnitude(rng, scans);
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
            scans.slow_hysteresis,
        )),
        Candidate::Vibration => EffectConfig::Vibration(Vibration {
            // Slow enough that the image stays one-to-one along the slow axis (faster
            // vibration folds it: see the module docs).
            frequency_hz: uniform(rng, scans.vibration_hz[0], scans.vibration_hz[1]),
            amplitude_m: [m * 4e-12, m * 3e-12],
            phase_rad: [
                uniform(rng, 0.0, std::f64::consts::TAU),
                uniform(rng, 0.0, std::f64::consts::TAU),
            ],
        }),
        Candidate::TipChange => EffectConfig::TipChange(TipChange {
            time_s: uniform(rng, 0.15, 0.85) * frame,
            jump_m: [sign(rng) * m * 25e-12, sign(rng) * m * 20e-12],
            height_offset_m: match scans.tip_height_m {
                Some([lo, hi]) => sign(rng) * uniform(rng, lo, hi),
                None => 0.0,
            },
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
    pub fn with_effects(effects: &[Candidate], seed: u64, set: &ValidationSet) -> ValidationCase {
        let scans = &set.scans;
        let mut config = match scans.base {
            BaseForm::LawBySeed => base_config_with_law(seed, BaseLaw::of_seed(seed)),
            BaseForm::PowerLaw => base_config(seed),
        };
        if scans.images {
            rendered_look(&mut config, seed);
        }
        if let Some(band) = scans.plane_slope {
            config.surface.plane_slope = tilted_plane(seed, band);
        }
        let mut rng = Self::rng(seed, 0x5EED);
        let mut truth = Vec::new();
        for &c in effects {
            if add_effect(&mut config, c, &mut rng, scans) {
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
            set: set.name.clone(),
            scans: scans.clone(),
        }
    }

    /// The base scan plus one effect outside the library (magnitudes from the seed):
    /// a telegraph tip (jumps 20–35 pm, 0.05–0.15 Hz) or a strain bubble (radius
    /// 0.5–0.9 nm, amplitude 25–45 pm, centre in the middle half of the image).
    pub fn out_of_library(effect: ForeignEffect, seed: u64, set: &ValidationSet) -> ValidationCase {
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
    pub fn single(candidate: Candidate, seed: u64, set: &ValidationSet) -> ValidationCase {
        Self::with_effects(&[candidate], seed, set)
    }

    /// The base scan alone.
    pub fn effect_free(seed: u64, set: &ValidationSet) -> ValidationCase {
        Self::with_effects(&[], seed, set)
    }
}
