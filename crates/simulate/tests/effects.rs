//! Each effect alone produces its analytically expected displacement, checked on the ground
//! truth (feature controller vs sample positions) and on the images themselves.

mod common;

use std::f64::consts::TAU;

use common::{
    A, PITCH, SPEED, base_config, cell, nearest_distance, peaks, run, well_inside, with_effects,
};
use dhct_scan::ScanPass;
use dhct_simulate::effects::{
    AsymmetricHysteresis, ExponentialCreep, FastScanHysteresis, HeightCoupling, LineDrift,
    LineJitter, LogCreep, PiezoNonlinearity, ScanCoupling, ScannerGain, SessionDrift,
    SlowScanHysteresis, ThermalDrift, TipChange, Vibration,
};
use dhct_simulate::{AcquisitionContext, Effect, EffectConfig, HysteresisLaw, Region, StepEdge};

/// Pixel period and line time of the base config.
const PERIOD: f64 = PITCH / SPEED;
const LINE: f64 = 128.0 * PERIOD;
/// Mean slow speed: one pixel per line pair.
const SLOW_SPEED: f64 = PITCH / (2.0 * LINE);

fn close(a: f64, b: f64, tolerance: f64) -> bool {
    (a - b).abs() <= tolerance
}

/// Pairs of features adjacent along the lattice's a2 (m + 1, same n) or a1 (n + 1, same m).
fn neighbour_pairs<'a>(
    features: &[&'a dhct_simulate::FeatureTruth],
    along_m: bool,
) -> Vec<(
    &'a dhct_simulate::FeatureTruth,
    &'a dhct_simulate::FeatureTruth,
)> {
    let mut pairs = Vec::new();
    for a in features {
        for b in features {
            let (Some((na, ma)), Some((nb, mb))) = (cell(a), cell(b)) else {
                continue;
            };
            let adjacent = if along_m {
                na == nb && mb == ma + 1
            } else {
                ma == mb && nb == na + 1
            };
            if adjacent {
                pairs.push((*a, *b));
            }
        }
    }
    pairs
}

#[test]
fn slow_axis_drift_stretches_the_slow_scale_by_exactly_v_over_v_slow() {
    let v = 40e-12;
    let output = run(&with_effects(vec![EffectConfig::ThermalDrift(
        ThermalDrift {
            velocity_m_per_s: [0.0, v],
            acceleration_m_per_s2: [0.0, 0.0],
        },
    )]));
    let stretch = 1.0 + v / SLOW_SPEED;
    for pass in ScanPass::BOTH {
        let features = well_inside(&output, pass, 1.0);
        let pairs = neighbour_pairs(&features, true);
        assert!(pairs.len() > 50, "{} pairs", pairs.len());
        for (a, b) in pairs {
            let dy_px = b.acquisition(pass).controller_position_px[1]
                - a.acquisition(pass).controller_position_px[1];
            let measured = dy_px * PITCH * stretch;
            assert!(close(measured, A, 1e-6 * A), "{pass:?}: {measured} vs {A}");
            // Along x nothing changes.
            let dx_px = b.acquisition(pass).controller_position_px[0]
                - a.acquisition(pass).controller_position_px[0];
            assert!(dx_px.abs() < 1e-6, "{dx_px}");
        }
    }
}

#[test]
fn fast_axis_drift_stretches_trace_and_retrace_oppositely() {
    let v = 2.5e-9; // 5 % of the fast speed, so the effect is large
    for effect in [
        EffectConfig::ThermalDrift(ThermalDrift {
            velocity_m_per_s: [v, 0.0],
            acceleration_m_per_s2: [0.0, 0.0],
        }),
        EffectConfig::LineDrift(LineDrift {
            velocity_m_per_s: [v, 0.0],
        }),
    ] {
        let output = run(&with_effects(vec![effect.clone()]));
        for (pass, stretch) in [
            (ScanPass::Trace, 1.0 + v / SPEED),
            (ScanPass::Retrace, 1.0 - v / SPEED),
        ] {
            let features = well_inside(&output, pass, 1.0);
            let pairs = neighbour_pairs(&features, false);
            assert!(pairs.len() > 20, "{}: {} pairs", effect.kind(), pairs.len());
            for (a, b) in pairs {
                let dx_px = b.acquisition(pass).controller_position_px[0]
                    - a.acquisition(pass).controller_position_px[0];
                let measured = dx_px * PITCH * stretch;
                assert!(
                    close(measured, A, 1e-6 * A),
                    "{} {pass:?}: {measured}",
                    effect.kind()
                );
            }
        }
    }
}

