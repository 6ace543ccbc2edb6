//! Image sequences: drift continuous over the session in the instrument frame, the same
//! surface in every frame whatever the scan angle and offset, refusals naming the field,
//! and the files (start time, scan angle and offset read back from the SM4).

mod common;

use common::base_config;
use dhct_scan::{ScanGeometry, ScanPass};
use dhct_simulate::effects::{FastScanHysteresis, ScanCoupling, ThermalDrift};
use dhct_simulate::sequence::{
    CreepConfig, DriftConfig, MoveConfig, SEQUENCE_TRUTH_FILE, SequenceConfig,
};
use dhct_simulate::surface::FeatureKind;
use dhct_simulate::{
    EffectConfig, HysteresisLaw, LatticeConfig, OutputFormat, Region, SequenceSimulation,
    SequenceTruth, Simulation, SimulationConfig, SimulationError, StepEdge,
};
use nalgebra::{Matrix2, Vector2};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Lattice constants of the test surface: a rectangular lattice has no symmetry that hides
/// a wrong rotation by 30°.
const A_M: f64 = 0.5e-9;
const B_M: f64 = 0.7e-9;

/// A 4-frame sequence of `size`² px at 62.5 pm (features 8 and 11.2 px apart), 50 nm/s,
/// with hysteresis and coupling in the raster frame, scan angles 0°, 90°, 30°, 0°, drift
/// with an oscillation, initial creep and a move with creep before frame 2.
fn sequence_config(size: usize) -> SimulationConfig {
    let mut config = base_config();
    config.scan.columns = size;
    config.scan.rows = size;
    config.scan.width_m = size as f64 * 62.5e-12;
    config.scan.height_m = size as f64 * 62.5e-12;
    config.surface.lattice = LatticeConfig::Rectangular { a_m: A_M, b_m: B_M };
    config.surface.angle_rad = 0.3;
    config.surface.origin_m = [0.11e-9, -0.07e-9];
    config.surface.feature.sigma_m = [0.1e-9, 0.1e-9];
    config.effects = vec![
        EffectConfig::FastHysteresis(FastScanHysteresis {
            law: HysteresisLaw::Power { k: 0.95, n: -0.03 },
        }),
        EffectConfig::ScanCoupling(ScanCoupling {
            slow_to_fast: 0.01,
            fast_to_slow: -0.005,
        }),
    ];
    config.sequence = Some(SequenceConfig {
        frames: 4,
        pause_s: 2.5,
        start_unix_s: 1_800_000_000,
        scan_angles_deg: vec![0.0, 90.0, 30.0],
        offset_m: [0.2e-9, 0.1e-9],
        drift: DriftConfig {
            velocity_m_per_s: [20e-12, -10e-12],
            acceleration_m_per_s2: [1e-13, 2e-13],
            oscillation_m: [0.1e-9, 0.05e-9],
            oscillation_period_s: Some(30.0),
        },
        initial_creep: Some(CreepConfig {
            coefficient_m: [0.1e-9, 0.05e-9],
            t0_s: 5.0,
        }),
        scanner_gain: [1.0, 1.0],
        moves: vec![MoveConfig {
            before_frame: 2,
            offset_m: [0.6e-9, -0.4e-9],
            creep: Some(CreepConfig {
                coefficient_m: [0.15e-9, -0.1e-9],
                t0_s: 3.0,
            }),
        }],
    });
    config
}

/// `T_k`, from the convention: each start the pause after the previous end, rounded up.
fn frame_start(config: &SimulationConfig, k: usize) -> f64 {
    let duration = config.scan.geometry().unwrap().frame_duration();
    let pause = config.sequence.as_ref().unwrap().pause_s;
    let mut t = 0.0;
    for _ in 0..k {
        t = f64::ceil(t + duration + pause);
    }
    t
}

