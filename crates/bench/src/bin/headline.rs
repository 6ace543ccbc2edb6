//! The paper's headline case end to end, the scaling curve, accuracy vs truth, files for
//! the peer comparison, and the full robustness sweep.
//!
//! ```sh
//! cargo run --release -p dhct-bench --bin headline -- \
//!     [--json OUT.json] [--sizes 512,1024,2048,4096] [--repeats 3] \
//!     [--peers-dir DIR [--peer-size 1024] [--peer-static]] [--sm4-out FILE] [--robustness] \
//!     [--skip-headline]
//! python3 scripts/peers/compare.py DIR        # Atomap, stmpy Lawler–Fujita, FFT affine
//! ```
//!
//! `--peer-static` writes the peers' image without drift, creep, hysteresis, line, 1/f and
//! spike noise (white noise only): a comparison of localisation alone.
//!
//! Each timed run (read SM4 + `dhct_pipeline::run`) is a child process of its own
//! (`headline measure FILE LATTICE_JSON`), so its peak memory (VmHWM) is that of the run
//! alone. The load average is printed beside every timing: the machine is shared.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use dhct_bench::accuracy::{Accuracy, accuracy, match_features};
use dhct_bench::machine::{cpus, load_string, peak_memory_mib};
use dhct_bench::measure::{Measurement, StageTimes, measure_file};
use dhct_bench::robustness::{self, SweepSize};
use dhct_bench::scenario::{HEADLINE_PIXELS, SpeedScaling, headline_at, pipeline_options};
use dhct_bench::table::Table;
use dhct_scan::ScanPass;
use dhct_simulate::{LatticeConfig, Simulation, SimulationOutput};
use serde_json::{Value, json};

struct Args {
    json: Option<PathBuf>,
    sizes: Vec<usize>,
    repeats: usize,
    peers_dir: Option<PathBuf>,
    peer_size: usize,
    peer_static: bool,
    sm4_out: Option<PathBuf>,
    robustness: bool,
    skip_headline: bool,
}

fn parse_args(args: &[String]) -> Result<Args, String> {
    let mut parsed = Args {
        json: None,
        sizes: vec![512, 1024, 2048, 4096],
        repeats: 3,
        peers_dir: None,
        peer_size: 1024,
        peer_static: false,
        sm4_out: None,
        robustness: false,
        skip_headline: false,
    };
    let mut it = args.iter();
    while let Some(arg) = it.next() {
        let mut value = || {
            it.next()
                .cloned()
                .ok_or_else(|| format!("{arg} needs a value"))
        };
        match arg.as_str() {
            "--json" => parsed.json = Some(value()?.into()),
            "--sizes" => {
                parsed.sizes = value()?
                    .split(',')
                    .filter(|s| !s.is_empty())
                    .map(|s| s.parse().map_err(|e| format!("--sizes {s}: {e}")))
                    .collect::<Result<_, _>>()?
            }
            "--repeats" => {
                parsed.repeats = value()?.parse().map_err(|e| format!("--repeats: {e}"))?
            }
            "--peers-dir" => parsed.peers_dir = Some(value()?.into()),
            "--peer-size" => {
                parsed.peer_size = value()?.parse().map_err(|e| format!("--peer-size: {e}"))?
            }
            "--peer-static" => parsed.peer_static = true,
            "--sm4-out" => parsed.sm4_out = Some(value()?.into()),
            "--robustness" => parsed.robustness = true,
            "--skip-headline" => parsed.skip_headline = true,
            other => return Err(format!("unknown argument {other}")),
        }
    }
    if parsed.repeats == 0 {
        return Err("--repeats must be at least 1".into());
    }
    Ok(parsed)
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.first().map(String::as_str) == Some("measure") {
        std::process::exit(child(&args[1..]));
    }
    let args = match parse_args(&args) {
        Ok(a) => a,
        Err(e) => {
            eprintln!("headline: {e}");
            std::process::exit(2);
        }
    };
    if let Err(e) = run(&args) {
        eprintln!("headline: {e}");
        std::process::exit(1);
    }
}

