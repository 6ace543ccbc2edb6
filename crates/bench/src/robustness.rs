//! Robustness sweep: the whole chain on inputs that get harder along one axis at a time
//! (noise, drift, lattice type, image size, missing retrace, masks with holes) and on
//! inputs without a lattice. Every run is wrapped in `catch_unwind`: a panic anywhere is a
//! finding. Inputs without a lattice must end in an error that says what to try; the
//! others report how the accuracy degrades (corrected rms vs truth, fraction indexed).

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::time::Instant;

use dhct_features::LineCorrection;
use dhct_scan::{ImageChannel, ScanPair, ScanPass};
use dhct_simulate::{EffectConfig, LatticeConfig, Simulation, SimulationConfig, presets};
use ndarray::Array2;
use serde::Serialize;

use crate::accuracy::{Accuracy, accuracy};
use crate::scenario::pipeline_options;
use crate::table::Table;

/// How large a sweep to run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SweepSize {
    /// 256² images, a few levels per axis (the test; well under a minute in release).
    Quick,
    /// 512² base images, more levels, sizes up to 2048².
    Full,
}

/// What the run must end in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum Expect {
    /// A full analysis (the input is well within the method's range).
    Analysis,
    /// An error naming the problem (there is no lattice to find).
    Error,
    /// Either, but no panic (degradation is being measured).
    Either,
}

/// Which pixels the analysis may use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum MaskKind {
    /// No mask.
    None,
    /// One circular hole of radius ¼ of the width in the middle.
    CentralHole,
    /// Five small circular holes.
    ManyHoles,
    /// A vertical band masked out across the whole height: two regions.
    TwoRegions,
    /// Only a 6 % × 6 % square is usable (too few features).
    Tiny,
}

/// The image that goes in.
#[derive(Debug, Clone)]
pub enum Input {
    /// A simulation (trace and retrace), optionally dropping one pass.
    Simulated {
        /// The simulation.
        config: SimulationConfig,
        /// Keep the trace.
        trace: bool,
        /// Keep the retrace.
        retrace: bool,
    },
    /// The geometry of `config`, filled with Gaussian white noise of `sigma_m` (no lattice).
    PureNoise {
        /// Supplies the geometry.
        config: SimulationConfig,
        /// Noise rms, metres.
        sigma_m: f64,
    },
    /// The geometry of `config`, every pixel 0 (no lattice).
    Flat {
        /// Supplies the geometry.
        config: SimulationConfig,
    },
    /// A simulation with a block of rows set to NaN in both passes (an interrupted scan).
    NanRows {
        /// The simulation.
        config: SimulationConfig,
        /// Fraction of the rows (at the bottom) that are NaN.
        fraction: f64,
    },
}

/// One run of the sweep.
#[derive(Debug, Clone)]
pub struct Case {
    /// Which axis of the sweep.
    pub axis: &'static str,
    /// The level on that axis.
    pub level: String,
    /// The image.
    pub input: Input,
    /// The lattice the analysis is told (`None` = the simulated one).
    pub analyse_as: Option<LatticeConfig>,
    /// The mask.
    pub mask: MaskKind,
    /// What it must end in.
    pub expect: Expect,
    /// Turn the default median line levelling off.
    pub no_line_levelling: bool,
}

/// How a run ended.
#[derive(Debug, Clone, Serialize)]
pub enum Outcome {
    /// The chain produced an analysis (its accuracy; `None` for an input without truth).
    Analysis(Option<Box<Accuracy>>),
    /// The chain returned an error (its message).
    Error(String),
    /// Something panicked (its message).
    Panic(String),
}

/// One row of the result table.
#[derive(Debug, Clone, Serialize)]
pub struct Row {
    /// Axis of the sweep.
    pub axis: &'static str,
    /// Level on it.
    pub level: String,
    /// What was expected.
    pub expect: Expect,
    /// What happened.
    pub outcome: Outcome,
    /// Wall time of simulate + analyse, seconds.
    pub seconds: f64,
}

/// An analysis is silently wrong if the corrected positions are more than this many
/// times the localisation noise floor from the truth…
pub const WRONG_OVER_FLOOR: f64 = 3.0;

