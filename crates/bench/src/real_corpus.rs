//! The real-data corpus (`tests/data/real/corpus.toml`) run as a user would, and judged
//! from the corrected image alone.
//!
//! Each file is corrected by the `dhct` command with the corpus' arguments; when that is
//! refused and the error's hint offers a flag (`--polarity dark`, `--calibrate`), once more
//! with it. The corrected
//! trace and retrace written (GSF, sample units) are then judged without dhct's own fit:
//!
//! * **lattice**: the surface's lattice read from the corrected image's Fourier transform
//!   (the constant's first-order reflections, [`crate::known_lattice`], else the lattice
//!   fitted to the blindly measured peaks) must have the literature constant within 1.5 %
//!   along x and y and a shear within 1°; where the constant is not known, only the shape
//!   is judged (anisotropy ≤ 1.015, shear ≤ 1°). Below 8 periods across the tolerances
//!   widen ([`CorpusFile::tolerances`]);
//! * **regularity**: the non-affine displacement from the Bragg phases
//!   ([`crate::regularity`]) of the corrected image, against the raw image's (which is what
//!   any affine correction leaves), both in periods of the first reflection.

use std::path::{Path, PathBuf};
use std::process::Command;

use dhct_calibrate::{CheckOptions, LatticeMatch, match_lattice, measure_lattice};
use dhct_lattice::{Hexagonal, Lattice, PlaneGroup, Square};
use dhct_scan::{ScanPair, ScanPass};
use serde::Deserialize;

pub use crate::known_lattice::JudgeLattice;
use crate::known_lattice::read_known_lattice;
use crate::regularity::non_affine_rms_px;

/// The corrected lattice's constant must be within this fraction of the truth.
pub const SCALE_TOLERANCE: f64 = 0.015;
/// …and its shear within this, degrees.
pub const SHEAR_TOLERANCE_DEG: f64 = 1.0;
/// The tolerances hold for frames this many periods across or more; see
/// [`CorpusFile::tolerances`].
pub const FULL_PRECISION_PERIODS: f64 = 8.0;

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