/// `headline measure FILE LATTICE_JSON`: one timed run, printed as one JSON line.
fn child(args: &[String]) -> i32 {
    let [path, lattice_json] = args else {
        eprintln!("usage: headline measure FILE LATTICE_JSON");
        return 2;
    };
    let lattice = match serde_json::from_str::<LatticeConfig>(lattice_json)
        .map_err(|e| e.to_string())
        .and_then(|l| l.build().map_err(|e| e.to_string()))
    {
        Ok(l) => l,
        Err(e) => {
            eprintln!("lattice: {e}");
            return 2;
        }
    };
    match measure_file(
        Path::new(path),
        lattice.as_ref(),
        &pipeline_options(lattice.as_ref()),
    ) {
        Ok((measurement, _analysis)) => {
            println!(
                "{}",
                serde_json::to_string(&measurement).expect("a measurement serialises")
            );
            0
        }
        Err(e) => {
            eprintln!("{e}");
            1
        }
    }
}

fn measure_in_child(path: &Path, lattice: &LatticeConfig) -> Result<Measurement, String> {
    let exe = std::env::current_exe().map_err(|e| e.to_string())?;
    let output = Command::new(exe)
        .arg("measure")
        .arg(path)
        .arg(serde_json::to_string(lattice).map_err(|e| e.to_string())?)
        .output()
        .map_err(|e| format!("starting the measuring child: {e}"))?;
    if !output.status.success() {
        return Err(format!(
            "the measuring child failed ({}): {}",
            output.status,
            String::from_utf8_lossy(&output.stderr)
        ));
    }
    let stdout = String::from_utf8_lossy(&output.stdout);
    let line = stdout.lines().last().unwrap_or("");
    serde_json::from_str(line).map_err(|e| format!("child output {line:?}: {e}"))
}

/// Simulates `pixels`², writes the SM4 into `dir`; returns the output and the file.
fn simulate_to_sm4(pixels: usize, dir: &Path) -> Result<(SimulationOutput, PathBuf, f64), String> {
    let config = headline_at(pixels, SpeedScaling::SameLineTime);
    let start = Instant::now();
    let output = Simulation::from_config(&config)
        .and_then(|s| s.run())
        .map_err(|e| format!("simulation {pixels}²: {e}"))?;
    let simulate_s = start.elapsed().as_secs_f64();
    let path = dir.join(format!("headline-{pixels}.sm4"));
    dhct_sm4_io::write_atomically(&path, |w| dhct_sm4_io::sm4::write(&output.scan_file(), w))
        .map_err(|e| format!("writing {path:?}: {e}"))?;
    Ok((output, path, simulate_s))
}

/// `"2048²: peak per stage (MiB): read 98, Calibration 120, …"`.
fn stage_peaks_line(m: &Measurement) -> String {
    let stages: Vec<String> = m
        .stage_peaks_mib
        .iter()
        .map(|(stage, peak)| format!("{stage} {peak:.0}"))
        .collect();
    format!(
        "{}²: peak per stage (MiB): {}",
        m.pixels[0],
        stages.join(", ")
    )
}

/// Issue 18's time and memory targets for the sizes that have one (2048², 4096², 8192²;
/// read + pipeline on 2 cores; GB = 10⁹ bytes), met or missed.
fn scale_target(m: &Measurement) -> Option<String> {
    let (seconds, gigabytes) = match m.pixels {
        [2048, 2048] => (1.5, None),
        [4096, 4096] => (6.0, Some(1.5)),
        [8192, 8192] => (30.0, Some(4.0)),
        _ => return None,
    };
    let time = m.times.end_to_end_s;
    let verdict = |ok: bool| if ok { "met" } else { "MISSED" };
    let mut text = format!(
        "target {}²: ≤ {seconds} s: {time:.2} s {}",
        m.pixels[0],
        verdict(time <= seconds)
    );
    if let Some(gb) = gigabytes {
        let peak_gb = m.peak_memory_mib.unwrap_or(f64::NAN) * 1048576.0 / 1e9;
        text += &format!("; ≤ {gb} GB: {peak_gb:.2} GB {}", verdict(peak_gb <= gb));
    }
    Some(text)
}

