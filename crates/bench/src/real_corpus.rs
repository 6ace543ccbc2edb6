//! The real-data corpus (`tests/data/real/corpus.toml`) run as a user would, and judged
//! from the corrected image alone.
//!
//! Each file is corrected by the `dhct` command with the corpus' arguments; when that is
//! refused and the error's hint offers a flag (`--polarity dark`, `--calibrate`), once more
//! with it. The corrected
//! trace and retrace written (GSF, sample units) are then judged without dhct's own fit:
//!
//! * **lattice**: the surface's lattice fitted to the corrected image's Fourier peaks must
//!   have the literature constant within 1.5 % along x and y and a shear within 1°; where
//!   the constant is not known, only the shape is judged (anisotropy ≤ 1.015, shear ≤ 1°);
//! * **regularity**: the non-affine displacement from the Bragg phases
//!   ([`crate::regularity`]) of the corrected image, against the raw image's (which is what
//!   any affine correction leaves), both in periods of the first reflection.

use std::path::{Path, PathBuf};
use std::process::Command;

use dhct_calibrate::{CheckOptions, LatticeMatch, match_lattice, measure_lattice};
use dhct_lattice::{Hexagonal, Lattice, PlaneGroup, Square};
use dhct_scan::{ScanPair, ScanPass};
use serde::Deserialize;

use crate::regularity::non_affine_rms_px;

/// The corrected lattice's constant must be within this fraction of the truth.
pub const SCALE_TOLERANCE: f64 = 0.015;
/// …and its shear within this, degrees.
pub const SHEAR_TOLERANCE_DEG: f64 = 1.0;

/// One file of the corpus.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CorpusFile {
    /// A short name.
    pub name: String,
    /// Path relative to the repository root, or to `DHCT_REAL_DATA` when `real_data`.
    pub path: String,
    /// Read from `DHCT_REAL_DATA` (not redistributable).
    #[serde(default)]
    pub real_data: bool,
    /// The `dhct correct` arguments a user would give (lattice, constant, config).
    pub args: Vec<String>,
    /// The surface.
    pub surface: String,
    /// The file's vendor and format.
    pub vendor: String,
    /// The surface's translation lattice the judge fits: `hexagonal` (default) or
    /// `square`.
    #[serde(default)]
    pub judge_lattice: JudgeLattice,
    /// The surface's lattice constant from the literature, metres, if known.
    pub judge_a_m: Option<f64>,
    /// About how many lattice periods the frame holds.
    pub periods_across: f64,
}

/// The translation lattice a corpus file is judged with.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum JudgeLattice {
    /// Hexagonal (one site per 60° rhombus).
    #[default]
    Hexagonal,
    /// Square.
    Square,
}

/// The corpus manifest.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Corpus {
    /// The files.
    pub file: Vec<CorpusFile>,
}

impl Corpus {
    /// Reads the manifest at `path`.
    pub fn read(path: &Path) -> Result<Corpus, String> {
        let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
        toml::from_str(&text).map_err(|e| format!("{}: {e}", path.display()))
    }
}

/// What became of one file.
#[derive(Debug, Clone)]
pub enum Verdict {
    /// Corrected, and the corrected image's lattice is right.
    Right,
    /// Stopped with an error (its first line).
    Refused(String),
    /// Corrected at exit 0, but the corrected image's lattice is not the surface's, and
    /// dhct did not say so.
    Wrong(String),
    /// Corrected, a pass's lattice off (or not measurable by the judge), and dhct warned
    /// about that pass itself (`corrected_image_off`, `corrected_image_unchecked`): not
    /// silently wrong, but not right either.
    Flagged(String),
    /// The file is not there (`DHCT_REAL_DATA` unset or missing).
    Missing(String),
}