#[test]
fn line_drift_restarts_every_line() {
    let effect = LineDrift {
        velocity_m_per_s: [1e-9, 2e-9],
    };
    let config = base_config();
    let geometry = config.scan.geometry().unwrap();
    for row in [0.0, 50.0, 127.0] {
        let at = AcquisitionContext::at_pixel(&geometry, ScanPass::Trace, 0.0, row, 0.0);
        let d = effect.displacement(&at);
        assert!(close(d.x, 1e-9 * 0.5 * PERIOD, 1e-24) && close(d.y, 2e-9 * 0.5 * PERIOD, 1e-24));
    }
}

#[test]
fn drift_acceleration_and_creep_follow_their_closed_forms() {
    let drift = ThermalDrift {
        velocity_m_per_s: [3e-12, -5e-12],
        acceleration_m_per_s2: [2e-13, 1e-13],
    };
    let creep = LogCreep {
        coefficient_m: [0.1e-9, -0.2e-9],
        t0_s: 5.0,
        start_s: 0.0,
    };
    let output = run(&with_effects(vec![
        EffectConfig::ThermalDrift(drift.clone()),
        EffectConfig::Creep(creep.clone()),
    ]));
    let geometry = output.pair.geometry();
    let expected = |t: f64| {
        let ln = (1.0 + t / 5.0).ln();
        [
            3e-12 * t + 0.5 * 2e-13 * t * t + 0.1e-9 * ln,
            -5e-12 * t + 0.5 * 1e-13 * t * t - 0.2e-9 * ln,
        ]
    };
    for field in &output.truth.displacement {
        for (row, column) in [(0, 0), (0, 127), (64, 3), (127, 127), (100, 40)] {
            let t = geometry
                .acquisition_time(field.pass, column as f64, row as f64)
                .since_frame_start;
            let [ex, ey] = expected(t);
            assert!(
                close(field.dx.z[[row, column]], ex, 1e-21),
                "{:?}",
                field.pass
            );
            assert!(close(field.dy.z[[row, column]], ey, 1e-21));
        }
    }
    for feature in output.truth.imaged_features(ScanPass::Retrace) {
        let a = feature.retrace;
        let [ex, ey] = expected(a.time_since_frame_start_s);
        assert!(close(a.displacement_m[0], ex, 1e-20) && close(a.displacement_m[1], ey, 1e-20));
        // p_sample = p_ctrl + d
        for k in 0..2 {
            assert!(close(
                a.controller_position_m[k] + a.displacement_m[k],
                feature.sample_position_m[k],
                1e-16
            ));
        }
    }
}

#[test]
fn a_second_creep_impulse_and_exponential_creep_start_when_told() {
    let config = base_config();
    let geometry = config.scan.geometry().unwrap();
    let impulse = LogCreep {
        coefficient_m: [0.3e-9, 0.0],
        t0_s: 2.0,
        start_s: 10.0,
    };
    let exponential = ExponentialCreep {
        amplitude_m: [0.0, 0.4e-9],
        time_constant_s: 3.0,
        start_s: 10.0,
    };
    for t in [0.0, 5.0, 9.999, 10.0, 12.0, 30.0] {
        let mut at = AcquisitionContext::at_pixel(&geometry, ScanPass::Trace, 0.0, 0.0, 0.0);
        at.time_since_frame_start = t;
        let elapsed = (t - 10.0).max(0.0);
        let d = impulse.displacement(&at);
        assert!(close(d.x, 0.3e-9 * (1.0 + elapsed / 2.0).ln(), 1e-22) && d.y == 0.0);
        let d = exponential.displacement(&at);
        assert!(close(d.y, 0.4e-9 * (1.0 - (-elapsed / 3.0).exp()), 1e-22) && d.x == 0.0);
    }
    // In an image: features scanned before the impulse are undisplaced.
    let output = run(&with_effects(vec![EffectConfig::Creep(impulse)]));
    for feature in output.truth.imaged_features(ScanPass::Trace) {
        let a = feature.trace;
        if a.time_since_frame_start_s < 10.0 {
            assert_eq!(a.displacement_m, [0.0, 0.0]);
        } else {
            assert!(a.displacement_m[0] > 0.0);
        }
    }
}

