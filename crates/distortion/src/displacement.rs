//! The displacement field of one pass: for every pixel, where the tip really was relative
//! to where the controller put it, `d = p_sample − p_controller` (metres, display frame: x
//! right, y down), from the fitted model. Other tools apply dhct's correction with it: the
//! pixel `(c, r)` was recorded at `(c·pitch_x + dx, r·pitch_y + dy)` on the sample.

use dhct_scan::{ScanGeometry, ScanPass};
use ndarray::Array2;
use serde::Serialize;

use crate::correction::pixel_sample_positions;
use crate::model::DistortionModel;

/// Per pixel of one pass, the tip's displacement from its controller position.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DisplacementField {
    /// Trace or retrace.
    pub pass: ScanPass,
    /// `dx`, metres, `rows × columns` (display orientation).
    pub dx_m: Array2<f64>,
    /// `dy`, metres, `rows × columns`.
    pub dy_m: Array2<f64>,
}

/// The displacement field of `pass` under `model`.
pub fn displacement_field(
    model: &DistortionModel,
    geometry: &ScanGeometry,
    pass: ScanPass,
) -> DisplacementField {
    let (x, y) = pixel_sample_positions(model, geometry, pass);
    let (px, py) = (geometry.pitch_x(), geometry.pitch_y());
    let dx_m = Array2::from_shape_fn(x.dim(), |(r, c)| (x[(r, c)] - c as f64) * px);
    let dy_m = Array2::from_shape_fn(y.dim(), |(r, c)| (y[(r, c)] - r as f64) * py);
    DisplacementField { pass, dx_m, dy_m }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::DriftCreep;
    use dhct_scan::{HysteresisLaw, ScanDirection};

    #[test]
    fn the_field_is_the_models_displacement_at_each_pixel() {
        let geometry = ScanGeometry::new(
            32,
            24,
            1e-10,
            1.2e-10,
            1e-3,
            ScanDirection::Right,
            ScanDirection::Down,
        )
        .unwrap();
        let drift = DriftCreep {
            velocity_m_per_s: [2e-11, -3e-11],
            creep_m: [4e-10, 1e-10],
            t0_s: 0.5,
            ..DriftCreep::none()
        };
        let model = DistortionModel::new(drift, HysteresisLaw::none());
        for pass in [ScanPass::Trace, ScanPass::Retrace] {
            let field = displacement_field(&model, &geometry, pass);
            assert_eq!(field.dx_m.dim(), (24, 32));
            for (c, r) in [(0, 0), (31, 0), (5, 17), (31, 23)] {
                let d = model.displacement(&geometry, pass, c as f64, r as f64);
                assert!((field.dx_m[(r, c)] - d[0]).abs() < 1e-15, "{pass} {c} {r}");
                assert!((field.dy_m[(r, c)] - d[1]).abs() < 1e-15, "{pass} {c} {r}");
            }
            // The drift moves the tip: the field is not zero.
            assert!(field.dy_m[(23, 31)].abs() > 1e-12);
        }
    }
}
