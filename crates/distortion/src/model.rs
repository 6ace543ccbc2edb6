//! The distortion model: drift + creep per axis with a shared `t0` (the paper's eq. 14) and
//! fast-scan hysteresis `S(τ)` (the paper's quartic eq. 13, the Matlab power law, or an
//! exponential), with the closed-form displacement they integrate to.
//!
//! # Signs and frames
//!
//! `d(t, pass)` is the displacement of the tip *relative to the sample*, metres, display
//! frame (x right, y down): the tip commanded to controller position `p_c` at time `t` was at
//! sample position `p_s = p_c + d`. This is the convention of `dhct-simulate`, so given the
//! simulator's true parameters [`DistortionModel::displacement`] reproduces its
//! `ThermalDrift + LogCreep + FastScanHysteresis` displacement exactly:
//!
//! * drift + creep: `d_D(t) = ∫0^t D(t') dt' = v·t + a·t²/2 + C·ln(1 + t/t0)` per axis;
//! * hysteresis, trace: `d_H = −v_f·I(τ)·ê_trace`; retrace: `d_H = −v_f·(I(T) − I(τ))·ê_trace`,
//!   `I(τ) = ∫0^τ (S − 1) dτ'`, `T` the scanning time of a line, `v_f` the fast speed.

pub use dhct_scan::HysteresisLaw;
use dhct_scan::{ScanDirection, ScanGeometry, ScanPass};
use serde::{Deserialize, Serialize};

/// Drift + creep velocity of the tip relative to the sample, per display axis:
/// `D(t) = v + a·t + C/(t + t0)` (m/s), `t` seconds since frame start, `t0` shared.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DriftCreep {
    /// `v`, m/s, `[x, y]`.
    pub velocity_m_per_s: [f64; 2],
    /// `a`, m/s², `[x, y]`.
    pub acceleration_m_per_s2: [f64; 2],
    /// `C`, metres, `[x, y]`.
    pub creep_m: [f64; 2],
    /// `t0`, seconds (> 0).
    pub t0_s: f64,
}

impl DriftCreep {
    /// No drift.
    pub fn none() -> DriftCreep {
        DriftCreep {
            velocity_m_per_s: [0.0; 2],
            acceleration_m_per_s2: [0.0; 2],
            creep_m: [0.0; 2],
            t0_s: 1.0,
        }
    }

    /// `D(t)`, m/s, `[x, y]`.
    pub fn velocity(&self, t: f64) -> [f64; 2] {
        std::array::from_fn(|k| {
            self.velocity_m_per_s[k]
                + self.acceleration_m_per_s2[k] * t
                + self.creep_m[k] / (t + self.t0_s)
        })
    }

    /// `∫0^t D`, metres, `[x, y]`: `v·t + a·t²/2 + C·ln(1 + t/t0)`.
    pub fn displacement(&self, t: f64) -> [f64; 2] {
        self.displacement_with_log(t, (t / self.t0_s).ln_1p())
    }

    /// [`DriftCreep::displacement`] with `log = ln(1 + t/t0)` computed by the caller (the
    /// correction of a row of pixels takes it from the row's first pixel).
    pub fn displacement_with_log(&self, t: f64, log: f64) -> [f64; 2] {
        std::array::from_fn(|k| {
            self.velocity_m_per_s[k] * t
                + 0.5 * self.acceleration_m_per_s2[k] * t * t
                + self.creep_m[k] * log
        })
    }
}

/// One fitted parameter with its 1σ uncertainty and unit.
///
/// Serialised (model.json) as `{"name", "value", "sigma", "determined", "unit"}`: when the
/// data cannot fix the uncertainty (a singular or non-finite covariance, e.g. a parameter
/// the frame does not constrain) `sigma` is NaN here, and written as `"sigma": null` with
/// `"determined": false`; otherwise `"determined": true`. Reading accepts `null` (as NaN)
/// and ignores `determined`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub struct Parameter {
    /// Name, e.g. `"v_x"`.
    pub name: String,
    /// Value in `unit`.
    pub value: f64,
    /// 1σ uncertainty from the fit covariance (scaled by the residual variance), `unit`;
    /// NaN when undetermined (see [`Parameter::is_determined`]).
    #[serde(deserialize_with = "sigma_or_nan")]
    pub sigma: f64,
    /// SI unit, e.g. `"m/s"`.
    pub unit: String,
}

impl Parameter {
    /// Whether the data fixed the uncertainty (`sigma` finite).
    pub fn is_determined(&self) -> bool {
        self.sigma.is_finite()
    }
}

impl Serialize for Parameter {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeStruct;
        let mut out = serializer.serialize_struct("Parameter", 5)?;
        out.serialize_field("name", &self.name)?;
        out.serialize_field("value", &self.value)?;
        out.serialize_field("sigma", &self.is_determined().then_some(self.sigma))?;
        out.serialize_field("determined", &self.is_determined())?;
        out.serialize_field("unit", &self.unit)?;
        out.end()
    }
}

