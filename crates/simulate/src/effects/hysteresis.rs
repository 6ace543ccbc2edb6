//! Scan hysteresis: fast-axis (effect 3), trace/retrace-asymmetric (effect 10) and
//! slow-axis at frame start (effect 9).
//!
//! # Convention (the DHCT reference's)
//!
//! A hysteresis law gives the *apparent local scale* `S(τ)` along the scan axis as a
//! function of the time `τ` since the motion started (line start for the fast axis, frame
//! start for the slow axis): `S > 1` means the image is locally stretched — features look
//! farther apart than they are — exactly what DHCT measures as `S = w/r0`. The tip's
//! displacement along the pass's own scan direction `ê` is
//!
//! `d = −v·I(τ)·ê`, `I(τ) = ∫0^τ (S(τ') − 1) dτ'`,
//!
//! with `v` the controller speed along that axis. So the tip covers sample at the rate
//! `v·(2 − S) ≈ v/S` and a feature spacing `a` appears as `a/(2 − S)` ≈ `S·a`, which is the
//! inverse of the DHCT correction `f' = k − I(τ)/P` with the same `S`. Trace and retrace are
//! mirrored: each pass measures `τ` from its own line start and the retrace is anchored so
//! the tip is continuous at the turnaround after the trace
//! (`d_retrace(τ) = −v·(I(T) − I(τ))·ê_trace`, `T` = scanning time of a line), which is
//! also where the DHCT correction anchors it.

use nalgebra::Vector2;
use serde::{Deserialize, Serialize};

use super::{AcquisitionContext, Effect, EffectConfig, direction_vector};
use crate::SimulationError;
use crate::error::{finite, invalid, parameter_count, positive};

/// The apparent local scale `S(τ)` of a hysteresis effect (`τ` in seconds).
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
            HysteresisLaw::Power { k, n } => k * tau.powf(n),
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

    /// Checks the law's domain; `field` names it in error messages.
    pub fn validate(&self, field: &str) -> Result<(), SimulationError> {
        match *self {
            HysteresisLaw::Quartic {
                coefficients,
                time_scale_s,
            } => {
                for (k, c) in coefficients.iter().enumerate() {
                    finite(&format!("{field}.coefficients[{k}]"), *c)?;
                }
                positive(&format!("{field}.time_scale_s"), time_scale_s)
            }
            HysteresisLaw::Power { k, n } => {
                positive(&format!("{field}.k"), k)?;
                if n.is_finite() && n > -1.0 {
                    Ok(())
                } else {
                    Err(invalid(
                        format!("{field}.n"),
                        format!("must be finite and > −1 (∫S dτ diverges otherwise), got {n}"),
                    ))
                }
            }
            HysteresisLaw::Exponential {
                amplitude,
                time_constant_s,
            } => {
                finite(&format!("{field}.amplitude"), amplitude)?;
                positive(&format!("{field}.time_constant_s"), time_constant_s)
            }
        }
    }

    /// Parameter names, optionally prefixed for the trace or retrace law.
    fn parameter_names(&self, prefix: Prefix) -> Vec<&'static str> {
        match (self, prefix) {
            (HysteresisLaw::Quartic { .. }, Prefix::None) => vec!["c0", "c1", "c2", "c3", "c4"],
            (HysteresisLaw::Quartic { .. }, Prefix::Trace) => {
                vec!["trace_c0", "trace_c1", "trace_c2", "trace_c3", "trace_c4"]
            }
            (HysteresisLaw::Quartic { .. }, Prefix::Retrace) => vec![
                "retrace_c0",
                "retrace_c1",
                "retrace_c2",
                "retrace_c3",
                "retrace_c4",
            ],
            (HysteresisLaw::Power { .. }, Prefix::None) => vec!["k", "n"],
            (HysteresisLaw::Power { .. }, Prefix::Trace) => vec!["trace_k", "trace_n"],
            (HysteresisLaw::Power { .. }, Prefix::Retrace) => vec!["retrace_k", "retrace_n"],
            (HysteresisLaw::Exponential { .. }, Prefix::None) => {
                vec!["amplitude", "time_constant_s"]
            }
            (HysteresisLaw::Exponential { .. }, Prefix::Trace) => {
                vec!["trace_amplitude", "trace_time_constant_s"]
            }
            (HysteresisLaw::Exponential { .. }, Prefix::Retrace) => {
                vec!["retrace_amplitude", "retrace_time_constant_s"]
            }
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

    /// The same law with new fit parameters (length [`HysteresisLaw::parameter_count`]).
    fn with_parameters(&self, p: &[f64]) -> HysteresisLaw {
        match *self {
            HysteresisLaw::Quartic { time_scale_s, .. } => HysteresisLaw::Quartic {
                coefficients: [p[0], p[1], p[2], p[3], p[4]],
                time_scale_s,
            },
            HysteresisLaw::Power { .. } => HysteresisLaw::Power { k: p[0], n: p[1] },
            HysteresisLaw::Exponential { .. } => HysteresisLaw::Exponential {
                amplitude: p[0],
                time_constant_s: p[1],
            },
        }
    }
}

#[derive(Clone, Copy)]
enum Prefix {
    None,
    Trace,
    Retrace,
}