/// One file's result.
#[derive(Debug, Clone)]
pub struct FileResult {
    /// The verdict.
    pub verdict: Verdict,
    /// The arguments of the run judged (with the hint's flag when it was needed).
    pub args: Vec<String>,
    /// `drift-model` or `affine`: which correction the corrected data come from.
    pub correction: Option<String>,
    /// The lattice fit's rms deviation with the drift model and with the affine map
    /// (largest region), metres.
    pub model_vs_affine_m: Option<[f64; 2]>,
    /// Per pass judged.
    pub passes: Vec<PassJudgement>,
    /// The passes dhct itself flagged as off or unchecked (`corrected_image_off`,
    /// `corrected_image_unchecked`).
    pub flagged: Vec<String>,
    /// The file read, when it was found.
    pub input: Option<PathBuf>,
}

/// The judgement of one corrected image.
#[derive(Debug, Clone, Copy)]
pub struct PassJudgement {
    /// Trace or retrace.
    pub pass: ScanPass,
    /// Apparent over true length along x and y of the corrected lattice (1 = right), or
    /// the principal stretches' ratio and 1 when only the shape is judged.
    pub scale: [f64; 2],
    /// Shear of the corrected lattice, degrees.
    pub shear_deg: f64,
    /// Non-affine displacement of the raw image, periods.
    pub raw_non_affine: Option<f64>,
    /// The same of the corrected image, periods.
    pub corrected_non_affine: Option<f64>,
}

/// Runs `file` with the `dhct` binary `dhct` into `out`, and judges it.
pub fn run_file(file: &CorpusFile, root: &Path, dhct: &Path, out: &Path) -> FileResult {
    let mut result = FileResult {
        verdict: Verdict::Missing(String::new()),
        args: file.args.clone(),
        correction: None,
        model_vs_affine_m: None,
        passes: Vec::new(),
        flagged: Vec::new(),
        input: None,
    };
    let input = match locate(file, root) {
        Ok(path) => {
            result.input = Some(path.clone());
            path
        }
        Err(why) => {
            result.verdict = Verdict::Missing(why);
            return result;
        }
    };
    let mut outcome = correct(dhct, &input, &file.args, root, out);
    if let Err(stderr) = &outcome
        && let Some(flag) = hinted_flag(stderr, &file.args)
    {
        result.args.extend(flag);
        outcome = correct(dhct, &input, &result.args, root, out);
    }
    if let Err(stderr) = outcome {
        result.verdict = Verdict::Refused(first_error_line(&stderr));
        return result;
    }
    read_model(out, &mut result);
    let raw = dhct_sm4_io::read_path(&input)
        .ok()
        .and_then(|f| f.topography().cloned());
    let (mut wrong, mut flagged) = (Vec::new(), Vec::new());
    for (pass, name) in [
        (ScanPass::Trace, "corrected_trace.gsf"),
        (ScanPass::Retrace, "corrected_retrace.gsf"),
    ] {
        let Some(corrected) = dhct_sm4_io::read_path(&out.join(name))
            .ok()
            .and_then(|f| f.topography().cloned())
        else {
            continue;
        };
        match judge_pass(file, pass, &corrected, raw.as_ref()) {
            Ok(judgement) => {
                if !judgement_is_right(file, &judgement) {
                    let said = result.flagged.iter().any(|f| *f == pass.to_string());
                    (if said { &mut flagged } else { &mut wrong }).push(format!(
                        "{pass}: x {:.4}, y {:.4}, shear {:.2}°",
                        judgement.scale[0], judgement.scale[1], judgement.shear_deg
                    ));
                }
                result.passes.push(judgement);
            }
            Err(why) => {
                let said = result.flagged.iter().any(|f| *f == pass.to_string());
                (if said { &mut flagged } else { &mut wrong }).push(format!("{pass}: {why}"));
            }
        }
    }
    result.verdict = if result.passes.is_empty() && flagged.is_empty() {
        Verdict::Wrong(format!(
            "no corrected image could be judged: {}",
            wrong.join("; ")
        ))
    } else if !wrong.is_empty() {
        Verdict::Wrong(wrong.join("; "))
    } else if !flagged.is_empty() {
        Verdict::Flagged(flagged.join("; "))
    } else {
        Verdict::Right
    };
    result
}

