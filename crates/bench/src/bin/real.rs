//! The real-data corpus run as a user would, judged from the corrected images alone.
//!
//! ```sh
//! cargo build --release -p dhct-cli
//! DHCT_REAL_DATA=../shared/data cargo run --release -p dhct-bench --bin real -- \
//!     [--corpus tests/data/real/corpus.toml] [--dhct target/release/dhct] [--out DIR]
//! ```
//!
//! Prints one row per file: right / refused (with the reason) / wrong, the correction kept
//! (drift model or affine) with both lattice-fit rms deviations, the corrected lattice's
//! scales and shear, and the non-affine displacement (Bragg phases) of the raw and the
//! corrected image. A pass whose lattice is off (or cannot be measured) counts as flagged
//! when dhct's own `corrected_image_off` (`corrected_image_unchecked`) warning names it,
//! as wrong otherwise. Exits non-zero when a file
//! is wrong at exit 0 without a warning.

use std::path::PathBuf;

use dhct_bench::real_corpus::{Corpus, FileResult, Verdict, run_file};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let value = |flag: &str| {
        args.iter()
            .position(|a| a == flag)
            .and_then(|i| args.get(i + 1))
            .map(PathBuf::from)
    };
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
    let corpus_path = value("--corpus").unwrap_or_else(|| root.join("tests/data/real/corpus.toml"));
    let dhct = value("--dhct").unwrap_or_else(|| {
        std::env::current_exe()
            .ok()
            .and_then(|exe| exe.parent().map(|d| d.join("dhct")))
            .unwrap_or_else(|| root.join("target/release/dhct"))
    });
    let out = value("--out").unwrap_or_else(|| std::env::temp_dir().join("dhct-bench-real"));
    let corpus = match Corpus::read(&corpus_path) {
        Ok(corpus) => corpus,
        Err(e) => {
            eprintln!("real: {e}");
            std::process::exit(2);
        }
    };
    if !dhct.is_file() {
        eprintln!(
            "real: no dhct binary at {} (cargo build --release -p dhct-cli, or --dhct PATH)",
            dhct.display()
        );
        std::process::exit(2);
    }
    let mut wrong = 0;
    let mut counts = [0usize; 5];
    for (i, file) in corpus.file.iter().enumerate() {
        let result = run_file(file, &root, &dhct, &out.join(format!("{i:02}")));
        counts[match result.verdict {
            Verdict::Right => 0,
            Verdict::Refused(_) => 1,
            Verdict::Wrong(_) => 2,
            Verdict::Missing(_) => 3,
            Verdict::Flagged(_) => 4,
        }] += 1;
        if matches!(result.verdict, Verdict::Wrong(_)) {
            wrong += 1;
        }
        print_row(file.name.as_str(), file.periods_across, &result);
    }
    println!(
        "\n{} right, {} with a pass dhct flagged as off, {} refused, {} wrong, {} missing",
        counts[0], counts[4], counts[1], counts[2], counts[3]
    );
    if wrong > 0 {
        std::process::exit(1);
    }
}

fn print_row(name: &str, periods: f64, r: &FileResult) {
    let verdict = match &r.verdict {
        Verdict::Right => "right".to_string(),
        Verdict::Refused(why) => format!("refused: {why}"),
        Verdict::Wrong(why) => format!("WRONG: {why}"),
        Verdict::Flagged(why) => format!("a pass off or unchecked, flagged by dhct: {why}"),
        Verdict::Missing(why) => format!("missing: {why}"),
    };
    println!(
        "{name} (~{periods:.0} periods; {}): {verdict}",
        r.args.join(" ")
    );
    if let (Some(correction), Some([model, affine])) = (&r.correction, r.model_vs_affine_m) {
        println!(
            "    correction {correction}; lattice-fit rms: drift model {:.1} pm, affine {:.1} pm",
            model * 1e12,
            affine * 1e12
        );
    }
    for p in &r.passes {
        let periods = |v: Option<f64>| v.map_or("-".into(), |v| format!("{:.1} %", 100.0 * v));
        println!(
            "    {}: corrected x {:.4}, y {:.4}, shear {:.2}°; non-affine displacement raw {} → corrected {} of a period",
            p.pass,
            p.scale[0],
            p.scale[1],
            p.shear_deg,
            periods(p.raw_non_affine),
            periods(p.corrected_non_affine)
        );
    }
}