#[test]
fn hysteresis_laws_integrate_to_their_closed_forms() {
    let laws = [
        HysteresisLaw::Power { k: 0.93, n: -0.035 },
        HysteresisLaw::Power { k: 1.2, n: 0.4 },
        HysteresisLaw::Exponential {
            amplitude: 0.3,
            time_constant_s: 0.02,
        },
        HysteresisLaw::Quartic {
            coefficients: [0.05, -0.3, 0.6, -0.2, 0.1],
            time_scale_s: 0.128,
        },
    ];
    for law in laws {
        let tau = 0.1;
        // Midpoint rule on a graded grid (the power law is singular at 0).
        let steps = 200_000;
        let mut integral = 0.0;
        for i in 0..steps {
            let (a, b) = (
                tau * (i as f64 / steps as f64).powi(3),
                tau * ((i + 1) as f64 / steps as f64).powi(3),
            );
            integral += (law.scale(0.5 * (a + b)) - 1.0) * (b - a);
        }
        let closed = law.excess_integral(tau);
        assert!(
            close(closed, integral, 1e-6 * tau),
            "{law:?}: {closed} vs {integral}"
        );
        assert_eq!(law.excess_integral(0.0), 0.0);
    }
}

/// Spacing along x (px) of features on one lattice row, ordered by x, for `pass`.
fn fast_spacings(output: &dhct_simulate::SimulationOutput, pass: ScanPass) -> Vec<(f64, f64)> {
    let features = well_inside(output, pass, 1.0);
    neighbour_pairs(&features, false)
        .into_iter()
        .map(|(a, b)| {
            let xa = a.acquisition(pass).controller_position_px[0];
            let xb = b.acquisition(pass).controller_position_px[0];
            (0.5 * (xa + xb), xb - xa)
        })
        .collect()
}

#[test]
fn hysteresis_with_s_above_one_at_line_start_stretches_the_image_there() {
    // S = 1 + 0.3·exp(−τ/τh): 30 % stretch at the line start, relaxing within ~2 atoms.
    let tau_h = 0.15 * LINE;
    let law = HysteresisLaw::Exponential {
        amplitude: 0.3,
        time_constant_s: tau_h,
    };
    let output = run(&with_effects(vec![EffectConfig::FastHysteresis(
        FastScanHysteresis { law: law.clone() },
    )]));
    let nominal = A / PITCH; // 10 px
    for pass in ScanPass::BOTH {
        let spacings = fast_spacings(&output, pass);
        // Line start: left edge for the trace (Right), right edge for the retrace (Left).
        let from_line_start = |x: f64| match pass {
            ScanPass::Trace => x,
            ScanPass::Retrace => 127.0 - x,
        };
        let mean_spacing = |keep: &dyn Fn(f64) -> bool| {
            let chosen: Vec<f64> = spacings
                .iter()
                .filter(|(x, _)| keep(from_line_start(*x)))
                .map(|(_, dx)| *dx)
                .collect();
            chosen.iter().sum::<f64>() / chosen.len() as f64
        };
        let near_mean = mean_spacing(&|from_start| from_start < 25.0);
        let far_mean = mean_spacing(&|from_start| from_start > 80.0);
        assert!(
            near_mean > 1.05 * nominal,
            "{pass:?}: near line start {near_mean} px"
        );
        assert!(
            close(far_mean, nominal, 0.01 * nominal),
            "{pass:?}: far {far_mean} px"
        );
        // Exactly: sample spacing = p·Δx − v·(I(τ_b) − I(τ_a)) along the pass direction.
        for (x_mid, dx) in &spacings {
            let (xa, xb) = (x_mid - 0.5 * dx, x_mid + 0.5 * dx);
            let tau = |x: f64| (from_line_start(x) + 0.5) * PERIOD;
            let lag = law.excess_integral(tau(xb)) - law.excess_integral(tau(xa));
            let sample = match pass {
                ScanPass::Trace => dx * PITCH - SPEED * lag,
                ScanPass::Retrace => dx * PITCH + SPEED * lag,
            };
            assert!(close(sample, A, 1e-6 * A), "{pass:?} at {x_mid}: {sample}");
        }
    }
    // The image agrees: peaks near the trace's line start are farther apart than 10 px.
    let trace = output.pair.trace().unwrap();
    let mut found: Vec<[f64; 2]> = peaks(trace, 25e-12)
        .into_iter()
        .filter(|p| (p[1] - 62.5).abs() < 3.0)
        .collect();
    found.sort_by(|a, b| a[0].total_cmp(&b[0]));
    assert!(found.len() >= 10, "{found:?}");
    let first_gap = found[1][0] - found[0][0];
    assert!(
        first_gap > 1.1 * nominal,
        "first gap {first_gap} px in the image"
    );
}