fn median(mut v: Vec<f64>) -> f64 {
    dhct_numerics::robust::median(&mut v).unwrap_or(f64::NAN)
}

/// Per-stage minimum and median over repeated runs.
fn summarise(runs: &[Measurement]) -> (StageTimes, StageTimes) {
    let stage = |f: fn(&StageTimes) -> f64| {
        let v: Vec<f64> = runs.iter().map(|m| f(&m.times)).collect();
        (v.iter().copied().fold(f64::INFINITY, f64::min), median(v))
    };
    let mut min = StageTimes::default();
    let mut med = StageTimes::default();
    macro_rules! fill {
        ($($field:ident),*) => {$(
            let (a, b) = stage(|t| t.$field);
            min.$field = a;
            med.$field = b;
        )*};
    }
    fill!(
        read_s,
        calibration_s,
        features_s,
        neighbours_local_s,
        model_fit_s,
        model_s,
        correction_s,
        lattice_fit_s,
        unit_cells_s,
        pipeline_s,
        end_to_end_s
    );
    (min, med)
}

/// Reads one stage's time.
type Stage = fn(&StageTimes) -> f64;

fn stage_table(min: &StageTimes, med: &StageTimes) -> Table {
    let mut table = Table::new(&["stage", "min s", "median s"]);
    let rows: [(&str, Stage); 11] = [
        ("read SM4", |t| t.read_s),
        ("calibration (lattice from the FFT)", |t| t.calibration_s),
        ("features (both images)", |t| t.features_s),
        ("  NN + local distortion (re-timed)", |t| {
            t.neighbours_local_s
        }),
        ("  model fit (re-timed)", |t| t.model_fit_s),
        ("model: NN + local + fit", |t| t.model_s),
        ("correction + resampling", |t| t.correction_s),
        ("lattice fit", |t| t.lattice_fit_s),
        ("unit cells", |t| t.unit_cells_s),
        ("pipeline total", |t| t.pipeline_s),
        ("end to end (read + pipeline)", |t| t.end_to_end_s),
    ];
    for (name, f) in rows {
        table.row(vec![
            name.into(),
            format!("{:.3}", f(min)),
            format!("{:.3}", f(med)),
        ]);
    }
    table
}

fn accuracy_lines(a: &Accuracy) -> String {
    let mut text = format!(
        "features: {} found, {} matched of {} true ({:.2} % recall), {:.2} % indexed\n\
         feature rms {:.4} px per axis (x {:.4}, y {:.4}) vs fit CRLB {:.4} px: ratio {:.3}; vs white-noise \
         CRLB of the simulated shape {:.4} px: ratio {:.3}\n\
         noise floor {:.3} pm; uncorrected {:.1} pm; DHCT corrected rms vs truth {:.3} pm \
         (= {:.3} x floor)\n\
         lattice constant error (largest region): x {:+.4} %, y {:+.4} % ({:+.3}, {:+.3} pm)\n",
        a.found,
        a.matched,
        a.truth_in_image,
        100.0 * a.recall,
        100.0 * a.indexed_fraction,
        a.feature_rms_px,
        a.feature_rms_xy_px[0],
        a.feature_rms_xy_px[1],
        a.crlb_px,
        a.feature_rms_over_crlb,
        a.crlb_white_px,
        a.feature_rms_over_crlb_white,
        a.noise_floor_m * 1e12,
        a.uncorrected_rms_m * 1e12,
        a.corrected_rms_m * 1e12,
        a.corrected_over_floor,
        100.0 * a.lattice_constant_error[0],
        100.0 * a.lattice_constant_error[1],
        a.lattice_constant_error[0] * 246.0,
        a.lattice_constant_error[1] * 246.0,
    );
    for p in &a.parameters {
        text.push_str(&format!(
            "  {:>3} = {:+.5e} ± {:.2e} {} (truth {:+.5e}): {:+.2} σ\n",
            p.name,
            p.value,
            p.sigma,
            p.unit,
            p.truth,
            (p.value - p.truth) / p.sigma
        ));
    }
    text
}

