//! `dhct`: distortion correction and lattice analysis of atomically resolved STM images.
//!
//! Exit codes: 0 success; 1 the input or parameters were rejected (the message says why and
//! what to try); 2 the command line itself was malformed.

mod info;
mod units;

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Args, Parser, Subcommand};
use dhct_scan::ScanDirection;
use dhct_sm4_io::GeometryOverrides;

#[derive(Parser)]
#[command(
    name = "dhct",
    version,
    about = "Distortion correction (DHCT) and lattice analysis of STM images"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Show the channels, sizes, scan geometry and timing of an STM file
    /// (RHK SM4, Nanonis SXM, ISO 28600, GSF, NPY, TIFF; detected from content).
    Info {
        /// The file to describe.
        file: PathBuf,
        /// Print a JSON summary instead of text.
        #[arg(long)]
        json: bool,
        #[command(flatten)]
        geometry: GeometryArgs,
    },
}

/// Scan geometry given on the command line; replaces or supplies what the file says.
#[derive(Args, Default)]
struct GeometryArgs {
    /// Pixel pitch along x and y, e.g. 0.2nm or 2A (a bare number is metres).
    #[arg(long, value_parser = units::parse_length)]
    pitch: Option<f64>,
    /// Time per pixel along the fast axis, e.g. 1.51ms (a bare number is seconds).
    #[arg(long, value_parser = units::parse_time, conflicts_with = "line_time")]
    pixel_period: Option<f64>,
    /// Time per line in one direction, e.g. 0.774s.
    #[arg(long, value_parser = units::parse_time)]
    line_time: Option<f64>,
    /// Dead time at each end of a line, e.g. 5ms.
    #[arg(long, value_parser = units::parse_time)]
    turnaround: Option<f64>,
    /// Fast direction of the trace: right, left, up or down.
    #[arg(long, value_parser = parse_direction)]
    fast: Option<ScanDirection>,
    /// Slow scan direction: down, up, right or left.
    #[arg(long, value_parser = parse_direction)]
    slow: Option<ScanDirection>,
}

impl GeometryArgs {
    fn overrides(&self) -> GeometryOverrides {
        GeometryOverrides {
            pitch_x: self.pitch,
            pitch_y: self.pitch,
            pixel_period: self.pixel_period,
            line_time: self.line_time,
            turnaround_time: self.turnaround,
            trace_fast: self.fast,
            slow: self.slow,
        }
    }
}

fn parse_direction(text: &str) -> Result<ScanDirection, String> {
    ScanDirection::parse(text)
        .ok_or_else(|| format!("'{text}' is not a scan direction (use right, left, up or down)"))
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match &cli.command {
        Command::Info {
            file,
            json,
            geometry,
        } => info::run(file, &geometry.overrides(), *json),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("error: {error:#}");
            ExitCode::from(1)
        }
    }
}
