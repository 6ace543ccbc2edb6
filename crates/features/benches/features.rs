//! Feature-finding throughput on the paper's headline image: graphite, 2048 × 2048 px trace +
//! retrace over 25 nm (simulated with drift, creep, hysteresis and noise), the full pipeline
//! (background, line correction, NCC, watershed, fits, duplicates, times) on both images.
//!
//! `cargo bench -p dhct-features --bench features [-- --write-dir ABSOLUTE_DIR]`
//! With `--write-dir DIR`, the trace image (`trace.npy`), its true feature positions
//! (`truth_trace.csv`), our features (`dhct_trace.csv`) and our timing (`dhct_timing.json`)
//! are written there, for comparing with other localisation tools (the Atomap comparison
//! on equal terms is `scripts/peers/compare.py`).

use std::time::Instant;

use dhct_features::{FeatureOptions, LineCorrection, find_features_in_pair};
use dhct_simulate::{Simulation, presets};

fn peak_memory_mib() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib / 1024.0)
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let write_dir = args
        .iter()
        .position(|a| a == "--write-dir")
        .and_then(|i| args.get(i + 1));
    let config = presets::headline_2048();
    let start = Instant::now();
    let output = Simulation::from_config(&config)
        .expect("preset is valid")
        .run()
        .expect("simulation runs");
    println!(
        "simulated 2048² pair in {:.2} s",
        start.elapsed().as_secs_f64()
    );
    let options = FeatureOptions {
        line_correction: LineCorrection::Median,
        ..FeatureOptions::for_neighbour_distance(2.46e-10)
    };
    let threads = rayon::current_num_threads();
    let mut best = f64::INFINITY;
    let mut sets = Vec::new();
    for _ in 0..3 {
        let start = Instant::now();
        sets = find_features_in_pair(&output.pair, &options).expect("features");
        best = best.min(start.elapsed().as_secs_f64());
    }
    let count = sets.iter().map(|s| s.features.len()).sum::<usize>();
    let iterations: usize = sets
        .iter()
        .flat_map(|s| &s.features)
        .map(|f| f.fit_iterations)
        .sum();
    let pixels: usize = sets
        .iter()
        .flat_map(|s| &s.features)
        .map(|f| f.pixel_count)
        .sum();
    println!(
        "fits: {:.1} iterations and {:.0} pixels on average",
        iterations as f64 / count as f64,
        pixels as f64 / count as f64
    );
    for set in &sets {
        println!("{:?} stage times: {:?}", set.pass, set.timings);
    }
    println!(
        "features: {count} in trace + retrace, best of 3: {best:.3} s on {threads} threads → {:.0} features/s",
        count as f64 / best
    );
    if let Some(mib) = peak_memory_mib() {
        println!("peak memory (VmHWM): {mib:.0} MiB");
    }

    // Accuracy against the truth: rms distance of matched trace features (px).
    let truth: Vec<[f64; 2]> = output
        .truth
        .features
        .iter()
        .filter(|f| f.trace.in_image)
        .map(|f| f.trace.controller_position_px)
        .collect();
    let trace = &sets[0];
    let tree: kiddo::ImmutableKdTree<f64, 2> =
        kiddo::ImmutableKdTree::new_from_slice(&truth).expect("index truth");
    let offsets: Vec<[f64; 2]> = trace
        .features
        .iter()
        .filter_map(|f| {
            let nearest = tree
                .query(&[f.x_px, f.y_px])
                .nearest_one::<kiddo::SquaredEuclidean<f64>>()
                .execute();
            let t = truth[nearest.item as usize];
            (nearest.distance < 25.0).then(|| [f.x_px - t[0], f.y_px - t[1]])
        })
        .collect();
    let n = offsets.len() as f64;
    let rms = (offsets
        .iter()
        .map(|d| d[0] * d[0] + d[1] * d[1])
        .sum::<f64>()
        / n)
        .sqrt();
    let mean = |k: usize| offsets.iter().map(|d| d[k]).sum::<f64>() / n;
    println!(
        "trace: {} features matched to truth, rms position error {rms:.4} px, mean offset ({:.4}, {:.4}) px",
        offsets.len(),
        mean(0),
        mean(1)
    );

    if let Some(dir) = write_dir {
        let dir = std::path::Path::new(dir);
        std::fs::create_dir_all(dir).expect("create output directory");
        let image = output.pair.trace().expect("trace");
        dhct_sm4_io::write_atomically(&dir.join("trace.npy"), |w| {
            dhct_sm4_io::npy::write(image, w)
        })
        .expect("write trace.npy");
        let mut csv = String::from("x_px,y_px\n");
        for t in &truth {
            csv.push_str(&format!("{},{}\n", t[0], t[1]));
        }
        std::fs::write(dir.join("truth_trace.csv"), csv).expect("write truth");
        let mut ours = Vec::new();
        trace.write_csv(&mut ours).expect("features csv");
        std::fs::write(dir.join("dhct_trace.csv"), ours).expect("write features");
        let timing = format!(
            "{{\"features_per_second\": {}, \"threads\": {threads}, \"rms_px\": {rms}}}",
            count as f64 / best
        );
        std::fs::write(dir.join("dhct_timing.json"), timing).expect("write timing");
        println!(
            "wrote trace.npy, truth_trace.csv, dhct_trace.csv, dhct_timing.json to {}",
            dir.display()
        );
    }
}