/// The headline case: repeated timed runs (each in a child process), the per-stage table,
/// peak memory, and the accuracy of one more run against the truth.
fn headline(args: &Args, dir: &Path, lattice_config: &LatticeConfig) -> Result<Value, String> {
    let (output, path, simulate_s) = simulate_to_sm4(HEADLINE_PIXELS, dir)?;
    let bytes = std::fs::metadata(&path).map(|m| m.len()).unwrap_or(0);
    println!(
        "\n## Headline 2048² trace + retrace (graphite, 25 nm)\nsimulated in {simulate_s:.2} s, \
         SM4 {:.1} MB",
        bytes as f64 / 1e6
    );
    if let Some(out) = &args.sm4_out {
        std::fs::copy(&path, out).map_err(|e| format!("copying to {out:?}: {e}"))?;
        println!("SM4 copied to {}", out.display());
    }
    let mut runs = Vec::new();
    for k in 0..args.repeats {
        let m = measure_in_child(&path, lattice_config)?;
        println!(
            "run {}: end to end {:.3} s, {} features, peak {:.0} MiB, {} threads, load {}, \
             other processes {:.2} CPUs",
            k + 1,
            m.times.end_to_end_s,
            m.features,
            m.peak_memory_mib.unwrap_or(f64::NAN),
            m.threads,
            m.load,
            m.other_cpus.unwrap_or(f64::NAN)
        );
        println!("  {}", stage_peaks_line(&m));
        runs.push(m);
    }
    let (min, med) = summarise(&runs);
    print!("{}", stage_table(&min, &med));
    let peak = runs
        .iter()
        .filter_map(|m| m.peak_memory_mib)
        .fold(f64::NAN, f64::max);
    println!(
        "peak memory (VmHWM of the measuring process): {peak:.0} MiB; targets: end to end ≤ 3 s \
         ({}), peak ≤ 1024 MiB ({})",
        if min.end_to_end_s <= 3.0 {
            "met"
        } else {
            "MISSED"
        },
        if peak <= 1024.0 { "met" } else { "MISSED" }
    );

    // Accuracy: the same file analysed in this process.
    let lattice = lattice_config.build().map_err(|e| e.to_string())?;
    let (_, analysis) = measure_file(&path, lattice.as_ref(), &pipeline_options(lattice.as_ref()))?;
    let geometry = output.pair.geometry().clone();
    let acc = accuracy(&analysis, &output.truth, &geometry, lattice.as_ref());
    println!(
        "\n### Accuracy vs truth (headline)\n{}",
        accuracy_lines(&acc)
    );
    let value = json!({"pixels": HEADLINE_PIXELS, "simulate_s": simulate_s, "sm4_bytes": bytes,
               "runs": runs, "min": min, "median": med, "peak_memory_mib": peak,
               "accuracy": acc});
    drop(analysis);
    drop(output);
    let _ = std::fs::remove_file(&path);
    Ok(value)
}