#[test]
fn retrace_hysteresis_starts_where_the_trace_ended() {
    let config = base_config();
    let geometry = config.scan.geometry().unwrap();
    let line = geometry.line_scan_time();
    let law = HysteresisLaw::Power { k: 0.9, n: -0.05 };
    let other = HysteresisLaw::Exponential {
        amplitude: 0.2,
        time_constant_s: 0.01,
    };
    let context = |pass, tau: f64| {
        let mut at = AcquisitionContext::at_pixel(&geometry, pass, 0.0, 0.0, 0.0);
        at.time_since_line_start = tau;
        at
    };
    let symmetric = FastScanHysteresis { law: law.clone() };
    let asymmetric = AsymmetricHysteresis {
        trace: law.clone(),
        retrace: other.clone(),
    };
    for effect in [&symmetric as &dyn Effect, &asymmetric] {
        let trace_end = effect.displacement(&context(ScanPass::Trace, line));
        let retrace_start = effect.displacement(&context(ScanPass::Retrace, 0.0));
        assert!((trace_end - retrace_start).norm() < 1e-24);
        assert_eq!(
            effect.displacement(&context(ScanPass::Trace, 0.0)).norm(),
            0.0
        );
    }
    // The symmetric loop closes: the retrace ends where the trace starts.
    assert!(
        symmetric
            .displacement(&context(ScanPass::Retrace, line))
            .norm()
            < 1e-24
    );
    // The asymmetric retrace follows its own law: d = −v·(I_t(T) − I_r(τ)) along +x.
    let tau = 0.03;
    let d = asymmetric.displacement(&context(ScanPass::Retrace, tau));
    let expected =
        -geometry.fast_speed() * (law.excess_integral(line) - other.excess_integral(tau));
    assert!(close(d.x, expected, 1e-22) && d.y == 0.0);
}

#[test]
fn slow_hysteresis_stretches_the_first_lines() {
    let law = HysteresisLaw::Exponential {
        amplitude: 0.4,
        time_constant_s: 3.0,
    };
    let output = run(&with_effects(vec![EffectConfig::SlowHysteresis(
        SlowScanHysteresis { law: law.clone() },
    )]));
    let geometry = output.pair.geometry();
    let field = output.truth.displacement_of(ScanPass::Trace).unwrap();
    for (row, column) in [(0, 0), (10, 50), (127, 127)] {
        let t = geometry
            .acquisition_time(ScanPass::Trace, column as f64, row as f64)
            .since_frame_start;
        let expected = -geometry.slow_speed() * law.excess_integral(t);
        assert!(close(field.dy.z[[row, column]], expected, 1e-21));
        assert_eq!(field.dx.z[[row, column]], 0.0);
    }
    let features = well_inside(&output, ScanPass::Trace, 1.0);
    let pairs = neighbour_pairs(&features, true);
    let spacing = |top: bool| {
        let chosen: Vec<f64> = pairs
            .iter()
            .filter(|(a, _)| (a.trace.controller_position_px[1] < 30.0) == top)
            .map(|(a, b)| b.trace.controller_position_px[1] - a.trace.controller_position_px[1])
            .collect();
        chosen.iter().sum::<f64>() / chosen.len() as f64
    };
    assert!(spacing(true) > 1.05 * A / PITCH, "{}", spacing(true));
    assert!(
        close(spacing(false), A / PITCH, 0.03 * A / PITCH),
        "{}",
        spacing(false)
    );
}

