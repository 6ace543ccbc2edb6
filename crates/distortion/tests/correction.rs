//! The correction inverts the simulator's displacement exactly, in every scan direction and
//! on non-square images, and corrected pixels agree with corrected features.

use dhct_distortion::{
    DistortionModel, DriftCreep, HysteresisLaw, correct_image, pixel_sample_positions,
};
use dhct_scan::{ScanDirection, ScanGeometry, ScanPass};
use dhct_simulate::effects::{FastScanHysteresis, LogCreep, ThermalDrift};
use dhct_simulate::{EffectConfig, Simulation, presets};
use ndarray::Array2;

/// The model with the simulator's true parameters of `presets::ci_small()`.
fn true_model() -> DistortionModel {
    DistortionModel::new(
        DriftCreep {
            velocity_m_per_s: [5e-12, -8e-12],
            acceleration_m_per_s2: [1e-15, -2e-15],
            creep_m: [0.1e-9, 0.2e-9],
            t0_s: 20.0,
        },
        HysteresisLaw::Power { k: 0.95, n: -0.03 },
    )
}

fn config_for(trace_fast: ScanDirection, slow: ScanDirection) -> dhct_simulate::SimulationConfig {
    let mut config = presets::ci_small();
    config.scan.columns = 96;
    config.scan.rows = 64;
    config.scan.width_m = 1.5e-9;
    config.scan.height_m = 1.0e-9;
    config.scan.trace_fast = trace_fast;
    config.scan.slow = slow;
    config.scan.turnaround_s = 2e-3;
    config.effects = vec![
        EffectConfig::ThermalDrift(ThermalDrift {
            velocity_m_per_s: [5e-12, -8e-12],
            acceleration_m_per_s2: [1e-15, -2e-15],
        }),
        EffectConfig::Creep(LogCreep {
            coefficient_m: [0.1e-9, 0.2e-9],
            t0_s: 20.0,
            start_s: 0.0,
        }),
        EffectConfig::FastHysteresis(FastScanHysteresis {
            law: dhct_simulate::HysteresisLaw::Power { k: 0.95, n: -0.03 },
        }),
    ];
    config
}

#[test]
fn true_parameters_invert_the_simulator_in_every_direction() {
    use ScanDirection::*;
    let model = true_model();
    for (fast, slow) in [
        (Right, Down),
        (Left, Down),
        (Right, Up),
        (Left, Up),
        (Down, Right),
        (Up, Left),
        (Down, Left),
        (Up, Right),
    ] {
        let config = config_for(fast, slow);
        let simulation = Simulation::from_config(&config).expect("config");
        let geometry = simulation.geometry().clone();
        // Displacement at pixels: model vs simulator, both passes.
        let mut worst_pixel: f64 = 0.0;
        for pass in ScanPass::BOTH {
            for (x, y) in [
                (0.0, 0.0),
                (95.0, 0.0),
                (10.3, 40.7),
                (95.0, 63.0),
                (47.5, 31.2),
            ] {
                let ours = model.displacement(&geometry, pass, x, y);
                let theirs = simulation.displacement(pass, x, y);
                worst_pixel = worst_pixel.max((ours[0] - theirs.x).hypot(ours[1] - theirs.y));
            }
        }
        assert!(
            worst_pixel < 1e-18,
            "{fast:?}/{slow:?}: displacement differs by {worst_pixel} m"
        );
        // Truth features: controller position + model displacement = sample position.
        let output = simulation.run().expect("runs");
        let mut worst: f64 = 0.0;
        for t in output
            .truth
            .features
            .iter()
            .filter(|t| t.trace.in_image && t.retrace.in_image)
        {
            for (pass, a) in [(ScanPass::Trace, t.trace), (ScanPass::Retrace, t.retrace)] {
                let [x, y] = a.controller_position_px;
                let s = model.to_sample(&geometry, pass, x, y);
                let e = (s[0] - t.sample_position_m[0]) / geometry.pitch_x();
                let f = (s[1] - t.sample_position_m[1]) / geometry.pitch_y();
                worst = worst.max(e.hypot(f));
            }
        }
        assert!(
            worst < 1e-4,
            "{fast:?}/{slow:?}: corrected truth features off by {worst} px"
        );
    }
}

#[test]
fn corrected_pixels_agree_with_corrected_positions() {
    // z at each controller pixel is a linear function of the sample position the tip was
    // at; the corrected image must then be that function of the output grid, exactly
    // (barycentric interpolation is exact for linear functions).
    let geometry = ScanGeometry::new(
        120,
        80,
        0.02e-9,
        0.025e-9,
        1e-3,
        ScanDirection::Left,
        ScanDirection::Up,
    )
    .expect("geometry")
    .with_turnaround(5e-3)
    .expect("turnaround");
    let model = DistortionModel::new(
        DriftCreep {
            velocity_m_per_s: [2e-11, -3e-11],
            acceleration_m_per_s2: [0.0; 2],
            creep_m: [0.05e-9, -0.1e-9],
            t0_s: 3.0,
        },
        HysteresisLaw::Power { k: 0.9, n: -0.05 },
    );
    let f = |x_m: f64, y_m: f64| 3.0 * x_m / 1e-9 - 2.0 * y_m / 1e-9 + 0.5;
    for pass in ScanPass::BOTH {
        let (xs, ys) = pixel_sample_positions(&model, &geometry, pass);
        let z = Array2::from_shape_fn((80, 120), |(r, c)| {
            f(
                xs[[r, c]] * geometry.pitch_x(),
                ys[[r, c]] * geometry.pitch_y(),
            )
        });
        let corrected = correct_image(&model, &geometry, pass, &z).expect("corrects");
        let mut covered = 0;
        for ((r, c), v) in corrected.indexed_iter() {
            if v.is_finite() {
                covered += 1;
                let expected = f(c as f64 * geometry.pitch_x(), r as f64 * geometry.pitch_y());
                assert!(
                    (v - expected).abs() < 1e-9,
                    "pixel ({c}, {r}): {v} vs {expected}"
                );
            }
        }
        assert!(
            covered > 80 * 120 / 2,
            "{pass:?}: only {covered} pixels covered"
        );
        // A feature's corrected position is the same map as its pixels'.
        let p = model.to_sample(&geometry, pass, 33.0, 21.0);
        assert!((p[0] / geometry.pitch_x() - xs[[21, 33]]).abs() < 1e-12);
        assert!((p[1] / geometry.pitch_y() - ys[[21, 33]]).abs() < 1e-12);
    }
}

#[test]
fn uncovered_pixels_are_nan_and_identity_is_identity() {
    let geometry = ScanGeometry::new(
        40,
        30,
        1e-10,
        1e-10,
        1e-3,
        ScanDirection::Right,
        ScanDirection::Down,
    )
    .expect("geometry");
    let z = Array2::from_shape_fn((30, 40), |(r, c)| (r * 40 + c) as f64);
    let same =
        correct_image(&DistortionModel::identity(), &geometry, ScanPass::Trace, &z).expect("ok");
    for ((idx, a), b) in same.indexed_iter().zip(z.iter()) {
        assert!((a - b).abs() < 1e-9, "{idx:?}: {a} vs {b}");
    }
    let shifted = DistortionModel::new(
        DriftCreep {
            velocity_m_per_s: [3e-10, 0.0],
            ..DriftCreep::none()
        },
        HysteresisLaw::none(),
    );
    let out = correct_image(&shifted, &geometry, ScanPass::Trace, &z).expect("ok");
    assert!(
        out.iter().any(|v| v.is_nan()),
        "a shifted image leaves NaN pixels"
    );
}
