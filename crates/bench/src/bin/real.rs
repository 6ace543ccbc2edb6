//! The real-data corpus run as a user would, judged from the corrected images alone.
//!
//! ```sh
//! cargo build --release -p dhct-cli
//! DHCT_REAL_DATA=../shared/data cargo run --release -p dhct-bench --bin real -- \
//!     [--corpus tests/data/real/corpus.toml] [--dhct target/release/dhct] [--out DIR] [--diagnose]
//! ```
//!
//! With `--diagnose`, every file dhct corrected is also diagnosed (`dhct diagnose` with the
//! same arguments): the verdict, the gap against the noise floor before and after the
//! effects named, and where what remains lies.
//!
//! Prints one row per file: right / refused (with the reason) / wrong, the correction kept
//! (drift model or affine) with both lattice-fit rms deviations, the corrected lattice's
//! scales and shear, and the non-affine displacement (Bragg phases) of the raw and the
//! corrected image. A pass whose lattice is off (or cannot be measured) counts as flagged
//! when dhct's own `corrected_image_off` (`corrected_image_unchecked`) warning names it,
//! as wrong otherwise. Exits non-zero when a file
//! is wrong at exit 0 without a warning.

use std::path::PathBuf;

use dhct_bench::real_corpus::{Corpus, CorpusFile, FileResult, SCALE_TOLERANCE, Verdict, run_file};
use dhct_bench::real_diagnosis::diagnose_file;

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
    let diagnose = args.iter().any(|a| a == "--diagnose");
    let mut wrong = 0;
    let mut counts = [0usize; 5];
    let mut verdicts = std::collections::BTreeMap::<String, usize>::new();
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
        print_row(file, &result);
        let corrected = !matches!(result.verdict, Verdict::Refused(_) | Verdict::Missing(_));
        if diagnose
            && corrected
            && let Some(input) = &result.input
        {
            let dir = out.join(format!("{i:02}-diagnosis"));
            let outcome = diagnose_file(&dhct, input, &result.args, &root, &dir);
            *verdicts.entry(print_diagnosis(&outcome)).or_default() += 1;
        }
    }
    if diagnose {
        let tally: Vec<String> = verdicts.iter().map(|(v, n)| format!("{n} {v}")).collect();
        println!("diagnosed: {}", tally.join(", "));
    }
    println!(
        "\n{} right, {} with a pass dhct flagged as off, {} refused, {} wrong, {} missing",
        counts[0], counts[4], counts[1], counts[2], counts[3]
    );
    if wrong > 0 {
        std::process::exit(1);
    }
}

fn print_row(file: &CorpusFile, r: &FileResult) {
    let verdict = match &r.verdict {
        Verdict::Right => "right".to_string(),
        Verdict::Refused(why) => format!("refused: {why}"),
        Verdict::Wrong(why) => format!("WRONG: {why}"),
        Verdict::Flagged(why) => format!("a pass off or unchecked, flagged by dhct: {why}"),
        Verdict::Missing(why) => format!("missing: {why}"),
    };
    let (scale_tolerance, shear_tolerance) = file.tolerances();
    let judged = if scale_tolerance > SCALE_TOLERANCE {
        format!(
            ", judged within {:.1} % and {shear_tolerance:.1}° (few periods)",
            100.0 * scale_tolerance
        )
    } else {
        String::new()
    };
    println!(
        "{} (~{} periods{judged}; {}): {verdict}",
        file.name,
        file.periods_across,
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

/// Prints what `dhct diagnose` said of a file; returns its verdict.
fn print_diagnosis(
    outcome: &Result<dhct_bench::real_diagnosis::DiagnosisOutcome, String>,
) -> String {
    match outcome {
        Ok(d) => {
            let list = |v: &[String]| {
                if v.is_empty() {
                    "none".to_string()
                } else {
                    v.join(", ")
                }
            };
            println!(
                "    diagnosis: {}; gap {:.2} → {:.2} × floor ({:.1} × {:.1} pm); effects: {}; remaining: {}",
                d.verdict,
                d.gap_before,
                d.gap_after,
                d.floor_m[0] * 1e12,
                d.floor_m[1] * 1e12,
                list(&d.effects),
                list(&d.remaining)
            );
            d.verdict.clone()
        }
        Err(why) => {
            println!("    diagnosis refused: {why}");
            "refused".to_string()
        }
    }
}