/// The flag a refusal's hint offers first that the arguments lack: `--polarity dark` (or
/// bright) when the hint says to add it, else `--calibrate` when the hint names it.
fn hinted_flag(stderr: &str, args: &[String]) -> Option<Vec<String>> {
    let hint = stderr.lines().find(|l| l.starts_with("hint:"))?;
    let has = |flag: &str| args.iter().any(|a| a == flag);
    for polarity in ["dark", "bright"] {
        if hint.contains(&format!("add --polarity {polarity}")) && !has("--polarity") {
            return Some(vec!["--polarity".into(), polarity.into()]);
        }
    }
    (hint.contains("--calibrate") && !has("--calibrate")).then(|| vec!["--calibrate".into()])
}

fn locate(file: &CorpusFile, root: &Path) -> Result<PathBuf, String> {
    let path = if file.real_data {
        let Some(dir) = std::env::var_os("DHCT_REAL_DATA") else {
            return Err("DHCT_REAL_DATA is not set".into());
        };
        PathBuf::from(dir).join(&file.path)
    } else {
        root.join(&file.path)
    };
    if path.is_file() {
        Ok(path)
    } else {
        Err(format!("{} is not there", path.display()))
    }
}

/// `dhct correct INPUT -o OUT ARGS` from the repository root; `Err(stderr)` on failure.
fn correct(
    dhct: &Path,
    input: &Path,
    args: &[String],
    root: &Path,
    out: &Path,
) -> Result<(), String> {
    run_dhct(dhct, "correct", input, args, root, out)
}

/// `dhct SUBCOMMAND INPUT -o OUT ARGS` from `root` into a fresh `out`; `Err(stderr)` on
/// failure.
pub(crate) fn run_dhct(
    dhct: &Path,
    subcommand: &str,
    input: &Path,
    args: &[String],
    root: &Path,
    out: &Path,
) -> Result<(), String> {
    let _ = std::fs::remove_dir_all(out);
    let output = Command::new(dhct)
        .current_dir(root)
        .arg(subcommand)
        .arg(input)
        .arg("-o")
        .arg(out)
        .args(args)
        .output()
        .map_err(|e| format!("{}: {e}", dhct.display()))?;
    if output.status.success() {
        Ok(())
    } else {
        Err(String::from_utf8_lossy(&output.stderr).into_owned())
    }
}

pub(crate) fn first_error_line(stderr: &str) -> String {
    stderr
        .lines()
        .find(|l| l.starts_with("error"))
        .unwrap_or_else(|| stderr.lines().next().unwrap_or(""))
        .to_string()
}

fn read_model(out: &Path, result: &mut FileResult) {
    let Ok(text) = std::fs::read_to_string(out.join("model.json")) else {
        return;
    };
    let Ok(model) = serde_json::from_str::<serde_json::Value>(&text) else {
        return;
    };
    result.correction = model["correction"].as_str().map(str::to_owned);
    for warning in model["warnings"].as_array().into_iter().flatten() {
        if (warning["code"] == "corrected_image_off"
            || warning["code"] == "corrected_image_unchecked")
            && let Some(message) = warning["message"].as_str()
        {
            for pass in ["trace", "retrace"] {
                if message.starts_with(&format!("corrected {pass}:")) {
                    result.flagged.push(pass.to_string());
                }
            }
        }
    }
    let first = &model["affine_baseline"][0];
    if let (Some(m), Some(a)) = (
        first["model_rms_m"].as_f64(),
        first["affine_rms_m"].as_f64(),
    ) {
        result.model_vs_affine_m = Some([m, a]);
    }
}