/// …or the fitted lattice constant is off by more than this fraction.
pub const WRONG_LATTICE_CONSTANT: f64 = 5e-3;

impl Row {
    /// True if the chain returned an analysis far from the truth without an error.
    pub fn silently_wrong(&self) -> bool {
        match &self.outcome {
            Outcome::Analysis(Some(a)) => {
                !(a.corrected_over_floor <= WRONG_OVER_FLOOR
                    && a.lattice_constant_error
                        .iter()
                        .all(|e| e.abs() <= WRONG_LATTICE_CONSTANT))
            }
            _ => false,
        }
    }

    /// True if the outcome meets the expectation (and nothing panicked). An expected
    /// analysis must also be right (not [`Row::silently_wrong`]).
    pub fn as_expected(&self) -> bool {
        match (&self.outcome, self.expect) {
            (Outcome::Panic(_), _) => false,
            (Outcome::Analysis(_), Expect::Analysis) => !self.silently_wrong(),
            (Outcome::Analysis(_), Expect::Error) => false,
            (Outcome::Error(_), Expect::Analysis) => false,
            (Outcome::Error(message), Expect::Error) => is_clear(message),
            _ => true,
        }
    }
}

/// An error message is clear if it names what was wrong (features, lattice or mask) and
/// is more than a bare code.
pub fn is_clear(message: &str) -> bool {
    let lower = message.to_lowercase();
    message.len() >= 30
        && ["feature", "lattice", "mask"]
            .iter()
            .any(|w| lower.contains(w))
}

fn with_white_noise(mut config: SimulationConfig, sigma_m: f64) -> SimulationConfig {
    config.noise.white_sigma_m = sigma_m;
    config
}

/// Slow-scan speed of `config`, m/s: one pitch per line pair (trace + retrace).
pub fn slow_speed_m_per_s(config: &SimulationConfig) -> f64 {
    let scan = &config.scan;
    let line_s = scan.width_m / scan.fast_speed_m_per_s + scan.turnaround_s;
    (scan.height_m / scan.rows as f64) / (2.0 * line_s)
}

/// Thermal drift of `fraction` × the slow-scan speed against the slow scan (−y), plus
/// 0.625 × that along +x (the direction of the `ci-small` drift, (5, −8) pm/s), no
/// acceleration. The slow scale of the image changes by `fraction`.
fn with_relative_drift(mut config: SimulationConfig, fraction: f64) -> SimulationConfig {
    let v = fraction * slow_speed_m_per_s(&config);
    for effect in &mut config.effects {
        if let EffectConfig::ThermalDrift(drift) = effect {
            drift.velocity_m_per_s = [0.625 * v, -v];
            drift.acceleration_m_per_s2 = [0.0, 0.0];
        }
    }
    config
}

/// `config` at `pixels`² with the same pitch, and the fast speed scaled with the width so
/// that line and frame times, and so every time-dependent displacement in metres, stay
/// as they were (a larger image is then relatively less distorted, never more).
fn with_size(mut config: SimulationConfig, pixels: usize) -> SimulationConfig {
    let pitch_m = config.scan.width_m / config.scan.columns as f64;
    let ratio = pixels as f64 / config.scan.columns as f64;
    config.scan.columns = pixels;
    config.scan.rows = pixels;
    config.scan.width_m = pitch_m * pixels as f64;
    config.scan.height_m = pitch_m * pixels as f64;
    config.scan.fast_speed_m_per_s *= ratio;
    config
}

fn with_lattice(mut config: SimulationConfig, lattice: &LatticeConfig) -> SimulationConfig {
    config.surface.lattice = lattice.clone();
    config.surface.feature.sigma_m = match lattice {
        LatticeConfig::Graphene | LatticeConfig::Honeycomb { .. } => [0.4e-10, 0.4e-10],
        LatticeConfig::SamSqrt3 => [1.2e-10, 1.2e-10],
        LatticeConfig::Square { a_m } | LatticeConfig::Hexagonal { a_m } => {
            [0.25 * a_m, 0.25 * a_m]
        }
        _ => config.surface.feature.sigma_m,
    };
    config
}