/// A σ that may be `null` (undetermined): NaN.
fn sigma_or_nan<'de, D: serde::Deserializer<'de>>(deserializer: D) -> Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(deserializer)?.unwrap_or(f64::NAN))
}

/// Two fitted parameters whose estimates are nearly degenerate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DegeneratePair {
    /// First parameter's name.
    pub first: String,
    /// Second parameter's name.
    pub second: String,
    /// Their correlation coefficient (|r| > 0.95).
    pub correlation: f64,
}

/// A fitted parameter that ended at a bound of its allowed range.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Bound {
    /// The parameter's name.
    pub parameter: String,
    /// Its value, in its unit.
    pub value: f64,
    /// The allowed range `[low, high]`, same unit.
    pub range: [f64; 2],
}

/// What the fit says about its own weak spots.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct FitDiagnostics {
    /// Pairs of drift/creep parameters correlated beyond ±0.95.
    pub degenerate_pairs: Vec<DegeneratePair>,
    /// Parameters at a bound of their range.
    pub at_bounds: Vec<Bound>,
}

/// The fitted distortion of one scan: drift + creep and fast-scan hysteresis.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DistortionModel {
    /// Drift and creep.
    pub drift: DriftCreep,
    /// Fast-scan hysteresis, the same law (mirrored) in trace and retrace.
    pub hysteresis: HysteresisLaw,
    /// Every fitted parameter with uncertainty and unit (drift first, then hysteresis).
    pub parameters: Vec<Parameter>,
    /// Degenerate pairs and parameters at bounds (empty for a model not fitted).
    #[serde(default)]
    pub diagnostics: FitDiagnostics,
    /// Correlation coefficients between the [`DistortionModel::parameters`] (same order;
    /// 0 with an undetermined parameter, whose `sigma` already says so), for carrying the
    /// model's uncertainty to positions ([`crate::map_point`]). Empty for a model
    /// not fitted. The local route fits drift/creep and hysteresis on different
    /// measurements, so their cross terms are 0 there; the global registration fits them
    /// together.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub parameter_correlation: Vec<Vec<f64>>,
}

fn direction_vector(direction: ScanDirection) -> [f64; 2] {
    match direction {
        ScanDirection::Right => [1.0, 0.0],
        ScanDirection::Left => [-1.0, 0.0],
        ScanDirection::Down => [0.0, 1.0],
        ScanDirection::Up => [0.0, -1.0],
    }
}

/// Unit vectors `(ê_fast, ê_slow)` of `pass` in the display frame (x right, y down).
pub fn scan_basis(geometry: &ScanGeometry, pass: ScanPass) -> ([f64; 2], [f64; 2]) {
    (
        direction_vector(geometry.fast_direction(pass)),
        direction_vector(geometry.slow_direction()),
    )
}

impl DistortionModel {
    /// A model with no distortion.
    pub fn identity() -> DistortionModel {
        DistortionModel {
            drift: DriftCreep::none(),
            hysteresis: HysteresisLaw::none(),
            parameters: Vec::new(),
            diagnostics: FitDiagnostics::default(),
            parameter_correlation: Vec::new(),
        }
    }

    /// A model from known drift and hysteresis (no uncertainties).
    pub fn new(drift: DriftCreep, hysteresis: HysteresisLaw) -> DistortionModel {
        DistortionModel {
            drift,
            hysteresis,
            parameters: Vec::new(),
            diagnostics: FitDiagnostics::default(),
            parameter_correlation: Vec::new(),
        }
    }

    /// Displacement `d = p_sample − p_ctrl` (metres, display frame) of the tip at acquisition
    /// time `t` (s since frame start) and line time `τ` (s since the line start of `pass`).
    pub fn displacement_at(
        &self,
        geometry: &ScanGeometry,
        pass: ScanPass,
        t: f64,
        tau: f64,
    ) -> [f64; 2] {
        self.displacement_with_lag(geometry, t, self.hysteresis_lag(geometry, pass, tau))
    }

    /// The hysteresis lag `∫(S − 1) dτ` (seconds of fast-axis travel) accumulated at line
    /// time `τ` (s since the line start of `pass`); the retrace runs the law backwards.
    pub fn hysteresis_lag(&self, geometry: &ScanGeometry, pass: ScanPass, tau: f64) -> f64 {
        match pass {
            ScanPass::Trace => self.hysteresis.excess_integral(tau),
            ScanPass::Retrace => {
                self.hysteresis.excess_integral(geometry.line_scan_time())
                    - self.hysteresis.excess_integral(tau)
            }
        }
    }

