//! `dhct series` on simulated sequences with known truth: every frame registered into one
//! sample frame within the single-frame localisation floor, frames against each other within
//! 0.02 px, the shared hysteresis far better fixed than by one frame; and the inputs a
//! series cannot be made of refused.

#[allow(dead_code)]
mod common;

use std::path::Path;

use common::dhct;
use dhct_simulate::{SequenceSimulation, SequenceTruth, presets};

/// Simulates `config` into `dir`; returns the truth.
fn simulate(config: &dhct_simulate::SimulationConfig, dir: &Path) -> SequenceTruth {
    let simulation = SequenceSimulation::from_config(config).expect("a valid sequence");
    simulation.write(dir, |_, _| {}).expect("written");
    let text = std::fs::read_to_string(dir.join("sequence_truth.json")).expect("truth");
    serde_json::from_str(&text).expect("truth parses")
}

/// `dhct series PATTERN -o OUT --quiet ARGS…`.
fn series(pattern: &str, out: &Path, args: &[&str]) -> std::process::Output {
    dhct()
        .arg("series")
        .arg(pattern)
        .arg("-o")
        .arg(out)
        .arg("--quiet")
        .args(args)
        .output()
        .expect("dhct runs")
}

/// One found feature: frame, pass, raw pixel position, registered session position.
struct Registered {
    frame: usize,
    pass: String,
    px: [f64; 2],
    session_m: [f64; 2],
}

fn read_features(path: &Path) -> Vec<Registered> {
    let mut reader = csv::Reader::from_path(path).expect("features.csv");
    reader
        .records()
        .map(|r| {
            let r = r.expect("a row");
            let num = |k: usize| r[k].parse::<f64>().expect("a number");
            Registered {
                frame: r[0].parse().expect("frame"),
                pass: r[1].to_string(),
                px: [num(2), num(3)],
                session_m: [num(6), num(7)],
            }
        })
        .collect()
}

/// One frame and pass: its index, and the localisation and registration error (pixels)
/// of every found feature matched to its true site.
type FrameErrors = (usize, Vec<[f64; 2]>, Vec<[f64; 2]>);

/// Per frame and pass: (localisation error, registration error) of each found feature
/// matched to its true site (within 1 px of where the truth says it was imaged), pixels.
fn errors(truth: &SequenceTruth, found: &[Registered]) -> Vec<FrameErrors> {
    let pitch = truth.frames[0].geometry.pitch_x();
    let mut out = Vec::new();
    for (k, frame) in truth.frames.iter().enumerate() {
        for pass in ["trace", "retrace"] {
            let (mut local, mut registered) = (Vec::new(), Vec::new());
            for f in found.iter().filter(|f| f.frame == k && f.pass == pass) {
                let best = frame
                    .features
                    .iter()
                    .filter_map(|t| {
                        let a = if pass == "trace" {
                            &t.trace
                        } else {
                            &t.retrace
                        };
                        let d = [
                            f.px[0] - a.controller_position_px[0],
                            f.px[1] - a.controller_position_px[1],
                        ];
                        (a.in_image && d[0].hypot(d[1]) < 1.0)
                            .then_some((d, t.instrument_position_m))
                    })
                    .min_by(|a, b| a.0[0].hypot(a.0[1]).total_cmp(&b.0[0].hypot(b.0[1])));
                if let Some((d, site)) = best {
                    local.push(d);
                    registered.push([
                        (f.session_m[0] - site[0]) / pitch,
                        (f.session_m[1] - site[1]) / pitch,
                    ]);
                }
            }
            out.push((k, local, registered));
        }
    }
    out
}

fn mean(v: &[[f64; 2]]) -> [f64; 2] {
    let n = v.len().max(1) as f64;
    let s = v.iter().fold([0.0; 2], |a, d| [a[0] + d[0], a[1] + d[1]]);
    [s[0] / n, s[1] / n]
}

fn rms_about(v: &[[f64; 2]], centre: [f64; 2]) -> f64 {
    let n = v.len().max(1) as f64;
    (v.iter()
        .map(|d| (d[0] - centre[0]).powi(2) + (d[1] - centre[1]).powi(2))
        .sum::<f64>()
        / n)
        .sqrt()
}