fn run(args: &Args) -> Result<(), String> {
    let mut report = serde_json::Map::new();
    let started = Instant::now();
    report.insert(
        "machine".into(),
        json!({"cpus": cpus(), "rayon_threads": rayon::current_num_threads(),
               "load_at_start": load_string()}),
    );
    println!(
        "dhct-bench headline: {} CPUs, load {}",
        cpus(),
        load_string()
    );
    let tmp = tempfile::tempdir().map_err(|e| format!("temporary directory: {e}"))?;
    let lattice_config = LatticeConfig::Graphite;

    // 1. The headline case: per-stage times, peak memory, accuracy.
    if !args.skip_headline {
        let headline = headline(args, tmp.path(), &lattice_config)?;
        report.insert("headline".into(), headline);
    }

    // 2. Scaling curve.
    let mut scaling = Vec::new();
    let mut table = Table::new(&[
        "pixels",
        "features",
        "read s",
        "features s",
        "model s",
        "correction s",
        "lattice s",
        "cells s",
        "end to end s",
        "µs / kpx",
        "peak MiB",
        "other CPUs",
        "load",
    ]);
    for &pixels in &args.sizes {
        let (output, path, _) = simulate_to_sm4(pixels, tmp.path())?;
        drop(output);
        let m = measure_in_child(&path, &lattice_config)?;
        let _ = std::fs::remove_file(&path);
        let t = &m.times;
        table.row(vec![
            format!("{pixels}²"),
            m.features.to_string(),
            format!("{:.3}", t.read_s),
            format!("{:.3}", t.features_s),
            format!("{:.3}", t.model_s),
            format!("{:.3}", t.correction_s),
            format!("{:.3}", t.lattice_fit_s),
            format!("{:.3}", t.unit_cells_s),
            format!("{:.3}", t.end_to_end_s),
            format!("{:.2}", t.end_to_end_s * 1e9 / (pixels * pixels) as f64),
            format!("{:.0}", m.peak_memory_mib.unwrap_or(f64::NAN)),
            format!("{:.2}", m.other_cpus.unwrap_or(f64::NAN)),
            m.load.clone(),
        ]);
        scaling.push(m);
    }
    if !scaling.is_empty() {
        println!("\n## Scaling (same pitch and line time; one run each)\n{table}");
        for m in &scaling {
            println!("{}", stage_peaks_line(m));
            if let Some(verdict) = scale_target(m) {
                println!("  {verdict}");
            }
        }
    }
    report.insert("scaling".into(), json!(scaling));

    // 3. Files for the peer comparison.
    if let Some(dir) = &args.peers_dir {
        let ours = write_peer_files(dir, args.peer_size, args.peer_static)?;
        report.insert("peers_input".into(), ours);
    }

    // 4. The full robustness sweep.
    if args.robustness {
        let rows: Vec<_> = robustness::cases(SweepSize::Full)
            .iter()
            .map(robustness::run_case)
            .collect();
        println!(
            "\n## Robustness (full sweep, load {})\n{}",
            load_string(),
            robustness::table(&rows)
        );
        let unexpected = rows.iter().filter(|r| !r.as_expected()).count();
        let wrong = rows.iter().filter(|r| r.silently_wrong()).count();
        println!(
            "{unexpected} of {} runs not as expected; {wrong} returned an analysis far from the \
             truth without an error",
            rows.len()
        );
        report.insert("robustness".into(), json!(rows));
    }

    report.insert(
        "machine_end".into(),
        json!({"load_at_end": load_string(), "wall_s": started.elapsed().as_secs_f64(),
               "parent_peak_memory_mib": peak_memory_mib()}),
    );
    if let Some(path) = &args.json {
        let text = serde_json::to_string_pretty(&Value::Object(report))
            .map_err(|e| format!("JSON: {e}"))?;
        std::fs::write(path, text + "\n").map_err(|e| format!("writing {path:?}: {e}"))?;
        println!("\nwrote {}", path.display());
    }
    Ok(())
}

