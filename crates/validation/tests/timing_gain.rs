//! A feature's acquisition time is assigned from its measured position, so with a
//! displacement that moves fast along the slow axis its localisation error reaches the
//! residual multiplied by the timing gain `1 + v·Δt_line/pitch`. The diagnosis undoes that
//! gain before comparing residuals with the fits' 1σ: an effect-free scan with a fast y
//! drift sits at the floor whichever way the drift runs.

use dhct_diagnose::{DiagnoseOptions, VerdictKind};
use dhct_simulate::EffectConfig;
use dhct_validation::{ValidationCase, ValidationSet, simulate_positions};

/// The base model's RMS residual per axis in units of the floor, and the verdict, for an
/// effect-free scan whose y drift is `velocity_y` m/s.
fn at_floor(velocity_y: f64) -> ([f64; 2], VerdictKind) {
    let mut case =
        ValidationCase::effect_free(8101, &ValidationSet::named("tuned").expect("a shipped set"));
    for effect in &mut case.config.effects {
        if let EffectConfig::ThermalDrift(drift) = effect {
            drift.velocity_m_per_s[1] = velocity_y;
        }
    }
    let scan = simulate_positions(&case.config, 2e-12, 3).expect("simulates");
    let report = scan
        .diagnosed(&case.config, &DiagnoseOptions::default())
        .expect("diagnoses");
    let (rms, floor) = (report.base.gap.rms_m, report.noise.sigma_m);
    ([rms[0] / floor[0], rms[1] / floor[1]], report.verdict)
}

#[test]
fn a_fast_slow_axis_drift_leaves_the_residuals_at_the_floor() {
    // 25 pm/s over 15.6 pm pixels scanned 0.24 s apart: a timing gain of 1 ± 0.38 in y,
    // which unwhitened put the y residual at 1.38 or 0.62 floors.
    for velocity in [25e-12, -25e-12] {
        let (ratio, verdict) = at_floor(velocity);
        for (axis, r) in ratio.iter().enumerate() {
            assert!(
                (0.9..1.1).contains(r),
                "drift {velocity:e} m/s: axis {axis} at {r:.3} floors"
            );
        }
        assert_eq!(verdict, VerdictKind::NoGap, "drift {velocity:e} m/s");
    }
}