#[test]
fn a_simulated_session_registers_every_frame_within_the_localisation_floor() {
    let dir = tempfile::tempdir().expect("tempdir");
    let frames = dir.path().join("frames");
    let truth = simulate(&presets::graphite_sequence(), &frames);
    let out = dir.path().join("out");
    let pattern = frames.join("*.sm4");
    let run = series(pattern.to_str().expect("utf-8"), &out, &[]);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let found = read_features(&out.join("features.csv"));
    let per_frame = errors(&truth, &found);
    // The session frame is defined up to one translation (the lattice has no origin of its
    // own): the mean over every frame is taken out, nothing per frame.
    let all: Vec<[f64; 2]> = per_frame.iter().flat_map(|(_, _, r)| r.clone()).collect();
    let global = mean(&all);
    for (k, local, registered) in &per_frame {
        assert!(
            registered.len() > 150,
            "frame {k}: {} matched",
            registered.len()
        );
        let floor = rms_about(local, [0.0; 2]);
        let error = rms_about(registered, global);
        assert!(
            error <= 1.2 * floor,
            "frame {k}: registered {error:.4} px against a floor of {floor:.4} px"
        );
        let offset = mean(registered);
        let between = (offset[0] - global[0]).hypot(offset[1] - global[1]);
        assert!(
            between <= 0.02,
            "frame {k}: {between:.4} px from the others"
        );
    }
    // The shared hysteresis, fitted to every frame, against the best single frame's σ.
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("series.json")).expect("json"))
            .expect("parses");
    for name in ["k", "n"] {
        let sigma_of = |list: &serde_json::Value| {
            list.as_array()
                .expect("parameters")
                .iter()
                .find(|p| p["name"] == name)
                .and_then(|p| p["sigma"].as_f64())
                .expect("a determined parameter")
        };
        let series_sigma = sigma_of(&summary["fit"]["parameters"]);
        let best_frame = summary["frames"]
            .as_array()
            .expect("frames")
            .iter()
            .map(|f| sigma_of(&f["own_hysteresis"]))
            .fold(f64::INFINITY, f64::min);
        assert!(
            series_sigma <= 0.5 * best_frame,
            "{name}: σ {series_sigma:e} in the series, {best_frame:e} in the best frame"
        );
    }
    // Every registered image shows the lattice given when its FFT is measured, as an
    // outsider would check it; nothing is flagged in a session the model holds.
    for (k, frame) in summary["frames"]
        .as_array()
        .expect("frames")
        .iter()
        .enumerate()
    {
        let checks = frame["registered_checks"].as_array().expect("checks");
        assert_eq!(checks.len(), 2, "frame {k}: {checks:?}");
        for c in checks {
            for scale in c["calibration"]["scale"].as_array().expect("scale") {
                let scale = scale.as_f64().expect("number");
                assert!((scale - 1.0).abs() <= 0.015, "frame {k}: {c}");
            }
        }
    }
    assert!(
        summary["mean_check"].is_object(),
        "{}",
        summary["mean_check"]
    );
    assert_eq!(summary["warnings"], serde_json::json!([]));
    let report = std::fs::read_to_string(out.join("report.html")).expect("report");
    assert!(report.contains("Drift over the session") && report.contains("No warning"));
    for file in [
        "trajectory.csv",
        "registered/stack.tif",
        "registered/mean.gsf",
        "registered/frame_11_retrace.gsf",
        "report.html",
        "trajectory_x.svg",
        "mean.png",
    ] {
        assert!(out.join(file).is_file(), "{file}");
    }
}

#[test]
fn inputs_a_series_cannot_be_made_of_are_refused() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mut config = presets::graphite_sequence();
    config.scan.columns = 96;
    config.scan.rows = 96;
    config.scan.width_m = 3e-9;
    config.scan.height_m = 3e-9;
    if let Some(sequence) = config.sequence.as_mut() {
        sequence.frames = 2;
        sequence.moves.clear();
    }
    let frames = dir.path().join("frames");
    simulate(&config, &frames);
    // One frame.
    let one = series(
        frames.join("frame_00.sm4").to_str().expect("utf-8"),
        &dir.path().join("a"),
        &[],
    );
    assert!(!one.status.success());
    let err = String::from_utf8_lossy(&one.stderr);
    assert!(err.contains("at least two frames"), "{err}");
    // Frames of two sizes.
    let other = dir.path().join("other");
    config.scan.columns = 80;
    config.scan.rows = 80;
    config.scan.width_m = 2.5e-9;
    config.scan.height_m = 2.5e-9;
    simulate(&config, &other);
    std::fs::copy(other.join("frame_01.sm4"), frames.join("frame_01.sm4")).expect("copied");
    let mixed = series(
        frames.join("*.sm4").to_str().expect("utf-8"),
        &dir.path().join("b"),
        &[],
    );
    assert!(!mixed.status.success());
    let err = String::from_utf8_lossy(&mixed.stderr);
    assert!(err.contains("one size, pitch and timing"), "{err}");
    assert!(
        !dir.path().join("b").exists(),
        "nothing written on a refusal"
    );
}

