//! `dhct`: distortion correction and lattice analysis of atomically resolved STM images.
//!
//! Exit codes: 0 success; 1 the input or parameters were rejected (the message says why and
//! what to try), or in `batch` at least one file failed (the others are still written);
//! 2 the command line itself was malformed.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Args, Parser, Subcommand};
use dhct_app::{apply, batch, correct, diagnose, info, lattice_check, series, simulate, units};
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
    /// Largest number of bytes a file and the images decoded from it may take, e.g. 8GiB
    /// (default 2GiB): raise it for truly huge scans.
    #[arg(long, global = true, value_parser = parse_bytes)]
    max_read_bytes: Option<u64>,
    /// Largest number of pixels of all images of one file together (default 2^28).
    #[arg(long, global = true)]
    max_read_pixels: Option<u64>,
}

/// A byte count: a number with an optional B, KiB, MiB, GiB or TiB (also kB, MB, GB, TB).
fn parse_bytes(text: &str) -> Result<u64, String> {
    let t = text.trim();
    let split = t
        .find(|c: char| !(c.is_ascii_digit() || c == '.'))
        .unwrap_or(t.len());
    let (number, unit) = t.split_at(split);
    let value: f64 = number
        .parse()
        .map_err(|_| format!("'{text}' is not a size (e.g. 8GiB)"))?;
    let factor = match unit.trim().to_ascii_lowercase().as_str() {
        "" | "b" => 1.0,
        "kib" => 1024.0,
        "mib" => 1024.0 * 1024.0,
        "gib" => 1024.0 * 1024.0 * 1024.0,
        "tib" => 1024.0 * 1024.0 * 1024.0 * 1024.0,
        "kb" => 1e3,
        "mb" => 1e6,
        "gb" => 1e9,
        "tb" => 1e12,
        other => {
            return Err(format!(
                "'{other}' is not a size unit (B, KiB, MiB, GiB, TiB)"
            ));
        }
    };
    let bytes = value * factor;
    if bytes.is_finite() && (1.0..=1e15).contains(&bytes) {
        Ok(bytes as u64)
    } else {
        Err(format!("'{text}' is not a size between 1 B and 1 PB"))
    }
}

