//! `dhct series` on a long simulated session: time and peak memory of the whole run
//! (every frame analysed alone, the series fit, the registered images written), and how far
//! the drift at each frame's start is from the truth.
//!
//! ```sh
//! cargo run --release -p dhct-bench --bin series -- [--frames 100] [--size 512] [--json OUT.json]
//! ```
//!
//! The session is the `graphite-sequence` preset stretched to `--frames` frames of
//! `--size`² at the preset's pixel size. The frames are simulated into a temporary folder
//! first (not timed); the run is `dhct_app::series::run` in this process, its peak memory
//! `VmHWM` reset just before it.

use std::time::Instant;

use dhct_app::series::{SeriesRequest, run};
use dhct_app::setup::CorrectConfig;
use dhct_bench::machine::{cpus, load_string, peak_memory_mib, reset_peak_memory};
use dhct_simulate::{SequenceSimulation, SequenceTruth, presets};
use serde_json::json;

fn flag(args: &[String], name: &str) -> Option<String> {
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1))
        .cloned()
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let number = |name: &str, default: usize| {
        flag(&args, name).map_or(Ok(default), |v| {
            v.parse::<usize>()
                .map_err(|_| format!("{name} takes a whole number, got {v:?}"))
        })
    };
    let (frames, size) = match (number("--frames", 100), number("--size", 512)) {
        (Ok(f), Ok(s)) if f >= 2 && (32..=4096).contains(&s) => (f, s),
        (Err(e), _) | (_, Err(e)) => fail(&e),
        _ => fail("--frames must be at least 2 and --size 32..=4096"),
    };
    let mut config = presets::graphite_sequence();
    let scale = size as f64 / config.scan.columns as f64;
    config.scan.columns = size;
    config.scan.rows = size;
    config.scan.width_m *= scale;
    config.scan.height_m *= scale;
    config.scan.fast_speed_m_per_s *= scale;
    if let Some(sequence) = config.sequence.as_mut() {
        sequence.frames = frames;
        sequence.moves.retain(|m| m.before_frame < frames);
    }
    let dir = tempfile::tempdir().unwrap_or_else(|e| fail(&format!("no temporary folder: {e}")));
    let frames_dir = dir.path().join("frames");
    let started = Instant::now();
    let simulation =
        SequenceSimulation::from_config(&config).unwrap_or_else(|e| fail(&e.to_string()));
    simulation
        .write(&frames_dir, |_, _| {})
        .unwrap_or_else(|e| fail(&e.to_string()));
    eprintln!(
        "simulated {frames} frames of {size}² in {:.1} s",
        started.elapsed().as_secs_f64()
    );
    let truth: SequenceTruth = std::fs::read_to_string(frames_dir.join("sequence_truth.json"))
        .ok()
        .and_then(|t| serde_json::from_str(&t).ok())
        .unwrap_or_else(|| fail("the truth cannot be read back"));
    let inputs = vec![frames_dir.join("*.sm4").display().to_string()];
    let output = dir.path().join("out");
    let load_before = load_string();
    reset_peak_memory();
    let started = Instant::now();
    let summary = run(&SeriesRequest {
        inputs: &inputs,
        output: &output,
        config: CorrectConfig::default(),
        knots: None,
    })
    .unwrap_or_else(|e| fail(&format!("{e:#}")));
    let seconds = started.elapsed().as_secs_f64();
    let peak = peak_memory_mib();
    let pitch = truth.frames[0].geometry.pitch_x();
    // The session frame is defined up to one translation: the frame starts' mean is taken out.
    let differences: Vec<[f64; 2]> = summary
        .fit
        .frame_starts
        .iter()
        .zip(&truth.frames)
        .map(|(fitted, true_frame)| {
            let t = true_frame.placement.displacement_at_start_m;
            [
                (fitted.displacement_m[0] - t[0]) / pitch,
                (fitted.displacement_m[1] - t[1]) / pitch,
            ]
        })
        .collect();
    let n = differences.len() as f64;
    let mean = differences
        .iter()
        .fold([0.0; 2], |a, d| [a[0] + d[0] / n, a[1] + d[1] / n]);
    let worst = differences
        .iter()
        .map(|d| (d[0] - mean[0]).hypot(d[1] - mean[1]))
        .fold(0.0, f64::max);
    let report = json!({
        "frames": frames,
        "size_px": size,
        "cpus": cpus(),
        "load_before": load_before,
        "load_after": load_string(),
        "seconds": seconds,
        "peak_memory_mib": peak,
        "features_fitted": summary.fit.features,
        "interior_knots": summary.fit.drift.basis.interior_knots,
        "worst_frame_start_error_px": worst,
        "timings_s": summary.timings,
    });
    println!(
        "{frames} frames of {size}²: {seconds:.1} s on {} cpus (load {} -> {}), peak memory {} MiB; \
         {} features fitted, {} knots; drift at the frame starts within {worst:.4} px of the truth \
         (target: ≤ 30 s, memory bounded by a few frames)",
        cpus(),
        report["load_before"],
        report["load_after"],
        peak.map_or("?".into(), |p| format!("{p:.0}")),
        summary.fit.features,
        summary.fit.drift.basis.interior_knots,
    );
    let t = &summary.timings;
    println!(
        "  frames analysed {:.1} s (one core: lattice {:.1} s, features {:.1} s, model {:.1} s), \
         steps {:.1} s, series fit {:.1} s, registered images {:.1} s, report {:.1} s, all {:.1} s",
        t.frames_s,
        t.frame_stages.calibration_s,
        t.frame_stages.features_s,
        t.frame_stages.model_s,
        t.steps_s,
        t.fit_s,
        t.registered_s,
        t.report_s,
        t.total_s
    );
    if let Some(path) = flag(&args, "--json") {
        let text = serde_json::to_string_pretty(&report).unwrap_or_default();
        if let Err(e) = std::fs::write(&path, text + "\n") {
            fail(&format!("cannot write {path}: {e}"));
        }
    }
}

fn fail(message: &str) -> ! {
    eprintln!("series: {message}");
    std::process::exit(2);
}