/// `D(T)` written out from the config, independently of the library.
fn session_drift(config: &SimulationConfig, t: f64) -> [f64; 2] {
    let s = config.sequence.as_ref().unwrap();
    let d = &s.drift;
    let period = d.oscillation_period_s.unwrap();
    let mut out = [0.0; 2];
    for (i, value) in out.iter_mut().enumerate() {
        *value = d.velocity_m_per_s[i] * t
            + 0.5 * d.acceleration_m_per_s2[i] * t * t
            + d.oscillation_m[i] * (2.0 * std::f64::consts::PI * t / period).sin();
    }
    let mut creeps: Vec<(f64, &CreepConfig)> = s.initial_creep.iter().map(|c| (0.0, c)).collect();
    for m in &s.moves {
        if let Some(c) = &m.creep {
            creeps.push((frame_start(config, m.before_frame), c));
        }
    }
    for (start, creep) in creeps {
        if t > start {
            for (i, value) in out.iter_mut().enumerate() {
                *value += creep.coefficient_m[i] * (1.0 + (t - start) / creep.t0_s).ln();
            }
        }
    }
    out
}

fn add(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] + b[0], a[1] + b[1]]
}

fn distance(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

/// The base config alone (no sequence): the raster-frame displacement `d_raster`.
fn raster_only(config: &SimulationConfig) -> Simulation {
    let mut base = config.clone();
    base.sequence = None;
    Simulation::from_config(&base).unwrap()
}

#[test]
fn the_tip_follows_the_session_drift_in_the_instrument_frame() {
    let config = sequence_config(48);
    let sequence = SequenceSimulation::from_config(&config).unwrap();
    let raster = raster_only(&config);
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    for k in 0..4 {
        let start = frame_start(&config, k);
        let placement = sequence.placement(k).unwrap();
        assert_eq!(placement.start_s, start, "frame {k}");
        let frame = sequence.frame_simulation(k).unwrap();
        let g = frame.geometry();
        assert_eq!(g.start_time(), Some(1_800_000_000.0 + start));
        let mut pixels: Vec<(f64, f64)> = (0..40)
            .map(|_| (rng.random::<f64>() * 47.0, rng.random::<f64>() * 47.0))
            .collect();
        pixels.push((47.0, 47.0)); // the last pixel of the frame
        for (x, y) in pixels {
            for pass in ScanPass::BOTH {
                let p = [x * g.pitch_x(), y * g.pitch_y()];
                let d = frame.displacement(pass, x, y);
                let simulated = add(
                    g.to_instrument([p[0] + d.x, p[1] + d.y]),
                    session_drift(&config, start),
                );
                let t = g.acquisition_time(pass, x, y).since_frame_start;
                let r = raster.displacement(pass, x, y);
                let expected = add(
                    g.to_instrument([p[0] + r.x, p[1] + r.y]),
                    session_drift(&config, start + t),
                );
                let error = distance(simulated, expected);
                assert!(error < 1e-15, "frame {k} ({x}, {y}) {pass:?}: {error:e} m");
            }
        }
    }
}

#[test]
fn the_drift_runs_on_across_frame_boundaries() {
    // The end of frame k and the start of frame k+1 lie on one continuous D(T): the tip of
    // the next frame at t = 0 is displaced by D(T_{k+1}), and the truth's trajectory
    // samples D between frames too.
    let config = sequence_config(32);
    let sequence = SequenceSimulation::from_config(&config).unwrap();
    for k in 0..4 {
        let placement = sequence.placement(k).unwrap();
        let want = session_drift(&config, placement.start_s);
        assert!(distance(placement.displacement_at_start_m, want) < 1e-20);
    }
    let truth = sequence.truth(Vec::new());
    let end = frame_start(&config, 3) + config.scan.geometry().unwrap().frame_duration();
    assert_eq!(truth.trajectory.first().unwrap().t_s, 0.0);
    assert_eq!(truth.trajectory.last().unwrap().t_s, end);
    assert!(truth.trajectory.len() >= end as usize);
    for sample in &truth.trajectory {
        let want = session_drift(&config, sample.t_s);
        assert!(
            distance([sample.x_m, sample.y_m], want) < 1e-20,
            "{sample:?}"
        );
    }
    assert_eq!(truth.trajectory[0].x_m, 0.0);
}

/// The common (instrument-frame) position of lattice site `(n, m)`, from the config alone.
fn common_site(config: &SimulationConfig, n: i64, m: i64) -> [f64; 2] {
    let lattice = config.surface.lattice.build().unwrap();
    let [a1, a2] = lattice.primitive_vectors();
    let (s, c) = config.surface.angle_rad.sin_cos();
    let rotation = Matrix2::new(c, -s, s, c); // surface.rs: from +x towards +y
    let o = config.surface.origin_m;
    let r = rotation * (a1 * n as f64 + a2 * m as f64) + Vector2::new(o[0], o[1]);
    [r.x, r.y]
}

/// The peak nearest `at` (pixels): the brightest pixel within 3 px, refined by a parabola
/// through it and its neighbours along each axis.
fn peak_near(z: &ndarray::Array2<f64>, at: [f64; 2]) -> [f64; 2] {
    let (rows, columns) = z.dim();
    let mut best = (f64::NEG_INFINITY, (0, 0));
    for row in 1..rows - 1 {
        for column in 1..columns - 1 {
            let p = [column as f64, row as f64];
            if distance(p, at) <= 3.0 && z[[row, column]] > best.0 {
                best = (z[[row, column]], (row, column));
            }
        }
    }
    let (row, column) = best.1;
    let vertex =
        |minus: f64, centre: f64, plus: f64| 0.5 * (minus - plus) / (minus - 2.0 * centre + plus);
    [
        column as f64 + vertex(z[[row, column - 1]], z[[row, column]], z[[row, column + 1]]),
        row as f64 + vertex(z[[row - 1, column]], z[[row, column]], z[[row + 1, column]]),
    ]
}

#[test]
fn every_frame_shows_the_same_surface_where_the_truth_says() {
    let config = sequence_config(64);
    let sequence = SequenceSimulation::from_config(&config).unwrap();
    let output = sequence.run().unwrap();
    let mut seen: std::collections::BTreeMap<(i64, i64), Vec<usize>> = Default::default();
    for (k, (frame, truth)) in output.frames.iter().zip(&output.truth.frames).enumerate() {
        assert_eq!(truth.placement.index, k);
        let trace = &frame.pair.trace().unwrap().z;
        let mut checked = 0;
        for feature in truth.imaged_features(ScanPass::Trace) {
            let FeatureKind::LatticeSite { n, m, .. } = feature.kind else {
                panic!("only lattice sites");
            };
            // The truth's common position is the config's lattice site, in every frame.
            let error = distance(feature.instrument_position_m, common_site(&config, n, m));
            assert!(error < 1e-15, "frame {k} site ({n}, {m}): {error:e} m");
            seen.entry((n, m)).or_default().push(k);
            // The image shows the feature at the truth's controller position.
            let at = feature.trace.controller_position_px;
            if at.iter().all(|v| (4.0..59.0).contains(v)) {
                let peak = peak_near(trace, at);
                assert!(
                    distance(peak, at) < 0.25,
                    "frame {k} site ({n}, {m}): peak at {peak:?}, truth {at:?}"
                );
                checked += 1;
            }
        }
        assert!(checked >= 15, "frame {k}: {checked} features checked");
    }
    // Sites seen in frame 0 and in the 90° frame, the 30° frame after the move and the
    // last frame.
    for k in 1..4 {
        let shared = seen
            .values()
            .filter(|f| f.contains(&0) && f.contains(&k))
            .count();
        assert!(
            shared >= 10,
            "frame {k}: {shared} sites shared with frame 0"
        );
    }
}

#[test]
fn a_frame_is_placed_by_its_scan_angle_offset_and_start() {
    let config = sequence_config(32);
    let sequence = SequenceSimulation::from_config(&config).unwrap();
    let expected = [
        (0.0, [0.2e-9, 0.1e-9]),
        (90.0, [0.2e-9, 0.1e-9]),
        (30.0, [0.6e-9, -0.4e-9]),
        (0.0, [0.6e-9, -0.4e-9]),
    ];
    for (k, (angle, offset)) in expected.into_iter().enumerate() {
        let placement = sequence.placement(k).unwrap();
        assert_eq!(placement.scan_angle_rad, f64::to_radians(angle));
        assert_eq!(placement.offset_m, offset);
        let g: ScanGeometry = sequence.frame_simulation(k).unwrap().geometry().clone();
        assert_eq!(g.scan_angle(), f64::to_radians(angle));
        assert_eq!(g.offset(), (offset[0], offset[1]));
        assert_eq!(
            placement.start_unix_s,
            1_800_000_000 + frame_start(&config, k) as i64
        );
    }
    assert!(sequence.placement(4).is_err());
    // The creep of the move restarts at frame 2's start: frame 2 carries one creep more.
    let creeps = |k: usize| {
        let frame = sequence.frame_simulation(k).unwrap();
        frame
            .effects()
            .iter()
            .filter(|e| e.name() == "creep")
            .count()
    };
    assert_eq!((creeps(0), creeps(1), creeps(2), creeps(3)), (1, 1, 2, 2));
}

fn field_of(error: SimulationError) -> String {
    match error {
        SimulationError::InvalidConfig { field, .. } => field,
        other => panic!("not a config error: {other}"),
    }
}

#[test]
fn drift_in_the_base_config_and_per_frame_surfaces_are_refused() {
    let mut config = sequence_config(32);
    config
        .effects
        .push(EffectConfig::ThermalDrift(ThermalDrift {
            velocity_m_per_s: [1e-12, 0.0],
            acceleration_m_per_s2: [0.0, 0.0],
        }));
    let error = SequenceSimulation::from_config(&config).unwrap_err();
    assert!(error.to_string().contains("sequence.drift"), "{error}");
    assert_eq!(field_of(error), "effects[2]");

    let mut config = sequence_config(32);
    config.surface.steps = vec![StepEdge {
        region: Region::HalfPlane {
            point_m: [1e-9, 0.0],
            normal: [1.0, 0.0],
        },
        height_m: 3.35e-10,
    }];
    assert_eq!(field_of(config.validate().unwrap_err()), "surface.steps");

    let mut config = sequence_config(32);
    config.surface.defects.adatom_count = 3;
    let error = SequenceSimulation::from_config(&config).unwrap_err();
    assert_eq!(field_of(error), "surface.defects.adatom_count");
}

/// A change to a sequence table.
type Edit = fn(&mut SequenceConfig);

#[test]
fn bad_sequence_values_are_refused_naming_the_field() {
    let cases: [(&str, Edit); 7] = [
        ("sequence.frames", |s| s.frames = 1),
        ("sequence.frames", |s| s.frames = 1001),
        ("sequence.moves[0].before_frame", |s| {
            s.moves[0].before_frame = 0
        }),
        ("sequence.moves[0].before_frame", |s| {
            s.moves[0].before_frame = 4
        }),
        ("sequence.pause_s", |s| s.pause_s = f64::NAN),
        ("sequence.drift.oscillation_period_s", |s| {
            s.drift.oscillation_period_s = None
        }),
        ("sequence.start_unix_s", |s| s.start_unix_s = 3_200_000_000),
    ];
    for (field, edit) in cases {
        let mut config = sequence_config(32);
        edit(config.sequence.as_mut().unwrap());
        let error = SequenceSimulation::from_config(&config).unwrap_err();
        assert_eq!(field_of(error), field);
    }
    let mut config = sequence_config(32);
    let s = config.sequence.as_mut().unwrap();
    s.moves.push(s.moves[0].clone());
    let error = SequenceSimulation::from_config(&config).unwrap_err();
    assert_eq!(field_of(error), "sequence.moves[1].before_frame");
    let mut config = sequence_config(32);
    config.sequence = None;
    assert_eq!(
        field_of(SequenceSimulation::from_config(&config).unwrap_err()),
        "sequence"
    );
}

#[test]
fn the_sequence_table_parses_from_toml() {
    let mut base = base_config();
    base.surface.feature.height_m = 40e-12;
    let text = format!(
        "{}\n{}",
        base.to_toml_string().unwrap(),
        r#"
[sequence]
frames = 12
pause_s = 3.0
start_unix_s = 1800000000
scan_angles_deg = [0.0, 90.0]
offset_m = [0.0, 0.0]
drift = { velocity_m_per_s = [3e-12, -2e-12], acceleration_m_per_s2 = [1e-15, 0.0], oscillation_m = [2e-10, 1e-10], oscillation_period_s = 900.0 }
initial_creep = { coefficient_m = [1e-10, 5e-11], t0_s = 20.0 }
[[sequence.moves]]
before_frame = 6
offset_m = [2e-9, -1e-9]
creep = { coefficient_m = [2e-10, -1e-10], t0_s = 5.0 }
"#
    );
    let config = SimulationConfig::from_toml_str(&text).unwrap();
    config.validate().unwrap();
    let s = config.sequence.as_ref().unwrap();
    assert_eq!(
        (s.frames, s.moves.len(), s.scan_angle_rad(3)),
        (12, 1, 90f64.to_radians())
    );
    let round_trip = SimulationConfig::from_toml_str(&config.to_toml_string().unwrap()).unwrap();
    assert_eq!(round_trip, config);
    let sequence = SequenceSimulation::from_config(&config).unwrap();
    assert_eq!(sequence.frame_count(), 12);
    assert_eq!(sequence.sequence().offset_of_frame(5), [0.0, 0.0]);
    assert_eq!(sequence.sequence().offset_of_frame(6), [2e-9, -1e-9]);
}

#[test]
fn a_written_sequence_reads_back_with_its_times_angles_and_offsets() {
    let mut config = sequence_config(32);
    config.sequence.as_mut().unwrap().frames = 3;
    config.output.formats = vec![OutputFormat::Sm4, OutputFormat::Gsf];
    let sequence = SequenceSimulation::from_config(&config).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let mut reported = Vec::new();
    let written = sequence
        .write(dir.path(), |frame, _| reported.push(frame.placement.index))
        .unwrap();
    assert_eq!(reported, [0, 1, 2]);
    for name in [
        "frame_00.sm4",
        "frame_01.sm4",
        "frame_02.sm4",
        "frame_01_trace.gsf",
        "frame_02_retrace.gsf",
        SEQUENCE_TRUTH_FILE,
    ] {
        assert!(dir.path().join(name).is_file(), "{name} missing");
        assert!(
            written.iter().any(|p| p.ends_with(name)),
            "{name} not reported"
        );
    }
    assert!(
        !dir.path()
            .join("frame_00_displacement_trace_dx.npy")
            .exists()
    );

    let file = dhct_sm4_io::read_path(&dir.path().join("frame_01.sm4")).unwrap();
    let pair = file.topography().unwrap();
    let g = pair.geometry();
    let start = 1_800_000_000.0 + frame_start(&config, 1);
    assert_eq!(g.start_time(), Some(start));
    assert!(
        (g.scan_angle() - 90f64.to_radians()).abs() < 1e-6,
        "{}",
        g.scan_angle()
    );
    let (x, y) = g.offset();
    assert!(
        (x - 0.2e-9).abs() < 1e-15 && (y - 0.1e-9).abs() < 1e-15,
        "{x} {y}"
    );
    assert!(pair.retrace().is_some());

    let text = std::fs::read_to_string(dir.path().join(SEQUENCE_TRUTH_FILE)).unwrap();
    let truth: SequenceTruth = serde_json::from_str(&text).unwrap();
    assert_eq!(truth.frames.len(), 3);
    assert_eq!(truth.frames[1].placement.start_unix_s as f64, start);
    assert!(!truth.frames[2].features.is_empty());
    // Running in memory gives the same truth as the streaming writer.
    let output = sequence.run().unwrap();
    assert_eq!(
        serde_json::to_string_pretty(&output.truth).unwrap() + "\n",
        text
    );
}