#[test]
fn piezo_nonlinearity_depends_on_the_commanded_position_alone() {
    let (q, c) = ([30e-12, -20e-12], [-40e-12, 25e-12]);
    let effect = PiezoNonlinearity {
        quadratic_m: q,
        cubic_m: c,
    };
    let output = run(&with_effects(vec![EffectConfig::PiezoNonlinearity(
        effect.clone(),
    )]));
    let g = output.pair.geometry();
    let (w, h) = (
        (g.columns() as f64 - 1.0) * g.pitch_x(),
        (g.rows() as f64 - 1.0) * g.pitch_y(),
    );
    let curve = |q: f64, c: f64, u: f64| q * (u * u - 1.0 / 3.0) + c * (u * u * u - 0.6 * u);
    let mut checked = 0;
    for f in output.truth.imaged_features(ScanPass::Trace) {
        for a in [&f.trace, &f.retrace].into_iter().filter(|a| a.in_image) {
            let [x, y] = a.controller_position_m;
            let (xi, eta) = (2.0 * x / w - 1.0, 2.0 * y / h - 1.0);
            // The same closed form in trace and retrace: no time, no direction.
            assert!(close(a.displacement_m[0], curve(q[0], c[0], xi), 1e-15));
            assert!(close(a.displacement_m[1], curve(q[1], c[1], eta), 1e-15));
            checked += 1;
        }
    }
    assert!(checked > 100, "{checked}");
    // Mean- and slope-free over a uniform scan; at the edges 2q/3 + 2c/5 (and 2q/3 − 2c/5).
    let n = 10_001;
    let samples: Vec<f64> = (0..n)
        .map(|k| -1.0 + 2.0 * k as f64 / (n - 1) as f64)
        .collect();
    let mean: f64 = samples.iter().map(|&u| curve(1.0, 1.0, u)).sum::<f64>() / n as f64;
    let slope: f64 = samples.iter().map(|&u| u * curve(1.0, 1.0, u)).sum::<f64>() / n as f64;
    assert!(mean.abs() < 1e-3 && slope.abs() < 1e-3, "{mean} {slope}");
    let largest = effect.largest_displacement_m();
    assert!(close(
        largest[0],
        (2.0 * q[0] / 3.0).abs() + (2.0 * c[0] / 5.0).abs(),
        1e-13
    ));
}

#[test]
fn line_jitter_moves_each_line_as_a_whole_by_its_own_offset() {
    let jitter = LineJitter {
        rms_m: [4e-12, 1e-12],
        seed: 3,
    };
    let config = with_effects(vec![EffectConfig::LineJitter(jitter.clone())]);
    let geometry = run(&config).pair.geometry().clone();
    let at = |pass, x: f64, y: f64| {
        jitter.displacement(&AcquisitionContext::at_pixel(&geometry, pass, x, y, 0.0))
    };
    let mut offsets = Vec::new();
    for line in 0..geometry.rows() {
        let y = line as f64;
        let trace = at(ScanPass::Trace, 0.0, y);
        // The same offset all along a line; the retrace of the same line has its own.
        assert_eq!(trace, at(ScanPass::Trace, 77.0, y));
        assert_eq!(trace, at(ScanPass::Trace, 127.0, y));
        let retrace = at(ScanPass::Retrace, 5.0, y);
        assert_eq!(retrace, at(ScanPass::Retrace, 120.0, y));
        assert_ne!(trace, retrace);
        offsets.extend([trace, retrace]);
    }
    let rms =
        |k: usize| (offsets.iter().map(|d| d[k] * d[k]).sum::<f64>() / offsets.len() as f64).sqrt();
    // 256 acquired lines (128 trace, 128 retrace): the sample rms within 15 % of the stated one.
    assert!(close(rms(0), 4e-12, 0.6e-12), "{}", rms(0));
    assert!(close(rms(1), 1e-12, 0.15e-12), "{}", rms(1));
}