#[derive(Subcommand)]
enum Command {
    /// Correct drift, creep and hysteresis in an atomically resolved image (trace and retrace
    /// taken from the file when present), fit the lattice and average the unit cell; write
    /// corrected images (TIFF, GSF, PNG), features.csv, model.json, unit-cell images and a
    /// self-contained report.html into OUTDIR.
    Correct {
        /// The image file (any format read: see `dhct --help`).
        input: PathBuf,
        /// A separate file holding the retrace image, if the input has none.
        retrace: Option<PathBuf>,
        /// Output directory (created if missing).
        #[arg(short, long)]
        output: PathBuf,
        /// Also diagnose the sim-to-real gap and add it to the report (diagnosis.json).
        #[arg(long)]
        diagnose: bool,
        #[command(flatten)]
        options: CorrectArgs,
    },
    /// Run `correct` on every scan file of folders (searched recursively), glob patterns
    /// and files, --jobs N at once, each into its own folder of OUTDIR (mirroring the
    /// folders it was found in), and write one table (summary.csv: status, error, lattice
    /// constant, model parameters ± 1σ, warnings). Files are recognised by content; others
    /// are skipped with a note. Exits with 1 when any file failed (the others are written).
    Batch {
        /// Folders, glob patterns (quoted, e.g. 'data/**/*.sm4') or files.
        #[arg(required = true)]
        inputs: Vec<String>,
        /// Output directory (one folder per input file, and summary.csv).
        #[arg(short, long)]
        output: PathBuf,
        /// Files corrected at once (and threads in all); default: the number of CPUs.
        #[arg(long, short = 'j', value_parser = clap::value_parser!(u16).range(1..))]
        jobs: Option<u16>,
        /// Only this part of the sorted file list: i/n takes files i, i+n, i+2n, ...
        /// (0 <= i < n), e.g. --shard $SLURM_ARRAY_TASK_ID/$SLURM_ARRAY_TASK_COUNT; give
        /// each shard its own -o and merge the tables with `dhct summarize`.
        #[arg(long)]
        shard: Option<batch::Shard>,
        #[command(flatten)]
        options: CorrectArgs,
    },
    /// Fit one model to frames of one area taken one after another (folders, glob patterns
    /// and files; ordered by the start time each file records): drift continuous over the
    /// whole session, a creep after every move of the frame, one hysteresis law; register
    /// every frame into one sample frame. Writes series.json, features.csv (every frame's
    /// features in the session frame), trajectory.csv (the drift with 1σ) and registered/
    /// (each frame's images on one grid, their stack as a multi-page TIFF, and the mean).
    Series {
        /// Folders, glob patterns (quoted) or files: the frames.
        #[arg(required = true)]
        inputs: Vec<String>,
        /// Output directory (created if missing).
        #[arg(short, long)]
        output: PathBuf,
        /// Interior knots of the drift spline over the session (default: chosen by
        /// cross-validation; with --register image, one per frame after the first).
        #[arg(long, value_parser = clap::value_parser!(u16).range(0..=1000))]
        knots: Option<u16>,
        /// How frames are placed: `lattice` (default: every frame's features against the
        /// lattice, with scale and hysteresis) or `image` (frames without a resolved
        /// lattice: bands of each frame's lines found in the frame before; the files'
        /// pixel size and any hysteresis are kept as they are).
        #[arg(long, value_enum, default_value_t = Registration::Lattice)]
        register: Registration,
        #[command(flatten)]
        options: CorrectArgs,
    },
    /// Merge the summary.csv tables of several batch runs (e.g. the shards of a scheduler
    /// array) into one CSV: the union of their columns, every row once.
    Summarize {
        /// summary.csv files, or batch output folders holding one.
        #[arg(required = true)]
        inputs: Vec<PathBuf>,
        /// The merged table to write (CSV).
        #[arg(short, long)]
        output: PathBuf,
    },
    /// Diagnose the sim-to-real gap of the correction `correct` makes (the same pipeline,
    /// options and mask): where it and the image disagree (in time, fast-line phase, space,
    /// trace vs retrace), which unmodelled effect explains it and how far the gap shrinks
    /// once it is added; writes diagnosis.json and diagnosis.html into OUTDIR. (Its
    /// validation on simulated scans: `cargo run --release -p dhct-validation`.)
    Diagnose {
        /// The image file.
        input: PathBuf,
        /// A separate file holding the retrace image.
        retrace: Option<PathBuf>,
        /// Output directory.
        #[arg(short, long)]
        output: PathBuf,
        #[command(flatten)]
        options: CorrectArgs,
    },
    /// Show the channels, sizes, scan geometry and timing of an STM file (any format read,
    /// detected from content: see `dhct --help`).
    Info {
        /// The file to describe.
        file: PathBuf,
        /// Print a JSON summary instead of text.
        #[arg(long)]
        json: bool,
        #[command(flatten)]
        geometry: GeometryArgs,
    },
    /// Apply a model `dhct correct` fitted (its model.json) to another file recorded in the
    /// same frame and timing (a channel saved on its own, a repeated export): write its
    /// corrected trace and retrace (TIFF with pixel size, GSF) into OUTDIR. A file whose
    /// size, pixel size, timing or scan directions differ is refused, naming what differs.
    /// With --points, move points of that frame into the sample frame with their 1σ.
    Apply {
        /// The model.json of a `dhct correct` run.
        model: PathBuf,
        /// The file to correct.
        #[arg(required_unless_present = "points")]
        input: Option<PathBuf>,
        /// A separate file holding its retrace, if any.
        retrace: Option<PathBuf>,
        /// Output directory.
        #[arg(short, long)]
        output: PathBuf,
        /// The channel to correct (default: the topography).
        #[arg(long)]
        channel: Option<String>,
        /// A CSV file of points of the model's frame (spectroscopy positions, grid points):
        /// columns x_px, y_px (pixels) or x_m, y_m (metres from the first pixel's centre),
        /// optionally t_s (seconds since the frame start) and pass; written with their
        /// sample-frame position and 1σ to OUTDIR/points_corrected.csv.
        #[arg(long, value_name = "POINTS.csv")]
        points: Option<PathBuf>,
        /// The grid of the corrected images, as for `correct`: frame (default) or full.
        #[arg(long, value_parser = parse_extent)]
        extent: Option<correct::Extent>,
        /// Replace an earlier run's output folder.
        #[arg(long)]
        overwrite: bool,
    },
    /// Check a lattice against the contract every lattice keeps (neighbour shells and
    /// counts, the neighbour window, the plane group's metric and motif symmetry about its
    /// origin, the translation cell, the feature appearance): a catalogue name or a
    /// lattice file (TOML/JSON). Names every broken rule; exits with 1 when one is.
    Lattice {
        #[command(subcommand)]
        action: LatticeAction,
    },
    /// Simulate an STM acquisition (trace and retrace) of a lattice surface with drift,
    /// creep, hysteresis and other distortions; write the images (SM4, ...) and the ground
    /// truth (ground_truth.json, displacement fields as NPY) into a directory.
    Simulate {
        /// Simulation config, TOML or JSON (see docs/simulator.md).
        #[arg(required_unless_present_any = ["preset", "list_presets"], conflicts_with = "preset")]
        config: Option<PathBuf>,
        /// Use a built-in preset instead of a config file (see --list-presets).
        #[arg(long)]
        preset: Option<String>,
        /// List the built-in presets and exit.
        #[arg(long)]
        list_presets: bool,
        /// Output directory (created if missing).
        #[arg(short, long, required_unless_present_any = ["list_presets", "print_config"])]
        output: Option<PathBuf>,
        /// Replace the config's random seed.
        #[arg(long)]
        seed: Option<u64>,
        /// Print the config as TOML (e.g. a preset to edit) instead of simulating.
        #[arg(long)]
        print_config: bool,
    },
}