/// The base simulation: the `ci-small` physics (graphite, 15.6 pm/px, 256² at 50 nm/s,
/// drift (5, −8) pm/s, creep, hysteresis, 2 pm white noise, frame time 41 s) at
/// `pixels`², with the same line and frame times (see `with_size`).
pub fn base(pixels: usize) -> SimulationConfig {
    with_size(presets::ci_small(), pixels)
}

fn simulated(config: SimulationConfig) -> Input {
    Input::Simulated {
        config,
        trace: true,
        retrace: true,
    }
}

/// The cases of a sweep.
pub fn cases(size: SweepSize) -> Vec<Case> {
    let pixels = match size {
        SweepSize::Quick => 256,
        SweepSize::Full => 512,
    };
    let base = base(pixels);
    let mut cases = vec![case(
        "baseline",
        format!("{pixels}² graphite, 2 pm noise"),
        simulated(base.clone()),
        Expect::Analysis,
    )];
    cases.extend(noise_cases(size, &base));
    cases.extend(drift_cases(size, &base));
    cases.extend(lattice_cases(pixels, &base));
    cases.extend(size_cases(size, &base));
    cases.extend(pass_and_mask_cases(&base));
    cases.extend(no_lattice_cases(&base));
    cases
}

/// A case on `axis` at `level` with the simulated lattice, no mask and line levelling.
fn case(axis: &'static str, level: String, input: Input, expect: Expect) -> Case {
    Case {
        axis,
        level,
        input,
        analyse_as: None,
        mask: MaskKind::None,
        expect,
        no_line_levelling: false,
    }
}

/// White noise of increasing rms (the feature height is 40 pm).
fn noise_cases(size: SweepSize, base: &SimulationConfig) -> Vec<Case> {
    let noise_pm: &[f64] = match size {
        SweepSize::Quick => &[5.0, 10.0, 20.0, 40.0],
        SweepSize::Full => &[5.0, 10.0, 15.0, 20.0, 30.0, 40.0, 80.0],
    };
    let mut cases = Vec::new();
    for &pm in noise_pm {
        let expect = if pm <= 10.0 {
            Expect::Analysis
        } else {
            Expect::Either
        };
        cases.push(case(
            "noise",
            format!("white {pm} pm (SNR {:.1})", 40.0 / pm),
            simulated(with_white_noise(base.clone(), pm * 1e-12)),
            expect,
        ));
    }
    cases
}

/// Drift against the slow scan as a fraction of the slow-scan speed (the slow scale
/// changes by that fraction; the paper's Fig. 3 shows 20 %).
fn drift_cases(size: SweepSize, base: &SimulationConfig) -> Vec<Case> {
    let fractions: &[f64] = match size {
        SweepSize::Quick => &[0.0, 0.1, 0.2, 0.3, 0.5],
        SweepSize::Full => &[0.0, 0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.35, 0.4, 0.5],
    };
    let slow = slow_speed_m_per_s(base);
    let mut cases = Vec::new();
    for &fraction in fractions {
        // Up to 40 % a first model (from the k nearest raw neighbours when the NN window
        // selects too few) and the neighbours found again in the corrected frame recover
        // the drift; at 50 % the raw lattice is beyond recognition (a clear error).
        let expect = if fraction <= 0.4 {
            Expect::Analysis
        } else {
            Expect::Either
        };
        cases.push(case(
            "drift",
            format!(
                "{:.0} % of slow speed ({:.0}, {:.0}) pm/s",
                100.0 * fraction,
                0.625 * fraction * slow * 1e12,
                -fraction * slow * 1e12
            ),
            simulated(with_relative_drift(base.clone(), fraction)),
            expect,
        ));
    }
    cases
}