/// Simulates the headline physics at `pixels`² (with `static_lattice`, its lattice and white
/// noise only), runs our chain on it and writes, for
/// `scripts/peers/compare.py`: `trace.npy` (metres, float64), `matches_trace.csv` (every
/// trace feature matched to its truth: found and true controller position in px, our
/// corrected and the true sample position in m) and `ours.json` (geometry, lattice, our
/// stage times and residuals vs truth).
fn write_peer_files(dir: &Path, pixels: usize, static_lattice: bool) -> Result<Value, String> {
    std::fs::create_dir_all(dir).map_err(|e| format!("{dir:?}: {e}"))?;
    let mut config = headline_at(pixels, SpeedScaling::SameSpeed);
    if static_lattice {
        // Localisation alone: the headline lattice and white noise, nothing that moves.
        config.name = format!("static-{pixels}");
        config.effects.clear();
        config.noise.pink_sigma_m = 0.0;
        config.noise.line_offset_sigma_m = 0.0;
        config.noise.spike_probability = 0.0;
    }
    let output = Simulation::from_config(&config)
        .and_then(|s| s.run())
        .map_err(|e| format!("simulation: {e}"))?;
    let path = dir.join("headline.sm4");
    dhct_sm4_io::write_atomically(&path, |w| dhct_sm4_io::sm4::write(&output.scan_file(), w))
        .map_err(|e| format!("writing {path:?}: {e}"))?;
    let lattice = config.surface.lattice.build().map_err(|e| e.to_string())?;
    let (measurement, analysis) =
        measure_file(&path, lattice.as_ref(), &pipeline_options(lattice.as_ref()))?;
    let geometry = output.pair.geometry().clone();
    let acc = accuracy(&analysis, &output.truth, &geometry, lattice.as_ref());
    let (matches, _, _) = match_features(&analysis, &output.truth, &geometry, lattice.as_ref());
    let trace = output.pair.trace().ok_or("no trace")?;
    dhct_sm4_io::write_atomically(&dir.join("trace.npy"), |w| {
        dhct_sm4_io::npy::write(trace, w)
    })
    .map_err(|e| format!("trace.npy: {e}"))?;
    let mut csv = String::from(
        "found_x_px,found_y_px,truth_x_px,truth_y_px,corrected_x_m,corrected_y_m,sample_x_m,sample_y_m\n",
    );
    for m in matches.iter().filter(|m| m.pass == ScanPass::Trace) {
        csv.push_str(&format!(
            "{},{},{},{},{},{},{},{}\n",
            m.found_px[0],
            m.found_px[1],
            m.truth_px[0],
            m.truth_px[1],
            m.corrected_m[0],
            m.corrected_m[1],
            m.sample_m[0],
            m.sample_m[1]
        ));
    }
    std::fs::write(dir.join("matches_trace.csv"), csv).map_err(|e| e.to_string())?;
    // Our features per second (both passes) and trace-only residuals.
    let trace_features = analysis.passes[0].features.features.len();
    let features_per_s = measurement.features as f64 / measurement.times.features_s;
    let ours = json!({
        "pixels": pixels,
        "static": static_lattice,
        "pitch_m": [geometry.pitch_x(), geometry.pitch_y()],
        "nn_m": lattice.nearest_neighbour_distance(),
        "lattice": "graphite",
        "threads": measurement.threads,
        "load": measurement.load,
        "other_cpus": measurement.other_cpus,
        "times": measurement.times,
        "features_both_passes": measurement.features,
        "trace_features": trace_features,
        "features_per_s": features_per_s,
        "feature_rms_px": acc.feature_rms_px,
        "accuracy": acc,
    });
    let mut file = std::fs::File::create(dir.join("ours.json")).map_err(|e| e.to_string())?;
    writeln!(
        file,
        "{}",
        serde_json::to_string_pretty(&ours).map_err(|e| e.to_string())?
    )
    .map_err(|e| e.to_string())?;
    println!(
        "\n## Peer inputs ({pixels}²) written to {}\nours: {} features/s, model {:.3} s, \
         correction {:.3} s, corrected rms {:.3} pm, load {}",
        dir.display(),
        features_per_s.round(),
        measurement.times.model_s,
        measurement.times.correction_s,
        acc.corrected_rms_m * 1e12,
        load_string()
    );
    Ok(ours)
}