/// How `dhct series` places its frames.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum Registration {
    /// Every frame's features against the lattice (scale and hysteresis measured).
    Lattice,
    /// What the frames' images share (no lattice needed; scale and hysteresis as stated).
    Image,
}

/// What `dhct lattice` does.
#[derive(Subcommand)]
enum LatticeAction {
    /// Check NAME (a catalogue lattice) or FILE (a lattice file) against the contract.
    Check {
        /// A catalogue name (graphite, hexagonal, kagome, ...) or a lattice file.
        lattice: String,
        /// Nearest-neighbour distance, e.g. 3.2A (needed by catalogue shapes without a
        /// constant; replaces a file's scale).
        #[arg(long, value_parser = parse_nn)]
        nn: Option<correct::Length>,
    },
}

/// Options of `correct` and `batch`; each replaces the same setting of `--config`.
#[derive(Args, Default)]
struct CorrectArgs {
    /// A TOML config (e.g. the config.toml a previous run wrote); flags override it.
    #[arg(long)]
    config: Option<PathBuf>,
    /// A catalogue lattice: graphite (default), honeycomb, hexagonal, sam-sqrt3, si111-7x7,
    /// square, rectangular, centred-rectangular, oblique, kagome (docs/lattices.md); or a
    /// lattice file (TOML/JSON; its numbers may be rounded).
    #[arg(long)]
    lattice: Option<String>,
    /// The channel to analyse, e.g. Z or Current (case-insensitive; a whole name first, else
    /// a part of one; `dhct info FILE` lists them). Default: the topography.
    #[arg(long)]
    channel: Option<String>,
    /// Nearest-neighbour distance, e.g. 2.46A or 0.246nm (a bare number is metres), or
    /// `auto`: the distance the image shows in the file's units. Presets with a known
    /// constant (graphite, sam-sqrt3, honeycomb, si111-7x7) need none; for the others it
    /// sets the size of the catalogue's shape. The image is checked against it: a constant that would need the file's pixel size to be off by more than
    /// 15 % (a factor 1.75 for a preset's constant) stops the run.
    #[arg(long, value_parser = parse_nn)]
    nn: Option<correct::Length>,
    /// The lattice constant is right and the file's pixel size may be wrong by any factor
    /// (up to ×10): calibrate from the lattice without the plausibility limit.
    #[arg(long)]
    calibrate: bool,
    /// Do not check the lattice and its constant against the image (and do not calibrate
    /// from it): for users who know better.
    #[arg(long)]
    trust_inputs: bool,
    /// Mask image (PNG, NPY, ...): analyse only where it is bright; each connected region is
    /// fitted as its own lattice domain.
    #[arg(long)]
    mask: Option<PathBuf>,
    /// Replace an output folder that holds an earlier dhct run (never one holding other
    /// files).
    #[arg(long)]
    overwrite: bool,
    /// bright (atoms are maxima, default) or dark (minima).
    #[arg(long, value_parser = parse_polarity)]
    polarity: Option<dhct_features::Polarity>,
    /// Plane group of the symmetry-averaged cell, e.g. p3m1 (default: the lattice's).
    #[arg(long)]
    plane_group: Option<dhct_lattice::PlaneGroup>,
    /// Colour map of the pictures: gold (default), viridis, inferno, magma, plasma,
    /// cividis, greys.
    #[arg(long, value_parser = parse_colormap)]
    colormap: Option<dhct_sm4_io::png_file::Colormap>,
    /// `all`: also correct every other image channel of the file (current, dI/dV, ...) with
    /// the model fitted on the analysed channel: corrected_{channel}_{trace,retrace}.tiff
    /// and .gsf, with the pixel size and the channel's unit.
    #[arg(long, value_parser = parse_channels)]
    channels: Option<correct::ChannelSet>,
    /// The grid of the corrected TIFF and GSF files: frame (default: the scan's own; what
    /// the correction moves outside it is cropped) or full (every corrected pixel on a
    /// larger grid of the same pitch, no-data around; the GSF holds its origin).
    #[arg(long, value_parser = parse_extent)]
    extent: Option<correct::Extent>,
    /// Also write each pass's displacement field: displacement_trace.npy (shape 2 × rows ×
    /// columns: dx, dy in metres, where the tip really was relative to the controller) and
    /// displacement_trace.tiff (the same as two float pages with the pixel size).
    #[arg(long)]
    displacement: bool,
    /// Print a JSON summary on stdout instead of text.
    #[arg(long)]
    json: bool,
    /// No progress display.
    #[arg(long, short)]
    quiet: bool,
    #[command(flatten)]
    geometry: GeometryArgs,
}