/// Other lattice types at the same pitch (`pixels`² unless the cell needs more), and two
/// without line levelling.
fn lattice_cases(pixels: usize, base: &SimulationConfig) -> Vec<Case> {
    let mut cases = Vec::new();
    // Lattice type, at the same pitch; the SAM cell is large, so its image is larger.
    // Graphene with the default median line levelling is measured, not required: the
    // levelling shifts its features by ~0.9 px rms along y and the lattice fit then fails
    // (issue 9 report); without levelling it must work.
    for (name, lattice, pixels, expect) in [
        (
            "square 3 Å",
            LatticeConfig::Square { a_m: 3e-10 },
            pixels,
            Expect::Analysis,
        ),
        (
            "honeycomb (graphene)",
            LatticeConfig::Graphene,
            pixels,
            Expect::Either,
        ),
        (
            "honeycomb (graphene) 2× size",
            LatticeConfig::Graphene,
            pixels * 2,
            Expect::Either,
        ),
        (
            "sam-sqrt3",
            LatticeConfig::SamSqrt3,
            pixels * 3 / 2,
            Expect::Analysis,
        ),
        (
            "hexagonal 4 Å",
            LatticeConfig::Hexagonal { a_m: 4e-10 },
            pixels,
            Expect::Analysis,
        ),
    ] {
        cases.push(case(
            "lattice",
            format!("{name}, {pixels}²"),
            simulated(with_lattice(with_size(base.clone(), pixels), &lattice)),
            expect,
        ));
    }
    for (name, lattice) in [
        ("honeycomb (graphene)", LatticeConfig::Graphene),
        ("square 3 Å", LatticeConfig::Square { a_m: 3e-10 }),
    ] {
        cases.push(Case {
            no_line_levelling: true,
            ..case(
                "lattice",
                format!("{name}, {pixels}², no line levelling"),
                simulated(with_lattice(base.clone(), &lattice)),
                Expect::Analysis,
            )
        });
    }
    cases
}

/// Image sizes at the same pitch (and line and frame times).
fn size_cases(size: SweepSize, base: &SimulationConfig) -> Vec<Case> {
    let sizes: &[usize] = match size {
        SweepSize::Quick => &[96, 128, 512],
        SweepSize::Full => &[96, 128, 256, 1024, 2048],
    };
    sizes
        .iter()
        .map(|&n| {
            case(
                "size",
                format!("{n}²"),
                simulated(with_size(base.clone(), n)),
                if n >= 128 {
                    Expect::Analysis
                } else {
                    Expect::Either
                },
            )
        })
        .collect()
}

/// One pass missing, and masks with holes, two regions or too little left.
fn pass_and_mask_cases(base: &SimulationConfig) -> Vec<Case> {
    let mut cases = Vec::new();
    // Missing passes.
    for (level, trace, retrace) in [("trace only", true, false), ("retrace only", false, true)] {
        cases.push(case(
            "passes",
            level.into(),
            Input::Simulated {
                config: base.clone(),
                trace,
                retrace,
            },
            Expect::Analysis,
        ));
    }
    // Masks.
    for (level, mask, expect) in [
        ("central hole", MaskKind::CentralHole, Expect::Analysis),
        ("five holes", MaskKind::ManyHoles, Expect::Analysis),
        ("two regions", MaskKind::TwoRegions, Expect::Analysis),
        ("tiny (6 % square)", MaskKind::Tiny, Expect::Error),
    ] {
        cases.push(Case {
            mask,
            ..case("mask", level.into(), simulated(base.clone()), expect)
        });
    }
    cases
}

/// No lattice (noise, a flat image), the wrong lattice, and rows of missing data.
fn no_lattice_cases(base: &SimulationConfig) -> Vec<Case> {
    vec![
        case(
            "no lattice",
            "pure noise".into(),
            Input::PureNoise {
                config: base.clone(),
                sigma_m: 20e-12,
            },
            Expect::Error,
        ),
        case(
            "no lattice",
            "flat".into(),
            Input::Flat {
                config: base.clone(),
            },
            Expect::Error,
        ),
        Case {
            analyse_as: Some(LatticeConfig::Square { a_m: 5e-10 }),
            ..case(
                "no lattice",
                "graphite analysed as square 5 Å".into(),
                simulated(base.clone()),
                Expect::Either,
            )
        },
        case(
            "bad pixels",
            "bottom 10 % of rows NaN".into(),
            Input::NanRows {
                config: base.clone(),
                fraction: 0.1,
            },
            Expect::Either,
        ),
    ]
}