#[test]
fn scan_coupling_shears_columns_and_tilts_lines() {
    let (t_sf, t_fs) = (0.05, -0.03);
    let output = run(&with_effects(vec![EffectConfig::ScanCoupling(
        ScanCoupling {
            slow_to_fast: t_sf,
            fast_to_slow: t_fs,
        },
    )]));
    let features = well_inside(&output, ScanPass::Trace, 1.0);
    // x_s = x_c·p + T_sf·(y_c·p − y0) and y_s = y_c·p + T_fs·(x_c·p − x0), solved exactly:
    // along a lattice column (fixed x_s) Δx_c = −T_sf·Δy_c, along a row Δy_c = −T_fs·Δx_c.
    for (a, b) in neighbour_pairs(&features, true) {
        let [xa, ya] = a.trace.controller_position_px;
        let [xb, yb] = b.trace.controller_position_px;
        assert!(close(xb - xa, -t_sf * (yb - ya), 1e-6));
    }
    for (a, b) in neighbour_pairs(&features, false) {
        let [xa, ya] = a.trace.controller_position_px;
        let [xb, yb] = b.trace.controller_position_px;
        assert!(close(yb - ya, -t_fs * (xb - xa), 1e-6));
    }
}

#[test]
fn vibration_shows_a_peak_at_its_frequency_in_the_imaged_feature_positions() {
    let frequency = 0.45;
    let amplitude = 30e-12; // 0.6 px
    let output = run(&with_effects(vec![EffectConfig::Vibration(Vibration {
        frequency_hz: frequency,
        amplitude_m: [amplitude, 0.0],
        phase_rad: [0.3, 0.0],
    })]));
    // Displacement of each feature as measured from the image: true position minus the
    // image peak position, against the truth's acquisition time.
    let mut samples = Vec::new();
    for pass in ScanPass::BOTH {
        let found = peaks(output.pair.image(pass).unwrap(), 25e-12);
        for feature in well_inside(&output, pass, 3.0) {
            let a = feature.acquisition(pass);
            let peak = found
                .iter()
                .min_by(|p, q| {
                    let d = |r: &[f64; 2]| {
                        (r[0] - a.controller_position_px[0]).powi(2)
                            + (r[1] - a.controller_position_px[1]).powi(2)
                    };
                    d(p).total_cmp(&d(q))
                })
                .unwrap();
            samples.push((
                a.time_since_frame_start_s,
                feature.sample_position_m[0] - peak[0] * PITCH,
            ));
        }
    }
    assert!(samples.len() > 150, "{}", samples.len());
    let power = |f: f64| {
        let (mut re, mut im) = (0.0, 0.0);
        for (t, d) in &samples {
            re += d * (TAU * f * t).cos();
            im -= d * (TAU * f * t).sin();
        }
        2.0 * (re * re + im * im).sqrt() / samples.len() as f64
    };
    let (best, best_amplitude) = (1..=300)
        .map(|i| i as f64 * 0.01)
        .map(|f| (f, power(f)))
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap();
    assert!(close(best, frequency, 0.02), "peak at {best} Hz");
    assert!(
        close(best_amplitude, amplitude, 0.25 * amplitude),
        "{best_amplitude}"
    );
}