impl CorrectArgs {
    /// The config file (if any) with the flags applied on top.
    fn config(&self) -> anyhow::Result<correct::CorrectConfig> {
        let base = match &self.config {
            Some(path) => correct::CorrectConfig::read(path)?,
            None => correct::CorrectConfig::default(),
        };
        Ok(base.overridden_by(correct::CorrectConfig {
            lattice: self.lattice.clone(),
            channel: self.channel.clone(),
            nn: self.nn.clone(),
            calibrate: self.calibrate.then_some(true),
            trust_inputs: self.trust_inputs.then_some(true),
            polarity: self.polarity,
            mask: self.mask.clone(),
            plane_group: self.plane_group,
            colormap: self.colormap,
            displacement: self.displacement.then_some(true),
            extent: self.extent,
            channels: self.channels,
            geometry: self.geometry.overrides(),
            overwrite: self.overwrite,
            ..correct::CorrectConfig::default()
        }))
    }
}

fn parse_nn(text: &str) -> Result<correct::Length, String> {
    if text.trim().eq_ignore_ascii_case("auto") {
        Ok(correct::Length::Text("auto".into()))
    } else {
        units::parse_length(text).map(correct::Length::Metres)
    }
}

fn parse_polarity(text: &str) -> Result<dhct_features::Polarity, String> {
    match text.to_ascii_lowercase().as_str() {
        "bright" => Ok(dhct_features::Polarity::Bright),
        "dark" => Ok(dhct_features::Polarity::Dark),
        _ => Err(format!("'{text}' is not a polarity (use bright or dark)")),
    }
}

fn parse_channels(text: &str) -> Result<correct::ChannelSet, String> {
    match text.trim().to_ascii_lowercase().as_str() {
        "all" => Ok(correct::ChannelSet::All),
        other => Err(format!(
            "'{other}' is not a channel set: use all (the analysed channel is --channel)"
        )),
    }
}

fn parse_extent(text: &str) -> Result<correct::Extent, String> {
    match text.trim().to_ascii_lowercase().as_str() {
        "frame" => Ok(correct::Extent::Frame),
        "full" => Ok(correct::Extent::Full),
        other => Err(format!(
            "'{other}' is not an extent: use frame (the scan's own grid) or full (every \
             corrected pixel)"
        )),
    }
}