/// The preset cut to a pair of frames at 0° and 90°, without moves.
fn pair_config() -> dhct_simulate::SimulationConfig {
    let mut config = presets::graphite_sequence();
    let sequence = config.sequence.as_mut().expect("a sequence preset");
    sequence.frames = 2;
    sequence.scan_angles_deg = vec![0.0, 90.0];
    sequence.moves.clear();
    config
}

/// Runs `dhct series` on `config`'s frames; returns the truth, the features and series.json.
fn run_pair(
    config: &dhct_simulate::SimulationConfig,
    dir: &Path,
) -> (SequenceTruth, Vec<Registered>, serde_json::Value) {
    let frames = dir.join("frames");
    let truth = simulate(config, &frames);
    let out = dir.join("out");
    let run = series(frames.join("*.sm4").to_str().expect("utf-8"), &out, &[]);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let summary =
        serde_json::from_str(&std::fs::read_to_string(out.join("series.json")).expect("json"))
            .expect("parses");
    (truth, read_features(&out.join("features.csv")), summary)
}

#[test]
fn a_pair_at_0_and_90_degrees_measures_the_slow_axis_pixel_size_the_drift_hid() {
    // The scanner's y moves 2 % further than the files say: in the 0° frame that is the
    // slow axis, where one frame cannot tell it from a drift along y.
    let mut config = pair_config();
    config.sequence.as_mut().expect("sequence").scanner_gain = [1.0, 1.02];
    let dir = tempfile::tempdir().expect("tempdir");
    let (truth, found, summary) = run_pair(&config, dir.path());
    let gain = summary["fit"]["gain_y"].as_f64().expect("gain");
    let sigma = summary["fit"]["gain_y_sigma"].as_f64().expect("σ");
    assert!(sigma < 2e-4, "σ {sigma}");
    assert!(
        (gain - 1.02).abs() < 3.0 * sigma.max(2e-5),
        "gain {gain} ± {sigma}"
    );
    let per_frame = errors(&truth, &found);
    let all: Vec<[f64; 2]> = per_frame.iter().flat_map(|(_, _, r)| r.clone()).collect();
    let global = mean(&all);
    for (k, local, registered) in &per_frame {
        let (floor, error) = (rms_about(local, [0.0; 2]), rms_about(registered, global));
        assert!(
            error <= 1.2 * floor,
            "frame {k}: {error:.4} px against {floor:.4} px"
        );
        assert!(error <= 0.1, "frame {k}: {error:.4} px");
    }
}

#[test]
fn a_pair_without_drift_or_hysteresis_is_registered_by_the_identity() {
    let mut config = pair_config();
    config.effects.clear();
    let sequence = config.sequence.as_mut().expect("sequence");
    sequence.drift = Default::default();
    sequence.initial_creep = None;
    let dir = tempfile::tempdir().expect("tempdir");
    let (truth, found, _) = run_pair(&config, dir.path());
    let pitch = truth.frames[0].geometry.pitch_x();
    // Every feature's registered position against where the files alone put it.
    let moved: Vec<[f64; 2]> = found
        .iter()
        .map(|f| {
            let g = &truth.frames[f.frame].geometry;
            let stated = g.to_instrument([f.px[0] * g.pitch_x(), f.px[1] * g.pitch_y()]);
            [
                (f.session_m[0] - stated[0]) / pitch,
                (f.session_m[1] - stated[1]) / pitch,
            ]
        })
        .collect();
    let rms = rms_about(&moved, [0.0; 2]);
    let largest = moved.iter().map(|d| d[0].hypot(d[1])).fold(0.0, f64::max);
    eprintln!("identity: rms {rms:.4} px, largest {largest:.4} px");
    assert!(
        rms <= 0.01,
        "the registration moves features by {rms:.4} px rms"
    );
}

/// Four frames at 0° from a scanner whose slow axis moves 6 % further than told.
fn slow_axis_gain_session() -> dhct_simulate::SimulationConfig {
    let mut config = pair_config();
    let sequence = config.sequence.as_mut().expect("sequence");
    sequence.frames = 4;
    sequence.scan_angles_deg = vec![0.0];
    sequence.scanner_gain = [1.0, 1.06];
    config
}