impl CorpusFile {
    /// The judge's tolerances for this file: fraction of the constant, degrees of shear.
    ///
    /// A reflection's position is read to about a fixed fraction of a Fourier bin, and the
    /// first-order ring lies as many bins out as the frame holds periods, so the judge's
    /// own precision falls as `1/periods`: below [`FULL_PRECISION_PERIODS`] across, both
    /// tolerances widen by `FULL_PRECISION_PERIODS / periods_across`.
    pub fn tolerances(&self) -> (f64, f64) {
        let widen = (FULL_PRECISION_PERIODS / self.periods_across).max(1.0);
        (SCALE_TOLERANCE * widen, SHEAR_TOLERANCE_DEG * widen)
    }
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

/// The judge's reading of one image's lattice.
struct Reading {
    /// Apparent over true length along x and y, or the principal stretches' ratio and 1
    /// when only the shape is judged.
    scale: [f64; 2],
    /// Shear, degrees.
    shear_deg: f64,
    /// The cell in the file, `[a1, a2]`, metres.
    cell_in_file_m: [[f64; 2]; 2],
}

/// The judge's reading of `pair`'s `pass`.
///
/// With the surface's constant known, a corrected image (`near`) is read from the
/// constant's first-order reflections ([`read_known_lattice`], within 15 % of it), and
/// where that ring is too weak, by fitting the lattice to the blindly measured Fourier
/// peaks within 15 % of the constant; a raw image (whose pixel size may be off) the other
/// way round, at any scale (the ring within a factor 2). Without the constant, only the
/// shape: the lattice type fitted at any scale to the blindly measured peaks.
fn read(file: &CorpusFile, pair: &ScanPair, pass: ScanPass, near: bool) -> Result<Reading, String> {
    let image = image_of(pair, pass).ok_or("no image")?;
    let Some(a) = file.judge_a_m else {
        let matched = fit_blind(file, pair, image, f64::MAX)?;
        let c = matched.calibration;
        return Ok(Reading {
            scale: [c.anisotropy, 1.0],
            shear_deg: c.shear_deg,
            cell_in_file_m: matched.cell_in_file_m,
        });
    };
    let blind = |tolerance: f64| {
        fit_blind(file, pair, image, tolerance).map(|matched| Reading {
            scale: matched.calibration.scale,
            shear_deg: matched.calibration.shear_deg,
            cell_in_file_m: matched.cell_in_file_m,
        })
    };
    let geometry = pair.geometry();
    let ring = |scale_range: [f64; 2]| {
        read_known_lattice(
            image.z.view(),
            [geometry.pitch_x(), geometry.pitch_y()],
            file.judge_lattice,
            a,
            scale_range,
        )
        .map(|read| Reading {
            scale: read.scale,
            shear_deg: read.shear_deg,
            cell_in_file_m: read.cell_in_file_m,
        })
    };
    if near {
        ring([0.85, 1.15]).or_else(|ring_failed| {
            blind(0.15).map_err(|blind_failed| format!("{ring_failed}; {blind_failed}"))
        })
    } else {
        blind(f64::MAX).or_else(|_| ring([0.5, 2.0]))
    }
}

/// The surface's lattice type fitted to the image's blindly measured Fourier peaks, its
/// constant within `pitch_tolerance` (a fraction; `f64::MAX`: any scale).
fn fit_blind(
    file: &CorpusFile,
    pair: &ScanPair,
    image: &dhct_scan::ImageChannel,
    pitch_tolerance: f64,
) -> Result<LatticeMatch, String> {
    let measured =
        measure_lattice(image.z.view(), pair.geometry(), None).map_err(|e| e.to_string())?;
    let options = CheckOptions {
        pitch_tolerance,
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
    let reading = read(file, corrected, pass, true)?;
    let corrected_non_affine = non_affine_periods(corrected, pass, &reading.cell_in_file_m);
    let raw_non_affine = raw.and_then(|raw| {
        let reading = read(file, raw, pass, false).ok()?;
        non_affine_periods(raw, pass, &reading.cell_in_file_m)
    });
    Ok(PassJudgement {
        pass,
        scale: reading.scale,
        shear_deg: reading.shear_deg,
        raw_non_affine,
        corrected_non_affine,
    })
}

/// The non-affine displacement of `pair`'s `pass` for the two cell reflections of
/// `cell` (`[a1, a2]`, metres), in periods of the first.
fn non_affine_periods(pair: &ScanPair, pass: ScanPass, cell: &[[f64; 2]; 2]) -> Option<f64> {
    let image = image_of(pair, pass)?;
    let [a1, a2] = *cell;
    let cell = nalgebra::Matrix2::new(a1[0], a2[0], a1[1], a2[1]);
    let reciprocal = cell.try_inverse()?.transpose();
    let (px, py) = (pair.geometry().pitch_x(), pair.geometry().pitch_y());
    let g = |k: usize| [reciprocal[(0, k)] * px, reciprocal[(1, k)] * py];
    let (g1, g2) = (g(0), g(1));
    let rms = non_affine_rms_px(image.z.view(), [g1, g2])?;
    Some(rms * g1[0].hypot(g1[1]))
}

fn judgement_is_right(file: &CorpusFile, j: &PassJudgement) -> bool {
    let (scale_tolerance, shear_tolerance) = file.tolerances();
    let scales_right = if file.judge_a_m.is_some() {
        j.scale.iter().all(|k| (k - 1.0).abs() <= scale_tolerance)
    } else {
        j.scale[0] <= 1.0 + scale_tolerance
    };
    scales_right && j.shear_deg.abs() <= shear_tolerance
}

#[cfg(test)]
mod tests {
    use super::*;

    fn file(periods_across: f64) -> CorpusFile {
        CorpusFile {
            name: "test".into(),
            path: "test".into(),
            real_data: false,
            args: Vec::new(),
            surface: "test".into(),
            vendor: "test".into(),
            judge_lattice: JudgeLattice::Hexagonal,
            judge_a_m: Some(2.46e-10),
            periods_across,
        }
    }

    #[test]
    fn tolerances_widen_only_below_eight_periods() {
        assert_eq!(
            file(47.0).tolerances(),
            (SCALE_TOLERANCE, SHEAR_TOLERANCE_DEG)
        );
        assert_eq!(
            file(8.0).tolerances(),
            (SCALE_TOLERANCE, SHEAR_TOLERANCE_DEG)
        );
        let (scale, shear) = file(4.0).tolerances();
        assert!((scale - 2.0 * SCALE_TOLERANCE).abs() < 1e-12);
        assert!((shear - 2.0 * SHEAR_TOLERANCE_DEG).abs() < 1e-12);
    }

    #[test]
    fn a_judgement_outside_the_tolerances_is_not_right() {
        let judged = |scale: [f64; 2], shear_deg: f64| PassJudgement {
            pass: ScanPass::Trace,
            scale,
            shear_deg,
            raw_non_affine: None,
            corrected_non_affine: None,
        };
        let wide = file(47.0);
        assert!(judgement_is_right(&wide, &judged([1.01, 0.99], 0.5)));
        assert!(!judgement_is_right(&wide, &judged([1.02, 1.0], 0.0)));
        assert!(!judgement_is_right(&wide, &judged([1.0, 1.0], 1.2)));
        // 5.5 periods: 2.2 % and 1.45°.
        let few = file(5.5);
        assert!(judgement_is_right(&few, &judged([0.9956, 1.0044], -1.07)));
        assert!(!judgement_is_right(&few, &judged([1.03, 1.0], 0.0)));
    }
}