fn parse_colormap(text: &str) -> Result<dhct_sm4_io::png_file::Colormap, String> {
    dhct_sm4_io::png_file::Colormap::parse(text).ok_or_else(|| {
        format!(
            "'{text}' is not a colour map (gold, viridis, inferno, magma, plasma, cividis, greys)"
        )
    })
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
    let cli = parse_command_line();
    let defaults = dhct_sm4_io::ReadLimits::default();
    dhct_app::read_limits::set(dhct_sm4_io::ReadLimits {
        max_bytes: cli.max_read_bytes.unwrap_or(defaults.max_bytes),
        max_pixels: cli.max_read_pixels.unwrap_or(defaults.max_pixels),
    });
    let result = match &cli.command {
        Command::Correct {
            input,
            retrace,
            output,
            diagnose,
            options,
        } => options.config().and_then(|config| {
            let summary = correct::run(correct::CorrectRequest {
                input,
                retrace: retrace.as_deref(),
                output,
                config,
                progress: !options.quiet && !options.json,
                diagnose: *diagnose,
            })?;
            if options.json {
                diagnose::write_stdout(&format!("{}\n", serde_json::to_string_pretty(&summary)?))?;
            } else {
                diagnose::write_stdout(&correct::text_summary(&summary, output))?;
            }
            // Warnings go to stderr whatever --quiet and --json say.
            eprint!("{}", correct::warning_lines(&summary));
            Ok(())
        }),
        Command::Diagnose {
            input,
            retrace,
            output,
            options,
        } => options.config().and_then(|config| {
            diagnose::run_file(input, retrace.as_deref(), output, config, options.json)
        }),
        Command::Batch {
            inputs,
            output,
            jobs,
            shard,
            options,
        } => options.config().and_then(|config| {
            batch::run(&batch::BatchRequest {
                inputs,
                output,
                config: &config,
                jobs: jobs.map(usize::from),
                shard: *shard,
                json: options.json,
                progress: !options.quiet,
            })
        }),
        Command::Series {
            inputs,
            output,
            knots,
            register,
            options,
        } => options.config().and_then(|config| {
            let request = series::SeriesRequest {
                inputs,
                output,
                config,
                knots: knots.map(usize::from),
            };
            // (series.json's content, the text summary, the warnings)
            let (json, text, warnings) = match register {
                Registration::Lattice => {
                    let summary = series::run(&request)?;
                    (
                        serde_json::to_string_pretty(&summary)?,
                        series::text_summary(&summary, output),
                        series::warning_lines(&summary),
                    )
                }
                Registration::Image => {
                    let summary = series::by_image::run(&request)?;
                    (
                        serde_json::to_string_pretty(&summary)?,
                        series::by_image::text_summary(&summary, output),
                        series::by_image::warning_lines(&summary),
                    )
                }
            };
            diagnose::write_stdout(&if options.json { json + "\n" } else { text })?;
            // Warnings go to stderr whatever --quiet and --json say.
            eprint!("{warnings}");
            Ok(())
        }),
        Command::Summarize { inputs, output } => {
            batch::summarize(inputs, output).and_then(|text| diagnose::write_stdout(&text))
        }
        Command::Info {
            file,
            json,
            geometry,
        } => info::run(file, &geometry.overrides(), *json),
        Command::Apply {
            model,
            input,
            retrace,
            output,
            channel,
            points,
            extent,
            overwrite,
        } => apply::run(&apply::ApplyRequest {
            model,
            input: input.as_deref(),
            retrace: retrace.as_deref(),
            channel: channel.as_deref(),
            points: points.as_deref(),
            output,
            extent: extent.unwrap_or_default(),
            overwrite: *overwrite,
        })
        .map(|applied| print!("{}", apply::describe(&applied, output))),
        Command::Lattice {
            action: LatticeAction::Check { lattice, nn },
        } => nn
            .as_ref()
            .map(|l| l.metres())
            .transpose()
            .and_then(|nn_m| lattice_check::run(lattice, nn_m))
            .map(|text| print!("{text}")),
        Command::Simulate {
            config,
            preset,
            list_presets,
            output,
            seed,
            print_config,
        } => {
            let source = match (config, preset) {
                (Some(path), _) => Some(simulate::ConfigSource::File(path)),
                (None, Some(name)) => Some(simulate::ConfigSource::Preset(name)),
                (None, None) => None,
            };
            match source {
                _ if *list_presets => {
                    print!("{}", simulate::list_presets());
                    Ok(())
                }
                Some(source) => simulate::run(&simulate::SimulateRequest {
                    source,
                    output: output.as_deref(),
                    seed: *seed,
                    print_config: *print_config,
                })
                .map(|text| print!("{text}")),
                None => Err(anyhow::anyhow!(
                    "give a simulation config file or --preset NAME (see --list-presets)"
                )),
            }
        }
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("error: {error:#}");
            ExitCode::from(1)
        }
    }
}

/// The command line, with the formats read listed in `--help` from the one table in the
/// code (`FileFormat::ALL`).
fn parse_command_line() -> Cli {
    use clap::{CommandFactory, FromArgMatches};
    let formats = format!(
        "Formats read (detected from content): {}.",
        dhct_scan::FileFormat::read_list()
    );
    let matches = Cli::command().after_help(formats).get_matches();
    Cli::from_arg_matches(&matches).unwrap_or_else(|e| e.exit())
}