#[test]
fn frames_the_drift_cannot_place_are_refused_not_registered_a_period_off() {
    // A 6 % slow-axis pixel-size error looks like a drift within each 4 nm frame and is
    // carried as 240 pm to the next: past half a lattice period, so the frames are placed
    // a period off. The series model then cannot explain them, and says so.
    let config = slow_axis_gain_session();
    let dir = tempfile::tempdir().expect("tempdir");
    let frames = dir.path().join("frames");
    simulate(&config, &frames);
    let out = dir.path().join("out");
    let run = series(frames.join("*.sm4").to_str().expect("utf-8"), &out, &[]);
    assert!(!run.status.success(), "a misplaced session was registered");
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(err.contains("does not explain frame"), "{err}");
    assert!(err.contains("pixel-size error"), "{err}");
    assert!(!out.exists(), "nothing written on a refusal");
}

#[test]
fn frames_with_vacancies_are_placed_by_their_images_where_the_drift_cannot_place_them() {
    // The session above that is refused (a 6 % slow-axis pixel-size error carried a period
    // off between frames), with 2 % of the sites empty: the vacancies, the same in every
    // frame, place each frame against the one before from the two images alone; the fit
    // then measures the gain and registers every frame.
    let mut config = slow_axis_gain_session();
    config.surface.defects.vacancy_fraction = 0.02;
    let dir = tempfile::tempdir().expect("tempdir");
    let (truth, found, summary) = run_pair(&config, dir.path());
    let notes = summary["notes"].to_string();
    assert!(
        notes.contains("placed from its image's correlation"),
        "{notes}"
    );
    let gain = summary["fit"]["gain_y"].as_f64().expect("gain");
    eprintln!("vacancies: gain_y {gain:.6}; {notes}");
    assert!((gain - 1.06).abs() < 0.002, "gain_y {gain}");
    let per_frame = errors(&truth, &found);
    let all: Vec<[f64; 2]> = per_frame.iter().flat_map(|(_, _, r)| r.clone()).collect();
    let global = mean(&all);
    for (k, local, registered) in &per_frame {
        let floor = rms_about(local, [0.0; 2]);
        let error = rms_about(registered, global);
        eprintln!("frame {k}: registered {error:.4} px, floor {floor:.4} px");
        assert!(
            error <= 1.2 * floor,
            "frame {k}: registered {error:.4} px against a floor of {floor:.4} px"
        );
    }
}

/// A session of `frames` frames of molecules on lattice sites of 1.4 nm, 60 % of the
/// sites empty (a pattern without a period), the substrate's atoms not resolved: 192 px
/// over 16 nm, the preset's drift with its move and creep before frame 4; no hysteresis
/// unless `hysteresis`.
fn molecule_session(frames: usize, hysteresis: bool) -> dhct_simulate::SimulationConfig {
    let mut config = presets::graphite_sequence();
    config.scan.columns = 192;
    config.scan.rows = 192;
    config.scan.width_m = 16e-9;
    config.scan.height_m = 16e-9;
    config.scan.fast_speed_m_per_s = 200e-9;
    config.surface.lattice = dhct_simulate::LatticeConfig::Hexagonal { a_m: 1.4e-9 };
    config.surface.feature.sigma_m = [2.5e-10, 2.5e-10];
    config.surface.defects.vacancy_fraction = 0.6;
    if !hysteresis {
        config.effects.clear();
    }
    if let Some(sequence) = config.sequence.as_mut() {
        sequence.frames = frames;
        sequence.moves[0].before_frame = 4.min(frames - 1);
    }
    config
}

/// Frame starts found less the truth, the constant between them (the session frame's
/// place, which comparisons cannot fix) taken out, pixels.
fn start_errors_px(truth: &SequenceTruth, summary: &serde_json::Value, pitch_m: f64) -> Vec<f64> {
    let found: Vec<[f64; 2]> = summary["drift"]["frame_starts"]
        .as_array()
        .expect("frame starts")
        .iter()
        .map(|p| {
            let d = &p["displacement_m"];
            [d[0].as_f64().expect("x"), d[1].as_f64().expect("y")]
        })
        .collect();
    assert_eq!(found.len(), truth.frames.len());
    let differences: Vec<[f64; 2]> = found
        .iter()
        .zip(&truth.frames)
        .map(|(f, t)| {
            [
                f[0] - t.placement.displacement_at_start_m[0],
                f[1] - t.placement.displacement_at_start_m[1],
            ]
        })
        .collect();
    let centre = mean(&differences);
    differences
        .iter()
        .map(|d| (d[0] - centre[0]).hypot(d[1] - centre[1]) / pitch_m)
        .collect()
}