/// The lattice the judge fits: the literature constant, or (shape only) any.
fn judge_lattice(file: &CorpusFile) -> Box<dyn Lattice> {
    let a = file.judge_a_m.unwrap_or(1e-9);
    match file.judge_lattice {
        JudgeLattice::Hexagonal => {
            Box::new(Hexagonal::new("judge", a, PlaneGroup::P6mm).expect("a positive constant"))
        }
        JudgeLattice::Square => Box::new(Square::new(a).expect("a positive constant")),
    }
}

/// The image of `pass` in `pair`, or its only image (a GSF holds one, in either slot).
fn image_of(pair: &ScanPair, pass: ScanPass) -> Option<&dhct_scan::ImageChannel> {
    pair.image(pass)
        .or_else(|| pair.image(ScanPass::Trace))
        .or_else(|| pair.image(ScanPass::Retrace))
}

/// The judge's fit of `pair`'s `pass`: near the constant when it is known and `near` (a
/// corrected image), at any scale otherwise (a raw image, whose pixel size may be off).
fn fit(
    file: &CorpusFile,
    pair: &ScanPair,
    pass: ScanPass,
    near: bool,
) -> Result<LatticeMatch, String> {
    let image = image_of(pair, pass).ok_or("no image")?;
    let measured =
        measure_lattice(image.z.view(), pair.geometry(), None).map_err(|e| e.to_string())?;
    let options = CheckOptions {
        pitch_tolerance: if near && file.judge_a_m.is_some() {
            0.15
        } else {
            f64::MAX
        },
        ..CheckOptions::default()
    };
    let mut bounds = options.bounds(pair.geometry().fast_axis());
    bounds.slow_scale = bounds.fast_scale;
    match_lattice(&measured, judge_lattice(file).as_ref(), &bounds)
        .filter(|m| m.explains_image)
        .ok_or_else(|| "the surface's lattice does not explain its Fourier peaks".to_string())
}

fn judge_pass(
    file: &CorpusFile,
    pass: ScanPass,
    corrected: &ScanPair,
    raw: Option<&ScanPair>,
) -> Result<PassJudgement, String> {
    let matched = fit(file, corrected, pass, true)?;
    let c = matched.calibration;
    let scale = if file.judge_a_m.is_some() {
        c.scale
    } else {
        [c.anisotropy, 1.0]
    };
    let corrected_non_affine = non_affine_periods(corrected, pass, &matched);
    let raw_non_affine = raw.and_then(|raw| {
        let matched = fit(file, raw, pass, false).ok()?;
        non_affine_periods(raw, pass, &matched)
    });
    Ok(PassJudgement {
        pass,
        scale,
        shear_deg: c.shear_deg,
        raw_non_affine,
        corrected_non_affine,
    })
}

/// The non-affine displacement of `pair`'s `pass` for the two cell reflections of
/// `matched`, in periods of the first.
fn non_affine_periods(pair: &ScanPair, pass: ScanPass, matched: &LatticeMatch) -> Option<f64> {
    let image = image_of(pair, pass)?;
    let [a1, a2] = matched.cell_in_file_m;
    let cell = nalgebra::Matrix2::new(a1[0], a2[0], a1[1], a2[1]);
    let reciprocal = cell.try_inverse()?.transpose();
    let (px, py) = (pair.geometry().pitch_x(), pair.geometry().pitch_y());
    let g = |k: usize| [reciprocal[(0, k)] * px, reciprocal[(1, k)] * py];
    let (g1, g2) = (g(0), g(1));
    let rms = non_affine_rms_px(image.z.view(), [g1, g2])?;
    Some(rms * g1[0].hypot(g1[1]))
}

fn judgement_is_right(file: &CorpusFile, j: &PassJudgement) -> bool {
    let scales_right = if file.judge_a_m.is_some() {
        j.scale.iter().all(|k| (k - 1.0).abs() <= SCALE_TOLERANCE)
    } else {
        j.scale[0] <= 1.0 + SCALE_TOLERANCE
    };
    scales_right && j.shear_deg.abs() <= SHEAR_TOLERANCE_DEG
}