    /// Displacement (metres, display frame) at acquisition time `t` (s since frame start)
    /// with hysteresis lag `lag` from [`DistortionModel::hysteresis_lag`].
    pub fn displacement_with_lag(&self, geometry: &ScanGeometry, t: f64, lag: f64) -> [f64; 2] {
        let log = (t / self.drift.t0_s).ln_1p();
        self.displacement_with_lag_and_log(geometry, t, lag, log)
    }

    /// [`DistortionModel::displacement_with_lag`] with the creep's `ln(1 + t/t0)` given.
    pub(crate) fn displacement_with_lag_and_log(
        &self,
        geometry: &ScanGeometry,
        t: f64,
        lag: f64,
        log: f64,
    ) -> [f64; 2] {
        let drift = self.drift.displacement_with_log(t, log);
        let trace = direction_vector(geometry.trace_fast());
        let h = -geometry.fast_speed() * lag;
        [drift[0] + h * trace[0], drift[1] + h * trace[1]]
    }

    /// Displacement (metres, display frame) at controller pixel position `(x, y)` of `pass`,
    /// with the exact acquisition time from [`ScanGeometry::acquisition_time`].
    pub fn displacement(
        &self,
        geometry: &ScanGeometry,
        pass: ScanPass,
        x_px: f64,
        y_px: f64,
    ) -> [f64; 2] {
        let time = geometry.acquisition_time(pass, x_px, y_px);
        self.displacement_at(
            geometry,
            pass,
            time.since_frame_start,
            time.since_line_start,
        )
    }

    /// Sample-frame position (metres) of controller pixel position `(x, y)` of `pass`:
    /// `p_s = (x·pitch_x, y·pitch_y) + d`.
    pub fn to_sample(
        &self,
        geometry: &ScanGeometry,
        pass: ScanPass,
        x_px: f64,
        y_px: f64,
    ) -> [f64; 2] {
        let d = self.displacement(geometry, pass, x_px, y_px);
        [
            x_px * geometry.pitch_x() + d[0],
            y_px * geometry.pitch_y() + d[1],
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn undetermined_sigma_is_written_as_null_with_determined_false() {
        let fixed = Parameter {
            name: "v_x".into(),
            value: 1e-12,
            sigma: 2e-13,
            unit: "m/s".into(),
        };
        let loose = Parameter {
            sigma: f64::NAN,
            ..fixed.clone()
        };
        let json = serde_json::to_value(&fixed).unwrap();
        assert_eq!(json["sigma"], 2e-13);
        assert_eq!(json["determined"], true);
        let json = serde_json::to_value(&loose).unwrap();
        assert!(json["sigma"].is_null(), "{json}");
        assert_eq!(json["determined"], false);
        let back: Parameter = serde_json::from_value(json).unwrap();
        assert!(back.sigma.is_nan() && !back.is_determined());
        let back: Parameter =
            serde_json::from_value(serde_json::to_value(&fixed).unwrap()).unwrap();
        assert_eq!(back, fixed);
    }

    #[test]
    fn integrals_match_numerical_quadrature() {
        let laws = [
            HysteresisLaw::Quartic {
                coefficients: [0.01, 0.2, -0.3, 0.1, 0.05],
                time_scale_s: 0.08,
            },
            HysteresisLaw::Power { k: 0.95, n: -0.03 },
            HysteresisLaw::Exponential {
                amplitude: 0.2,
                time_constant_s: 0.01,
            },
        ];
        for law in laws {
            let tau = 0.05;
            let steps = 200_000;
            let h = tau / steps as f64;
            let numeric: f64 = (0..steps)
                .map(|k| (law.scale((k as f64 + 0.5) * h) - 1.0) * h)
                .sum();
            assert!((numeric - law.excess_integral(tau)).abs() < 1e-6, "{law:?}");
        }
        let drift = DriftCreep {
            velocity_m_per_s: [1.0, -2.0],
            acceleration_m_per_s2: [0.1, 0.3],
            creep_m: [0.5, -0.7],
            t0_s: 3.0,
        };
        let t = 7.0;
        let h = 1e-5;
        let d = |t| drift.displacement(t);
        for k in 0..2 {
            let numeric = (d(t + h)[k] - d(t - h)[k]) / (2.0 * h);
            assert!((numeric - drift.velocity(t)[k]).abs() < 1e-6);
        }
        assert_eq!(drift.displacement(0.0), [0.0, 0.0]);
    }

    #[test]
    fn model_serialises() {
        let model =
            DistortionModel::new(DriftCreep::none(), HysteresisLaw::Power { k: 1.0, n: 0.0 });
        let json = serde_json::to_string(&model).expect("serialises");
        let back: DistortionModel = serde_json::from_str(&json).expect("deserialises");
        assert_eq!(model, back);
    }
}