#[test]
fn tip_change_jumps_and_changes_contrast_from_its_time_on() {
    let config = base_config();
    let frame = config.scan.geometry().unwrap().frame_duration();
    let jump = [50e-12, -50e-12]; // whole pixels, so atoms stay pixel-centred
    let output = run(&with_effects(vec![EffectConfig::TipChange(TipChange {
        time_s: 0.5 * frame,
        jump_m: jump,
        height_offset_m: 0.0,
        contrast: 2.0,
    })]));
    let mut before = 0;
    let mut after = 0;
    for feature in output.truth.imaged_features(ScanPass::Trace) {
        let a = feature.trace;
        if a.time_since_frame_start_s < 0.5 * frame - 0.1 {
            assert_eq!(a.displacement_m, [0.0, 0.0]);
            before += 1;
        } else if a.time_since_frame_start_s > 0.5 * frame + 0.1 {
            assert_eq!(a.displacement_m, jump);
            after += 1;
        }
    }
    assert!(before > 50 && after > 50);
    let trace = output.pair.trace().unwrap();
    let top = trace
        .z
        .slice(ndarray::s![..60, ..])
        .fold(0.0f64, |m, &v| m.max(v));
    let bottom = trace
        .z
        .slice(ndarray::s![68.., ..])
        .fold(0.0f64, |m, &v| m.max(v));
    assert!(close(bottom / top, 2.0, 1e-9), "{top} {bottom}");
}

#[test]
fn height_coupling_shifts_the_upper_terrace() {
    let mut config = with_effects(vec![EffectConfig::HeightCoupling(HeightCoupling {
        lateral_per_height: [0.05, 0.0],
    })]);
    let step = 1e-9;
    config.surface.steps.push(StepEdge {
        region: Region::HalfPlane {
            point_m: [0.0, 3.2e-9],
            normal: [0.0, 1.0],
        },
        height_m: step,
    });
    let output = run(&config);
    let mut upper = 0;
    for feature in output.truth.imaged_features(ScanPass::Trace) {
        let d = feature.trace.displacement_m;
        if feature.sample_position_m[1] > 3.3e-9 {
            assert!(close(d[0], 0.05 * step, 1e-18), "{d:?}");
            upper += 1;
        } else if feature.sample_position_m[1] < 3.1e-9 {
            assert_eq!(d[0], 0.0);
        }
        assert_eq!(d[1], 0.0);
    }
    assert!(upper > 50);
}

#[test]
fn raster_and_ground_truth_agree_under_combined_effects() {
    let output = run(&with_effects(vec![
        EffectConfig::ThermalDrift(ThermalDrift {
            velocity_m_per_s: [15e-12, -25e-12],
            acceleration_m_per_s2: [0.5e-12, 0.2e-12],
        }),
        EffectConfig::Creep(LogCreep {
            coefficient_m: [0.2e-9, 0.3e-9],
            t0_s: 4.0,
            start_s: 0.0,
        }),
        EffectConfig::FastHysteresis(FastScanHysteresis {
            law: HysteresisLaw::Power { k: 0.9, n: -0.04 },
        }),
        EffectConfig::ScanCoupling(ScanCoupling {
            slow_to_fast: 0.02,
            fast_to_slow: 0.01,
        }),
    ]));
    for pass in ScanPass::BOTH {
        let found = peaks(output.pair.image(pass).unwrap(), 25e-12);
        let features = well_inside(&output, pass, 3.0);
        assert!(features.len() > 80);
        for feature in features {
            let a = feature.acquisition(pass);
            let miss = nearest_distance(&found, a.controller_position_px);
            assert!(
                miss < 0.05,
                "{pass:?}: feature {} off by {miss} px",
                feature.index
            );
        }
    }
}

