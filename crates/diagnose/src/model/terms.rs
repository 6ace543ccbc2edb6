//! Model terms that are not simulator effects: higher-order drift, a smooth spatial
//! distortion field (the "local strain" candidate) and the base model's offset across the
//! lines between the passes.

use dhct_scan::{Axis, ScanPass};
use dhct_simulate::{AcquisitionContext, EffectConfig};
use nalgebra::Vector2;

use crate::model::global::ModelTerm;

/// Drift with a constant jerk: `d = j·t³/6` per axis (`t` seconds since frame start),
/// the next order after the base model's velocity and acceleration.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct CubicDrift {
    /// `j`, m/s³, `[x, y]`.
    pub jerk_m_per_s3: [f64; 2],
}

impl ModelTerm for CubicDrift {
    fn name(&self) -> &'static str {
        "higher-order-drift"
    }
    fn displacement(&self, at: &AcquisitionContext) -> Vector2<f64> {
        let t = at.time_since_frame_start;
        Vector2::new(self.jerk_m_per_s3[0], self.jerk_m_per_s3[1]) * (t * t * t / 6.0)
    }
    fn parameter_names(&self) -> Vec<&'static str> {
        vec!["jerk_x_m_per_s3", "jerk_y_m_per_s3"]
    }
    fn parameters(&self) -> Vec<f64> {
        self.jerk_m_per_s3.to_vec()
    }
    fn with_parameters(&self, p: &[f64]) -> Option<Box<dyn ModelTerm>> {
        (p.len() == 2 && p.iter().all(|v| v.is_finite())).then(|| {
            Box::new(CubicDrift {
                jerk_m_per_s3: [p[0], p[1]],
            }) as Box<dyn ModelTerm>
        })
    }
    fn config(&self) -> Option<EffectConfig> {
        None
    }
}

/// A smooth, time-independent distortion of the sample (local strain, a bent or warped
/// lattice): quadratic in the controller position normalised to `[−1, 1]` over the image,
/// `d = Σ c_k·φ_k(ξ, η)`, `φ = (ξ², ξη, η²)` for each axis. (Constant and linear parts are
/// the lattice's origin, rotation and the drift, so they are left out.)
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct QuadraticField {
    /// `[c_xx², c_xξη, c_xη², c_yξ², c_yξη, c_yη²]`, metres.
    pub coefficients_m: [f64; 6],
}

impl ModelTerm for QuadraticField {
    fn name(&self) -> &'static str {
        "local-strain"
    }
    fn displacement(&self, at: &AcquisitionContext) -> Vector2<f64> {
        let [xi, eta] = at.normalised_position();
        let phi = [xi * xi, xi * eta, eta * eta];
        let c = &self.coefficients_m;
        Vector2::new(
            c[0] * phi[0] + c[1] * phi[1] + c[2] * phi[2],
            c[3] * phi[0] + c[4] * phi[1] + c[5] * phi[2],
        )
    }
    fn parameter_names(&self) -> Vec<&'static str> {
        vec![
            "x_xi2_m",
            "x_xi_eta_m",
            "x_eta2_m",
            "y_xi2_m",
            "y_xi_eta_m",
            "y_eta2_m",
        ]
    }
    fn parameters(&self) -> Vec<f64> {
        self.coefficients_m.to_vec()
    }
    fn with_parameters(&self, p: &[f64]) -> Option<Box<dyn ModelTerm>> {
        (p.len() == 6 && p.iter().all(|v| v.is_finite())).then(|| {
            Box::new(QuadraticField {
                coefficients_m: [p[0], p[1], p[2], p[3], p[4], p[5]],
            }) as Box<dyn ModelTerm>
        })
    }
    fn config(&self) -> Option<EffectConfig> {
        None
    }
}

/// Label (and name) of the base model's [`PassOffset`] term.
pub(crate) const PASS_OFFSET: &str = "pass-offset";

/// The name of [`PassOffset`]'s one parameter (what the report reads it back by).
pub(crate) const ACROSS_LINES_PARAMETER: &str = "across_lines_m";

/// An offset across the scan lines between the two passes: the retrace's features sit
/// `offset` further along the slow axis than the trace's (half of it each way), the same
/// everywhere. No motion of the tip does this (drift, creep and hysteresis move both passes
/// alike across the lines, or through time), but measuring the features does: levelling
/// the lines of an image whose rows run nearly along them imprints the rows' period on the
/// levels, and the two passes, sheared apart by the fast-scan hysteresis, take it up with
/// opposite signs (±0.4–1.1 pm on levelled `tilted` scans). Part of the base model, so
/// that no effect is named for it.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct PassOffset {
    /// The retrace's offset from the trace across the lines (along the slow axis), metres.
    pub across_m: f64,
}

impl ModelTerm for PassOffset {
    fn name(&self) -> &'static str {
        PASS_OFFSET
    }
    fn displacement(&self, at: &AcquisitionContext) -> Vector2<f64> {
        // A feature seen further along the slow axis sits where the tip was displaced the
        // other way (`p_sample = p_controller + d`).
        let half = match at.pass {
            ScanPass::Trace => 0.5 * self.across_m,
            ScanPass::Retrace => -0.5 * self.across_m,
        };
        match at.geometry.fast_axis() {
            Axis::Horizontal => Vector2::new(0.0, half),
            Axis::Vertical => Vector2::new(half, 0.0),
        }
    }
    fn parameter_names(&self) -> Vec<&'static str> {
        vec![ACROSS_LINES_PARAMETER]
    }
    fn parameters(&self) -> Vec<f64> {
        vec![self.across_m]
    }
    fn with_parameters(&self, p: &[f64]) -> Option<Box<dyn ModelTerm>> {
        (p.len() == 1 && p[0].is_finite())
            .then(|| Box::new(PassOffset { across_m: p[0] }) as Box<dyn ModelTerm>)
    }
    fn config(&self) -> Option<EffectConfig> {
        None
    }
}
