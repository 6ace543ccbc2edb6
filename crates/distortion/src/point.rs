//! A point of a scan (a spectroscopy position, a grid point, a mark) moved into the sample
//! frame by a fitted model, with the 1σ the model's own uncertainty gives it.

use dhct_scan::{ScanGeometry, ScanPass};
use serde::{Deserialize, Serialize};

use crate::{DistortionModel, DriftCreep, HysteresisLaw};

/// A point of the scan in the sample frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MappedPoint {
    /// Position in the sample frame, metres `[x, y]` (display frame, the controller frame's
    /// origin: the first pixel's centre).
    pub position_m: [f64; 2],
    /// 1σ of the position along x and y from the model's parameter uncertainties and
    /// correlations, metres; NaN when the model does not carry them (not fitted, or a
    /// parameter the data did not determine).
    pub sigma_m: [f64; 2],
    /// The acquisition time used, seconds since the frame start.
    pub time_s: f64,
}

/// Moves the point at controller pixel position `(x, y)` of `pass` into the sample frame.
/// `time_s` is when it was recorded (seconds since the frame start; a spectrum taken with
/// the tip parked, a grid point); without it the point is taken to be recorded as the
/// pixel under it was. The fast-scan hysteresis is that of the point's place along its
/// line either way: the tip reached it along the fast axis.
pub fn map_point(
    model: &DistortionModel,
    geometry: &ScanGeometry,
    pass: ScanPass,
    xy_px: [f64; 2],
    time_s: Option<f64>,
) -> MappedPoint {
    let pixel_time = geometry.acquisition_time(pass, xy_px[0], xy_px[1]);
    let t = time_s.unwrap_or(pixel_time.since_frame_start);
    let tau = pixel_time.since_line_start;
    let position = |m: &DistortionModel| {
        let d = m.displacement_at(geometry, pass, t, tau);
        [
            xy_px[0] * geometry.pitch_x() + d[0],
            xy_px[1] * geometry.pitch_y() + d[1],
        ]
    };
    MappedPoint {
        position_m: position(model),
        sigma_m: propagated_sigma(model, position),
        time_s: t,
    }
}

/// 1σ per axis of `position(model)`: `√(J·C·Jᵀ)` with `J` the central-difference gradient
/// over the model's parameters and `C` their covariance (`r_kl·σ_k·σ_l`).
fn propagated_sigma(
    model: &DistortionModel,
    position: impl Fn(&DistortionModel) -> [f64; 2],
) -> [f64; 2] {
    let values: Vec<f64> = model.parameters.iter().map(|p| p.value).collect();
    let sigma: Vec<f64> = model.parameters.iter().map(|p| p.sigma).collect();
    let r = &model.parameter_correlation;
    let n = values.len();
    let known = n > 0 && r.len() == n && sigma.iter().all(|s| s.is_finite());
    if !known || with_values(model, &values).is_none() {
        return [f64::NAN; 2];
    }
    let gradient: Vec<[f64; 2]> = (0..n)
        .map(|k| {
            let h = 1e-3 * sigma[k];
            if h == 0.0 {
                return [0.0; 2];
            }
            let shifted = |step: f64| {
                let mut v = values.clone();
                v[k] += step;
                with_values(model, &v).map_or([f64::NAN; 2], |m| position(&m))
            };
            let (up, down) = (shifted(h), shifted(-h));
            [(up[0] - down[0]) / (2.0 * h), (up[1] - down[1]) / (2.0 * h)]
        })
        .collect();
    let variance = |axis: usize| -> f64 {
        let mut v = 0.0;
        for k in 0..n {
            for l in 0..n {
                v += gradient[k][axis] * r[k][l] * sigma[k] * sigma[l] * gradient[l][axis];
            }
        }
        v
    };
    [variance(0).max(0.0).sqrt(), variance(1).max(0.0).sqrt()]
}

