//! Scanner hysteresis laws: the apparent local scale `S(τ)` along a scan axis against the
//! time `τ` since the motion started (line start for the fast axis).
//!
//! `S > 1` means the image is locally stretched: features look farther apart than they are
//! (DHCT measures `S = w/r0`). The tip's displacement along the pass's own scan direction is
//! `−v·I(τ)`, `I(τ) = ∫0^τ (S(τ') − 1) dτ'` ([`HysteresisLaw::excess_integral`]). The law is
//! shared by the simulator (which applies it) and the distortion fit (which measures it), so
//! that a fitted law is the same object as a simulated one.

use serde::{Deserialize, Serialize};

/// The apparent local scale `S(τ)` of scan hysteresis (`τ` in seconds).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum HysteresisLaw {
    /// The paper's quartic (its eq. 13) in a normalised time `u = τ/τ_s`:
    /// `S = 1 + c0 + c1·u + c2·u² + c3·u³ + c4·u⁴`, so
    /// `I(τ) = τ_s·Σ c_k·u^(k+1)/(k+1)`. `c0` is a constant scale error.
    Quartic {
        /// `[c0, c1, c2, c3, c4]`, dimensionless.
        coefficients: [f64; 5],
        /// `τ_s`, seconds (> 0), e.g. the line scan time. Fixed, not a fit parameter.
        time_scale_s: f64,
    },
    /// The authors' Matlab power law `S = k·τ^n` (τ in seconds, so `k` is in s^−n):
    /// `I(τ) = k·τ^(n+1)/(n+1) − τ`. Needs `k > 0` and `n > −1`.
    Power {
        /// `k`, s^−n (> 0).
        k: f64,
        /// `n`, dimensionless (> −1).
        n: f64,
    },
    /// `S = 1 + A·exp(−τ/τ_h)`: `I(τ) = A·τ_h·(1 − exp(−τ/τ_h))`.
    Exponential {
        /// `A`, dimensionless: the excess scale at `τ = 0`.
        amplitude: f64,
        /// `τ_h`, seconds (> 0).
        time_constant_s: f64,
    },
}

impl HysteresisLaw {
    /// No hysteresis (`S ≡ 1`).
    pub fn none() -> HysteresisLaw {
        HysteresisLaw::Exponential {
            amplitude: 0.0,
            time_constant_s: 1.0,
        }
    }

    /// The apparent local scale `S(τ)`, dimensionless.
    pub fn scale(&self, tau: f64) -> f64 {
        match *self {
            HysteresisLaw::Quartic {
                coefficients,
                time_scale_s,
            } => {
                let u = tau / time_scale_s;
                1.0 + coefficients.iter().rev().fold(0.0, |acc, &c| acc * u + c)
            }
            HysteresisLaw::Power { k, n } => k * tau.max(0.0).powf(n),
            HysteresisLaw::Exponential {
                amplitude,
                time_constant_s,
            } => 1.0 + amplitude * (-tau / time_constant_s).exp(),
        }
    }

    /// `I(τ) = ∫0^τ (S(τ') − 1) dτ'`, seconds; zero for `τ ≤ 0`.
    pub fn excess_integral(&self, tau: f64) -> f64 {
        if tau <= 0.0 {
            return 0.0;
        }
        match *self {
            HysteresisLaw::Quartic {
                coefficients,
                time_scale_s,
            } => {
                let u = tau / time_scale_s;
                // Σ c_k u^(k+1)/(k+1), Horner in u.
                let inner = coefficients
                    .iter()
                    .enumerate()
                    .rev()
                    .fold(0.0, |acc, (k, &c)| acc * u + c / (k + 1) as f64);
                time_scale_s * u * inner
            }
            HysteresisLaw::Power { k, n } => k * tau.powf(n + 1.0) / (n + 1.0) - tau,
            HysteresisLaw::Exponential {
                amplitude,
                time_constant_s,
            } => -amplitude * time_constant_s * (-tau / time_constant_s).exp_m1(),
        }
    }

    /// The fit parameters (the quartic's time scale is fixed and not included).
    pub fn parameters(&self) -> Vec<f64> {
        match *self {
            HysteresisLaw::Quartic { coefficients, .. } => coefficients.to_vec(),
            HysteresisLaw::Power { k, n } => vec![k, n],
            HysteresisLaw::Exponential {
                amplitude,
                time_constant_s,
            } => vec![amplitude, time_constant_s],
        }
    }

    /// Number of fit parameters.
    pub fn parameter_count(&self) -> usize {
        match self {
            HysteresisLaw::Quartic { .. } => 5,
            HysteresisLaw::Power { .. } | HysteresisLaw::Exponential { .. } => 2,
        }
    }

    /// The same law with new fit parameters, or `None` unless `p` has
    /// [`HysteresisLaw::parameter_count`] values.
    pub fn with_parameters(&self, p: &[f64]) -> Option<HysteresisLaw> {
        if p.len() != self.parameter_count() {
            return None;
        }
        Some(match *self {
            HysteresisLaw::Quartic { time_scale_s, .. } => HysteresisLaw::Quartic {
                coefficients: [p[0], p[1], p[2], p[3], p[4]],
                time_scale_s,
            },
            HysteresisLaw::Power { .. } => HysteresisLaw::Power { k: p[0], n: p[1] },
            HysteresisLaw::Exponential { .. } => HysteresisLaw::Exponential {
                amplitude: p[0],
                time_constant_s: p[1],
            },
        })
    }
}