/// Displacement of fast-axis hysteresis with possibly different trace and retrace laws.
fn fast_displacement(
    trace: &HysteresisLaw,
    retrace: &HysteresisLaw,
    at: &AcquisitionContext,
) -> Vector2<f64> {
    let geometry = at.geometry;
    let along_trace = direction_vector(geometry.trace_fast());
    let speed = geometry.fast_speed();
    let tau = at.time_since_line_start;
    let lag = match at.pass {
        dhct_scan::ScanPass::Trace => trace.excess_integral(tau),
        dhct_scan::ScanPass::Retrace => {
            trace.excess_integral(geometry.line_scan_time()) - retrace.excess_integral(tau)
        }
    };
    along_trace * (-speed * lag)
}

/// Fast-scan hysteresis, the same law in trace and retrace (mirrored): see the module docs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FastScanHysteresis {
    /// `S(τ)` vs seconds since the line start.
    pub law: HysteresisLaw,
}

impl FastScanHysteresis {
    /// Checks the law.
    pub fn validate(&self, field: &str) -> Result<(), SimulationError> {
        self.law.validate(&format!("{field}.law"))
    }
}

impl Effect for FastScanHysteresis {
    fn name(&self) -> &'static str {
        "fast-hysteresis"
    }

    fn displacement(&self, at: &AcquisitionContext) -> Vector2<f64> {
        fast_displacement(&self.law, &self.law, at)
    }

    fn parameter_names(&self) -> Vec<&'static str> {
        self.law.parameter_names(Prefix::None)
    }

    fn parameters(&self) -> Vec<f64> {
        self.law.parameters()
    }

    fn with_parameters(&self, p: &[f64]) -> Result<Box<dyn Effect>, SimulationError> {
        parameter_count(self.name(), p, self.law.parameter_count())?;
        let effect = FastScanHysteresis {
            law: self.law.with_parameters(p),
        };
        effect.validate(self.name())?;
        Ok(Box::new(effect))
    }

    fn config(&self) -> EffectConfig {
        EffectConfig::FastHysteresis(self.clone())
    }
}

/// Fast-scan hysteresis with its own law in each pass (trace/retrace asymmetry). The
/// retrace starts where the trace ended; the next trace starts from zero again, so the loop
/// does not close when the two laws' `I(T)` differ.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AsymmetricHysteresis {
    /// `S(τ)` of the trace.
    pub trace: HysteresisLaw,
    /// `S(τ)` of the retrace, `τ` from the retrace's own line start.
    pub retrace: HysteresisLaw,
}

impl AsymmetricHysteresis {
    /// Checks both laws.
    pub fn validate(&self, field: &str) -> Result<(), SimulationError> {
        self.trace.validate(&format!("{field}.trace"))?;
        self.retrace.validate(&format!("{field}.retrace"))
    }
}

impl Effect for AsymmetricHysteresis {
    fn name(&self) -> &'static str {
        "asymmetric-hysteresis"
    }

    fn displacement(&self, at: &AcquisitionContext) -> Vector2<f64> {
        fast_displacement(&self.trace, &self.retrace, at)
    }

    fn parameter_names(&self) -> Vec<&'static str> {
        let mut names = self.trace.parameter_names(Prefix::Trace);
        names.extend(self.retrace.parameter_names(Prefix::Retrace));
        names
    }

    fn parameters(&self) -> Vec<f64> {
        let mut values = self.trace.parameters();
        values.extend(self.retrace.parameters());
        values
    }

    fn with_parameters(&self, p: &[f64]) -> Result<Box<dyn Effect>, SimulationError> {
        let split = self.trace.parameter_count();
        parameter_count(self.name(), p, split + self.retrace.parameter_count())?;
        let effect = AsymmetricHysteresis {
            trace: self.trace.with_parameters(&p[..split]),
            retrace: self.retrace.with_parameters(&p[split..]),
        };
        effect.validate(self.name())?;
        Ok(Box::new(effect))
    }

    fn config(&self) -> EffectConfig {
        EffectConfig::AsymmetricHysteresis(self.clone())
    }
}

/// Slow-scan hysteresis after the slow axis starts moving at frame start: `S(t)` vs seconds
/// since frame start, `d = −v_slow·I(t)·ê_slow` with `v_slow` the mean slow speed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SlowScanHysteresis {
    /// `S(t)` vs seconds since frame start.
    pub law: HysteresisLaw,
}

impl SlowScanHysteresis {
    /// Checks the law.
    pub fn validate(&self, field: &str) -> Result<(), SimulationError> {
        self.law.validate(&format!("{field}.law"))
    }
}

impl Effect for SlowScanHysteresis {
    fn name(&self) -> &'static str {
        "slow-hysteresis"
    }

    fn displacement(&self, at: &AcquisitionContext) -> Vector2<f64> {
        let geometry = at.geometry;
        let along_slow = direction_vector(geometry.slow_direction());
        along_slow * (-geometry.slow_speed() * self.law.excess_integral(at.time_since_frame_start))
    }

    fn parameter_names(&self) -> Vec<&'static str> {
        self.law.parameter_names(Prefix::None)
    }

    fn parameters(&self) -> Vec<f64> {
        self.law.parameters()
    }

    fn with_parameters(&self, p: &[f64]) -> Result<Box<dyn Effect>, SimulationError> {
        parameter_count(self.name(), p, self.law.parameter_count())?;
        let effect = SlowScanHysteresis {
            law: self.law.with_parameters(p),
        };
        effect.validate(self.name())?;
        Ok(Box::new(effect))
    }

    fn config(&self) -> EffectConfig {
        EffectConfig::SlowHysteresis(self.clone())
    }
}