/// `model` with its parameters set to `values` (the order and units of
/// [`DistortionModel::parameters`]: `v_x, a_x, C_x, v_y, a_y, C_y, t0`, then the
/// hysteresis law's). `None` when the model's parameters are not in that layout.
fn with_values(model: &DistortionModel, values: &[f64]) -> Option<DistortionModel> {
    const DRIFT: [&str; 7] = ["v_x", "a_x", "C_x", "v_y", "a_y", "C_y", "t0"];
    let names: Vec<&str> = model.parameters.iter().map(|p| p.name.as_str()).collect();
    if names.len() < 7 || names[..7] != DRIFT || values.len() != names.len() {
        return None;
    }
    let drift = DriftCreep {
        velocity_m_per_s: [values[0], values[3]],
        acceleration_m_per_s2: [values[1], values[4]],
        creep_m: [values[2], values[5]],
        t0_s: values[6],
    };
    let law = &values[7..];
    let hysteresis = match (&model.hysteresis, &names[7..]) {
        (_, []) => model.hysteresis.clone(),
        (HysteresisLaw::Quartic { time_scale_s, .. }, ["c0", "c1", "c2", "c3", "c4"]) => {
            HysteresisLaw::Quartic {
                coefficients: [law[0], law[1], law[2], law[3], law[4]],
                time_scale_s: *time_scale_s,
            }
        }
        (HysteresisLaw::Power { .. }, ["k", "n"]) => HysteresisLaw::Power {
            k: law[0],
            n: law[1],
        },
        (HysteresisLaw::Exponential { .. }, ["amplitude", "time_constant"]) => {
            HysteresisLaw::Exponential {
                amplitude: law[0],
                time_constant_s: law[1],
            }
        }
        _ => return None,
    };
    Some(DistortionModel {
        drift,
        hysteresis,
        ..model.clone()
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Parameter;
    use dhct_scan::ScanDirection;

    fn geometry() -> ScanGeometry {
        ScanGeometry::new(
            64,
            64,
            1e-10,
            1e-10,
            1e-3,
            ScanDirection::Right,
            ScanDirection::Down,
        )
        .unwrap()
    }

    /// A fitted-looking model: drift v = (2, −1) pm/s, creep C = (30, 0) pm with t0 = 5 s,
    /// a power-law hysteresis; σ of v_x and C_x given, the rest 0; correlation `r` between
    /// v_x and C_x.
    fn model(sigma_v: f64, sigma_c: f64, r: f64) -> DistortionModel {
        let drift = DriftCreep {
            velocity_m_per_s: [2e-12, -1e-12],
            acceleration_m_per_s2: [0.0, 0.0],
            creep_m: [30e-12, 0.0],
            t0_s: 5.0,
        };
        let hysteresis = HysteresisLaw::Power { k: 0.95, n: -0.02 };
        let mut model = DistortionModel::new(drift, hysteresis);
        let values = [2e-12, 0.0, 30e-12, -1e-12, 0.0, 0.0, 5.0, 0.95, -0.02];
        let sigmas = [sigma_v, 0.0, sigma_c, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        let names = ["v_x", "a_x", "C_x", "v_y", "a_y", "C_y", "t0", "k", "n"];
        model.parameters = (0..9)
            .map(|k| Parameter {
                name: names[k].into(),
                value: values[k],
                sigma: sigmas[k],
                unit: String::new(),
            })
            .collect();
        let mut correlation = vec![vec![0.0; 9]; 9];
        (0..9).for_each(|k| correlation[k][k] = 1.0);
        correlation[0][2] = r;
        correlation[2][0] = r;
        model.parameter_correlation = correlation;
        model
    }

    #[test]
    fn a_point_recorded_with_its_pixel_lands_where_the_pixel_does() {
        let (g, m) = (geometry(), model(1e-13, 0.0, 0.0));
        for pass in ScanPass::BOTH {
            let mapped = map_point(&m, &g, pass, [12.3, 40.7], None);
            let pixel = m.to_sample(&g, pass, 12.3, 40.7);
            assert_eq!(mapped.position_m, pixel);
        }
    }

    #[test]
    fn the_uncertainty_of_one_drift_velocity_grows_with_time() {
        let (g, m) = (geometry(), model(1e-13, 0.0, 0.0));
        for t in [1.0, 10.0, 100.0] {
            let mapped = map_point(&m, &g, ScanPass::Trace, [5.0, 5.0], Some(t));
            assert_eq!(mapped.time_s, t);
            assert!(
                (mapped.sigma_m[0] / (1e-13 * t) - 1.0).abs() < 1e-6,
                "{mapped:?}"
            );
            assert!(mapped.sigma_m[1].abs() < 1e-22, "{mapped:?}");
        }
    }

    #[test]
    fn correlated_parameters_add_and_anticorrelated_ones_cancel() {
        let g = geometry();
        let t = 20.0;
        let (a, b) = (1e-13 * t, 2e-12 * (t / 5.0f64).ln_1p());
        for (r, expected) in [(1.0, a + b), (-1.0, (a - b).abs()), (0.0, a.hypot(b))] {
            let mapped = map_point(
                &model(1e-13, 2e-12, r),
                &g,
                ScanPass::Trace,
                [0.0; 2],
                Some(t),
            );
            let ratio = mapped.sigma_m[0] / expected;
            assert!(
                (ratio - 1.0).abs() < 1e-5,
                "r = {r}: {mapped:?} vs {expected}"
            );
        }
    }

    #[test]
    fn without_the_correlation_the_uncertainty_is_not_known() {
        let mut m = model(1e-13, 0.0, 0.0);
        m.parameter_correlation.clear();
        let mapped = map_point(&m, &geometry(), ScanPass::Trace, [1.0, 1.0], None);
        assert!(mapped.sigma_m.iter().all(|s| s.is_nan()));
        assert!(mapped.position_m.iter().all(|p| p.is_finite()));
    }
}