#[test]
fn frames_without_a_resolved_lattice_are_registered_by_their_images() {
    let dir = tempfile::tempdir().expect("tempdir");
    let frames = dir.path().join("frames");
    let truth = simulate(&molecule_session(8, false), &frames);
    let out = dir.path().join("out");
    let run = series(
        frames.join("*.sm4").to_str().expect("utf-8"),
        &out,
        &["--register", "image"],
    );
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let text = std::fs::read_to_string(out.join("series.json")).expect("series.json");
    let summary: serde_json::Value = serde_json::from_str(&text).expect("json");
    assert_eq!(summary["registration"], "image");
    assert!(
        summary["undetermined"].as_array().is_some_and(|u| u
            .iter()
            .any(|s| s.as_str().is_some_and(|s| s.contains("scale")))),
        "{text}"
    );
    // The drift moves the frames by about 25 px over the session (1.6 nm at 83 pm/px,
    // the move's creep 0.2 nm within seconds); every frame start within 0.1 px.
    let errors = start_errors_px(&truth, &summary, 16e-9 / 192.0);
    let worst = errors.iter().copied().fold(0.0, f64::max);
    assert!(worst < 0.1, "frame starts off the truth by {errors:?} px");
    // The move's creep, (200, -100) pm over 5 s, is found as one.
    let creep = &summary["drift"]["drift"]["creeps"][0];
    let c = [
        creep["coefficient_m"][0].as_f64().expect("c_x"),
        creep["coefficient_m"][1].as_f64().expect("c_y"),
    ];
    assert!(
        (c[0] - 200e-12).abs() < 30e-12 && (c[1] + 100e-12).abs() < 30e-12,
        "{creep}"
    );
    // Registered images line up by their pixels alone.
    for frame in summary["frames"].as_array().expect("frames") {
        for shift in frame["registered_shifts"].as_array().expect("shifts") {
            let s = &shift["shift_px"];
            let off = s[0].as_f64().expect("x").hypot(s[1].as_f64().expect("y"));
            assert!(off < 0.2, "{frame}");
        }
    }
    assert!(out.join("registered/stack.tif").exists());
    assert!(out.join("report.html").exists());
}

#[test]
fn passes_apart_by_hysteresis_are_registered_halfway_and_other_areas_refused() {
    let dir = tempfile::tempdir().expect("tempdir");
    let frames = dir.path().join("frames");
    simulate(&molecule_session(3, true), &frames);
    let out = dir.path().join("out");
    let run = series(
        frames.join("*.sm4").to_str().expect("utf-8"),
        &out,
        &["--register", "image"],
    );
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let text = std::fs::read_to_string(out.join("series.json")).expect("series.json");
    let summary: serde_json::Value = serde_json::from_str(&text).expect("json");
    // The retrace shows the lattice several pixels along the lines from the trace
    // (the hysteresis); registered, the passes meet.
    let shift = summary["retrace_shift_px"][0].as_f64().expect("measured");
    assert!(shift.abs() > 1.0, "{shift}");
    for frame in summary["frames"].as_array().expect("frames") {
        for s in frame["registered_shifts"].as_array().expect("shifts") {
            let x = s["shift_px"][0].as_f64().expect("x");
            assert!(x.abs() < 0.3, "{frame}");
        }
    }
    // A frame of another area (other sites empty) in the session is refused, naming it.
    let mut other = molecule_session(3, true);
    other.seed = 99;
    other.surface.defects.vacancy_seed = Some(99);
    let elsewhere = dir.path().join("elsewhere");
    simulate(&other, &elsewhere);
    std::fs::copy(elsewhere.join("frame_01.sm4"), frames.join("frame_01.sm4")).expect("copied");
    let refused = series(
        frames.join("*.sm4").to_str().expect("utf-8"),
        &dir.path().join("refused"),
        &["--register", "image"],
    );
    assert!(!refused.status.success());
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(err.contains("no common structure"), "{err}");
    assert!(!dir.path().join("refused").exists(), "nothing written");
}

#[test]
fn a_file_of_several_frames_is_a_series_of_them() {
    // A real SPECS film (tests/data/real, BSD-3): five 100 nm frames, 38.5 s each, in one
    // file. Its frames are the series (the file is neither skipped nor one frame), and they
    // are refused: tip changes and line jumps between them leave no correlation peak that
    // stands out, and a guess would be a wrong registration.
    let film = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/data/real/specs_aarhus_film_100nm.flm");
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("out");
    let run = series(
        film.to_str().expect("utf-8"),
        &out,
        &["--register", "image"],
    );
    assert!(!run.status.success());
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(
        !err.contains("skipping") && !err.contains("at least two"),
        "{err}"
    );
    assert!(err.contains("no common structure"), "{err}");
    assert!(!out.exists(), "nothing written");
}
