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

pub use dhct_scan::HysteresisLaw;
use nalgebra::Vector2;
use serde::{Deserialize, Serialize};

use super::{AcquisitionContext, Effect, EffectConfig, direction_vector};
use crate::SimulationError;
use crate::error::{finite, invalid, parameter_count, positive};

/// Simulator-side checks of a [`HysteresisLaw`]: domain validation with field names and
/// parameter names for the effect interface.
pub(crate) trait LawChecks {
    /// Checks the law's domain; `field` names it in error messages.
    fn validate(&self, field: &str) -> Result<(), SimulationError>;
    /// Parameter names, optionally prefixed for the trace or retrace law.
    fn parameter_names(&self, prefix: Prefix) -> Vec<&'static str>;
}

impl LawChecks for HysteresisLaw {
    fn validate(&self, field: &str) -> Result<(), SimulationError> {
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
}

/// `law` with new fit parameters; a wrong count is an error naming the effect.
fn relaw(law: &HysteresisLaw, effect: &str, p: &[f64]) -> Result<HysteresisLaw, SimulationError> {
    law.with_parameters(p).ok_or_else(|| {
        invalid(
            effect.to_string(),
            format!(
                "expected {} hysteresis parameters, got {}",
                law.parameter_count(),
                p.len()
            ),
        )
    })
}

#[derive(Clone, Copy)]
pub(crate) enum Prefix {
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
            law: relaw(&self.law, self.name(), p)?,
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
            trace: relaw(&self.trace, self.name(), &p[..split])?,
            retrace: relaw(&self.retrace, self.name(), &p[split..])?,
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
            law: relaw(&self.law, self.name(), p)?,
        };
        effect.validate(self.name())?;
        Ok(Box::new(effect))
    }

    fn config(&self) -> EffectConfig {
        EffectConfig::SlowHysteresis(self.clone())
    }
}
