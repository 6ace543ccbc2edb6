//! Runs the diagnosis's validation sweep and prints every case, each set's confusion
//! matrix and summary; exits non-zero when a judged set misses the acceptance targets.
//!
//! ```text
//! cargo run --release -p dhct-validation                    # the default sweep (~25 min on 2 cores)
//! cargo run --release -p dhct-validation -- rendered-dev    # one set (names in sets.toml)
//! cargo run --release -p dhct-validation -- --seeds 1 --json report.json
//! ```

use std::io::Write as _;
use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use dhct_validation::{Catalogue, ValidationOptions, validate};

/// The withheld-effect validation of `dhct diagnose` on simulated scans.
#[derive(Parser)]
#[command(name = "dhct-validation")]
struct Args {
    /// Sets to run (names in the set file); the default sweep when none is given.
    sets: Vec<String>,
    /// At most this many seeds per effect and mixture, twice as many effect-free ones.
    #[arg(long)]
    seeds: Option<usize>,
    /// A set file other than the shipped `crates/validation/sets.toml`.
    #[arg(long)]
    set_file: Option<PathBuf>,
    /// Also run the first tuned seed of every effect through rendered images.
    #[arg(long)]
    image_path: bool,
    /// Write the whole report as JSON here.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Also print the noise floor each case found.
    #[arg(long)]
    floors: bool,
}

fn main() -> ExitCode {
    match run(Args::parse()) {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => {
            eprintln!("the validation missed its acceptance targets (see the table above)");
            ExitCode::FAILURE
        }
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(2)
        }
    }
}

fn run(args: Args) -> Result<bool, Box<dyn std::error::Error>> {
    let catalogue = match &args.set_file {
        Some(path) => Catalogue::parse(&std::fs::read_to_string(path)?)?,
        None => Catalogue::shipped(),
    };
    let names: Vec<&str> = args.sets.iter().map(String::as_str).collect();
    let mut options = ValidationOptions::of_catalogue(&catalogue, &names)?;
    options.image_path = args.image_path;
    if let Some(n) = args.seeds {
        options.truncate_seeds(n);
    }
    let report = validate(&options);
    println!("{report}");
    if args.floors {
        println!("floors (pm):");
        for c in &report.cases {
            let [x, y] = c.noise_floor_m.map(|v| v * 1e12);
            println!("{:<44} {x:.2} × {y:.2}", c.name);
        }
    }
    if let Some(path) = &args.json {
        let text = serde_json::to_string_pretty(&report)?;
        dhct_sm4_io::write_atomically(path, |w| w.write_all(text.as_bytes()).map_err(Into::into))?;
    }
    Ok(report.accepted())
}