#[test]
fn every_effect_keeps_the_effect_contract() {
    let effects: Vec<Box<dyn Effect>> = vec![
        Box::new(ThermalDrift {
            velocity_m_per_s: [1e-12, 2e-12],
            acceleration_m_per_s2: [3e-15, 4e-15],
        }),
        Box::new(LineDrift {
            velocity_m_per_s: [1e-12, 2e-12],
        }),
        Box::new(LogCreep {
            coefficient_m: [1e-10, 2e-10],
            t0_s: 3.0,
            start_s: 1.0,
        }),
        Box::new(ExponentialCreep {
            amplitude_m: [1e-10, 2e-10],
            time_constant_s: 3.0,
            start_s: 1.0,
        }),
        Box::new(FastScanHysteresis {
            law: HysteresisLaw::Quartic {
                coefficients: [0.1, 0.2, 0.3, 0.4, 0.5],
                time_scale_s: 0.1,
            },
        }),
        Box::new(AsymmetricHysteresis {
            trace: HysteresisLaw::Power { k: 0.9, n: -0.1 },
            retrace: HysteresisLaw::Exponential {
                amplitude: 0.1,
                time_constant_s: 0.01,
            },
        }),
        Box::new(SlowScanHysteresis {
            law: HysteresisLaw::Exponential {
                amplitude: 0.1,
                time_constant_s: 2.0,
            },
        }),
        Box::new(ScanCoupling {
            slow_to_fast: 0.01,
            fast_to_slow: 0.02,
        }),
        Box::new(HeightCoupling {
            lateral_per_height: [0.01, 0.02],
        }),
        Box::new(LineJitter {
            rms_m: [1e-12, 2e-12],
            seed: 9,
        }),
        Box::new(Vibration {
            frequency_hz: 50.0,
            amplitude_m: [1e-12, 2e-12],
            phase_rad: [0.1, 0.2],
        }),
        Box::new(TipChange {
            time_s: 5.0,
            jump_m: [1e-10, 0.0],
            height_offset_m: 1e-11,
            contrast: 1.5,
        }),
        Box::new(PiezoNonlinearity {
            quadratic_m: [1e-11, -2e-11],
            cubic_m: [3e-11, 4e-11],
        }),
        Box::new(SessionDrift {
            velocity_m_per_s: [3e-12, -2e-12],
            acceleration_m_per_s2: [1e-15, 0.0],
            oscillation_m: [2e-10, 1e-10],
            oscillation_period_s: 900.0,
            frame_start_s: 88.0,
            scan_angle_rad: 0.5,
        }),
        Box::new(ScannerGain {
            gain: [1.02, 0.97],
            scan_angle_rad: 0.3,
        }),
    ];
    assert_eq!(
        effects.len(),
        15,
        "one per effect type (telegraph tip and strain bubble aside)"
    );
    for effect in effects {
        let parameters = effect.parameters();
        assert_eq!(
            parameters.len(),
            effect.parameter_names().len(),
            "{}",
            effect.name()
        );
        let copy = effect.with_parameters(&parameters).unwrap();
        assert_eq!(copy.config(), effect.config());
        assert_eq!(effect.config().kind(), effect.name());
        let shifted: Vec<f64> = parameters.iter().map(|p| p * 1.01).collect();
        assert_eq!(
            effect.with_parameters(&shifted).unwrap().parameters(),
            shifted
        );
        assert!(effect.with_parameters(&parameters[1..]).is_err());
        displaces_finitely_and_rebuilds_from_its_config(effect.as_ref());
    }
}

/// The rest of the contract every effect keeps: a finite displacement at every pixel of a
/// frame in both passes, the same displacement from the effect rebuilt from its config
/// entry, and a config entry that survives JSON.
fn displaces_finitely_and_rebuilds_from_its_config(effect: &dyn Effect) {
    let geometry = dhct_scan::ScanGeometry::new(
        16,
        12,
        1e-10,
        1e-10,
        1e-3,
        dhct_scan::ScanDirection::Right,
        dhct_scan::ScanDirection::Down,
    )
    .unwrap();
    let config = effect.config();
    let json = serde_json::to_string(&config).unwrap();
    let back: EffectConfig = serde_json::from_str(&json).unwrap();
    assert_eq!(back, config, "{}", effect.name());
    let rebuilt = config.build("effects[0]").unwrap();
    for pass in [ScanPass::Trace, ScanPass::Retrace] {
        for r in 0..12 {
            for c in 0..16 {
                let at = AcquisitionContext::at_pixel(&geometry, pass, c as f64, r as f64, 1e-10);
                let d = effect.displacement(&at);
                assert!(
                    d.iter().all(|v| v.is_finite()),
                    "{} at {c}, {r}",
                    effect.name()
                );
                assert_eq!(
                    rebuilt.displacement(&at),
                    d,
                    "{} at {c}, {r}",
                    effect.name()
                );
            }
        }
    }
}