/// Gaussian white noise from a fixed seed (xorshift64* and Box–Muller; no dependency).
fn white_noise(rows: usize, columns: usize, sigma: f64, seed: u64) -> Array2<f64> {
    let mut state = seed.max(1);
    let mut uniform = move || {
        state ^= state >> 12;
        state ^= state << 25;
        state ^= state >> 27;
        ((state.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    };
    Array2::from_shape_simple_fn((rows, columns), || {
        let (u, v) = (uniform(), uniform());
        sigma * (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    })
}

/// The mask of `kind` for a `rows × columns` image (true = use).
pub fn mask(kind: MaskKind, rows: usize, columns: usize) -> Option<Array2<bool>> {
    let (h, w) = (rows as f64, columns as f64);
    let outside = |holes: &[(f64, f64, f64)]| {
        Array2::from_shape_fn((rows, columns), |(r, c)| {
            holes
                .iter()
                .all(|&(x, y, radius)| (c as f64 - x).hypot(r as f64 - y) > radius)
        })
    };
    match kind {
        MaskKind::None => None,
        MaskKind::CentralHole => Some(outside(&[(0.5 * w, 0.5 * h, 0.25 * w)])),
        MaskKind::ManyHoles => Some(outside(&[
            (0.25 * w, 0.25 * h, 0.08 * w),
            (0.75 * w, 0.25 * h, 0.06 * w),
            (0.5 * w, 0.5 * h, 0.1 * w),
            (0.25 * w, 0.75 * h, 0.05 * w),
            (0.75 * w, 0.75 * h, 0.07 * w),
        ])),
        MaskKind::TwoRegions => Some(Array2::from_shape_fn((rows, columns), |(_, c)| {
            let x = c as f64 / w;
            !(0.45..0.55).contains(&x)
        })),
        MaskKind::Tiny => Some(Array2::from_shape_fn((rows, columns), |(r, c)| {
            (r as f64) < 0.06 * h && (c as f64) < 0.06 * w
        })),
    }
}

fn message_of(panic: Box<dyn std::any::Any + Send>) -> String {
    panic
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| panic.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "(non-string panic payload)".into())
}

/// Builds the input of `case`, runs the chain and compares with the truth. Never panics.
pub fn run_case(case: &Case) -> Row {
    let start = Instant::now();
    let outcome = match catch_unwind(AssertUnwindSafe(|| run_inner(case))) {
        Ok(Ok(accuracy)) => Outcome::Analysis(accuracy.map(Box::new)),
        Ok(Err(message)) => Outcome::Error(message),
        Err(panic) => Outcome::Panic(message_of(panic)),
    };
    Row {
        axis: case.axis,
        level: case.level.clone(),
        expect: case.expect,
        outcome,
        seconds: start.elapsed().as_secs_f64(),
    }
}

fn run_inner(case: &Case) -> Result<Option<Accuracy>, String> {
    let (config, pair, truth) = match &case.input {
        Input::Simulated {
            config,
            trace,
            retrace,
        } => {
            let output = Simulation::from_config(config)
                .and_then(|s| s.run())
                .map_err(|e| format!("simulation: {e}"))?;
            let geometry = output.pair.geometry().clone();
            let keep =
                |pass: ScanPass, on: bool| on.then(|| output.pair.image(pass).cloned()).flatten();
            let pair = ScanPair::from_parts(
                geometry,
                keep(ScanPass::Trace, *trace),
                keep(ScanPass::Retrace, *retrace),
            )
            .map_err(|e| format!("pair: {e}"))?;
            (config, pair, Some(output.truth))
        }
        Input::NanRows { config, fraction } => {
            let output = Simulation::from_config(config)
                .and_then(|s| s.run())
                .map_err(|e| format!("simulation: {e}"))?;
            let geometry = output.pair.geometry().clone();
            let first = ((1.0 - fraction) * geometry.rows() as f64) as usize;
            let spoil = |image: &ImageChannel| {
                let mut image = image.clone();
                image.z.slice_mut(ndarray::s![first.., ..]).fill(f64::NAN);
                image
            };
            let pair = ScanPair::from_parts(
                geometry,
                output.pair.trace().map(spoil),
                output.pair.retrace().map(spoil),
            )
            .map_err(|e| format!("pair: {e}"))?;
            (config, pair, Some(output.truth))
        }
        Input::PureNoise { config, sigma_m } => {
            let geometry = config.scan.geometry().map_err(|e| e.to_string())?;
            let z = |seed| white_noise(geometry.rows(), geometry.columns(), *sigma_m, seed);
            let pair = ScanPair::new(
                geometry.clone(),
                ImageChannel::new("Topography", "m", z(1)),
                Some(ImageChannel::new("Topography", "m", z(2))),
            )
            .map_err(|e| format!("pair: {e}"))?;
            (config, pair, None)
        }
        Input::Flat { config } => {
            let geometry = config.scan.geometry().map_err(|e| e.to_string())?;
            let z = Array2::zeros((geometry.rows(), geometry.columns()));
            let pair = ScanPair::new(
                geometry.clone(),
                ImageChannel::new("Topography", "m", z.clone()),
                Some(ImageChannel::new("Topography", "m", z)),
            )
            .map_err(|e| format!("pair: {e}"))?;
            (config, pair, None)
        }
    };
    let lattice = case
        .analyse_as
        .as_ref()
        .unwrap_or(&config.surface.lattice)
        .build()
        .map_err(|e| format!("lattice: {e}"))?;
    let geometry = pair.geometry().clone();
    let mask = mask(case.mask, geometry.rows(), geometry.columns());
    let mut options = pipeline_options(lattice.as_ref());
    if case.no_line_levelling {
        options.features.line_correction = LineCorrection::None;
    }
    let analysis = dhct_pipeline::run(&pair, lattice.as_ref(), mask.as_ref(), &options, &|_| {})
        .map_err(|e| e.to_string())?;
    Ok(truth.map(|truth| accuracy(&analysis, &truth, &geometry, lattice.as_ref())))
}

/// The rows as a table: outcome, features matched / true, fraction indexed, corrected rms
/// vs truth (pm) and its ratio to the localisation noise floor, lattice-constant error.
pub fn table(rows: &[Row]) -> Table {
    let mut table = Table::new(&[
        "axis",
        "level",
        "expect",
        "outcome",
        "s",
        "recall",
        "indexed",
        "floor pm",
        "corr. rms pm",
        "÷ floor",
        "Δa/a x, y %",
        "note",
    ]);
    for row in rows {
        let expect = format!("{:?}", row.expect);
        let mut cells = vec![
            row.axis.to_string(),
            row.level.clone(),
            expect,
            String::new(),
            format!("{:.2}", row.seconds),
        ];
        match &row.outcome {
            Outcome::Analysis(None) => {
                cells[3] = if row.as_expected() {
                    "ok"
                } else {
                    "UNEXPECTED ok"
                }
                .into();
                cells.extend(std::iter::repeat_n(String::new(), 7));
            }
            Outcome::Analysis(Some(a)) => {
                cells[3] = match (row.as_expected(), row.silently_wrong()) {
                    (true, false) => "ok",
                    (true, true) => "WRONG, no error",
                    (false, true) => "UNEXPECTED: WRONG, no error",
                    (false, false) => "UNEXPECTED ok",
                }
                .into();
                cells.extend([
                    format!("{:.3}", a.recall),
                    format!("{:.3}", a.indexed_fraction),
                    format!("{:.2}", a.noise_floor_m * 1e12),
                    format!("{:.2}", a.corrected_rms_m * 1e12),
                    format!("{:.2}", a.corrected_over_floor),
                    format!(
                        "{:+.3}, {:+.3}",
                        a.lattice_constant_error[0] * 100.0,
                        a.lattice_constant_error[1] * 100.0
                    ),
                    String::new(),
                ]);
            }
            Outcome::Error(message) => {
                cells[3] = if row.as_expected() {
                    "error"
                } else {
                    "UNEXPECTED error"
                }
                .into();
                cells.extend(std::iter::repeat_n(String::new(), 6));
                cells.push(message.chars().take(110).collect());
            }
            Outcome::Panic(message) => {
                cells[3] = "PANIC".into();
                cells.extend(std::iter::repeat_n(String::new(), 6));
                cells.push(message.chars().take(110).collect());
            }
        }
        table.row(cells);
    }
    table
}
