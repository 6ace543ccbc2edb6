//! The `dhct correct` configuration: a TOML file, overridden by command-line flags, and
//! written back fully resolved (every pipeline option) into the output directory so that
//! `dhct correct --config OUTDIR/config.toml INPUT -o NEWDIR` repeats the run.
//!
//! The `[pipeline]` section is merged key by key onto the very defaults a run without a
//! config uses (`PipelineOptions::for_lattice` of the chosen lattice): a partial
//! `[pipeline.features]` changes only the keys it names. Unknown keys anywhere are errors
//! that list the valid ones and suggest the closest ("did you mean").

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, anyhow, bail};
use dhct_features::Polarity;
use dhct_lattice::{Lattice, LatticeError, PlaneGroup, UserLattice};
use dhct_pipeline::PipelineOptions;
use dhct_sm4_io::GeometryOverrides;
use dhct_sm4_io::png_file::Colormap;
use serde::{Deserialize, Serialize};

use crate::units;

/// A length given as metres or as text with a unit ("2.46A", "0.246nm").
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Length {
    /// A number, metres.
    Metres(f64),
    /// Text: a number with an optional unit (metres without one), or `auto`.
    Text(String),
}

impl Length {
    /// Whether this is `auto`: the constant is taken from the image (file units).
    pub fn is_auto(&self) -> bool {
        matches!(self, Length::Text(t) if t.trim().eq_ignore_ascii_case("auto"))
    }

    /// The length in metres; an error for text that is not a length (e.g. `auto`).
    pub fn metres(&self) -> Result<f64> {
        match self {
            Length::Metres(m) => Ok(*m),
            Length::Text(t) => units::parse_length(t).map_err(anyhow::Error::msg),
        }
    }
}

/// Everything `dhct correct` can be told. All fields are optional in a file.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CorrectConfig {
    /// A catalogue lattice (`dhct_lattice::catalogue::CATALOGUE`: graphite, honeycomb,
    /// hexagonal, sam-sqrt3, si111-7x7, square, rectangular, centred-rectangular, oblique,
    /// kagome), or the path of a user lattice (TOML/JSON).
    pub lattice: Option<String>,
    /// Nearest-neighbour distance; replaces the preset's.
    pub nn: Option<Length>,
    /// The lattice constant is right and the file's pixel size may be wrong by any factor
    /// (up to ×10): calibrate from the lattice without the plausibility limit.
    pub calibrate: Option<bool>,
    /// Skip the checks of the lattice and its constant against the image (and the
    /// calibration from it): for users who know better.
    pub trust_inputs: Option<bool>,
    /// bright (atoms are maxima) or dark (minima).
    pub polarity: Option<Polarity>,
    /// Mask file, raw-image pixels: PNG (light or opaque = use), NPY or TIFF (non-zero =
    /// use); see `dhct_distortion::mask::read_mask`.
    pub mask: Option<PathBuf>,
    /// Mask polygon, vertices in raw-image pixels (x = column, y = row).
    pub mask_polygon: Option<Vec<[f64; 2]>>,
    /// Plane group of the symmetry average (default: the lattice's).
    pub plane_group: Option<PlaneGroup>,
    /// Colour map of the pictures.
    pub colormap: Option<Colormap>,
    /// `all`: also correct every other image channel of the file with the model fitted on
    /// the analysed one (`corrected_{channel}_{pass}.tiff` and `.gsf`).
    pub channels: Option<ChannelSet>,
    /// Also write the displacement field of each pass (`displacement_{pass}.npy` and
    /// `.tiff`: per pixel, where the tip really was relative to the controller, metres).
    pub displacement: Option<bool>,
    /// The grid of the corrected TIFF and GSF files: the scan's own frame (default; what
    /// the correction moves outside it is cropped) or every corrected pixel (`full`).
    pub extent: Option<Extent>,
    /// The channel to analyse, by name (case-insensitive; a whole name first, else a part
    /// of one); default: the topography.
    pub channel: Option<String>,
    /// Scan geometry replacing the file's (SI units).
    pub geometry: GeometryOverrides,
    /// The pipeline options given, as written: merged key by key onto the lattice's
    /// defaults by [`CorrectConfig::pipeline_options`]. A written `config.toml` holds every
    /// option.
    pub pipeline: Option<toml::Table>,
    /// Replace an output folder holding an earlier run (`--overwrite`; never read from or
    /// written to a file).
    #[serde(skip)]
    pub overwrite: bool,
}

/// Largest config file read, bytes.
const MAX_CONFIG_BYTES: u64 = 1 << 20;

impl CorrectConfig {
    /// Reads a config file (only a regular file: a FIFO or device is refused before it is
    /// opened) and checks every key and value it can without the data: unknown keys,
    /// types, and the geometry and pipeline options against their ranges.
    pub fn read(path: &Path) -> Result<CorrectConfig> {
        let text = dhct_sm4_io::read_regular_text(path, MAX_CONFIG_BYTES)
            .with_context(|| format!("cannot read config {}", path.display()))?;
        let config: CorrectConfig = toml::from_str(&text)
            .map_err(|e| anyhow!("{}", with_suggestion(&e.to_string(), None)))
            .with_context(|| format!("config {} is not valid", path.display()))?;
        config
            .check()
            .with_context(|| format!("config {} is not valid", path.display()))?;
        Ok(config)
    }

    /// Checks the geometry overrides and the pipeline section against the plain defaults
    /// (unknown keys, types, ranges), before any lattice or data is read.
    pub fn check(&self) -> Result<()> {
        self.geometry
            .validate()
            .map_err(|e| anyhow!("geometry.{e}"))?;
        if self.pipeline.is_some() {
            self.merged_onto(PipelineOptions::default())?;
        }
        Ok(())
    }

    /// The pipeline options of a run on `lattice`: the `[pipeline]` keys given, merged one
    /// by one onto `PipelineOptions::for_lattice(lattice)` (what a run without a config
    /// uses), then validated.
    pub fn pipeline_options(&self, lattice: &dyn Lattice) -> Result<PipelineOptions> {
        self.merged_onto(PipelineOptions::for_lattice(lattice))
    }

    fn merged_onto(&self, defaults: PipelineOptions) -> Result<PipelineOptions> {
        let Some(given) = &self.pipeline else {
            return Ok(defaults);
        };
        let mut table = pipeline_table(&defaults)?;
        merge(&mut table, given);
        let options: PipelineOptions =
            toml::Value::Table(table)
                .try_into()
                .map_err(|e: toml::de::Error| {
                    anyhow!("[pipeline]: {}", with_suggestion(e.message(), Some(given)))
                })?;
        options.validate().map_err(|e| anyhow!("[pipeline]: {e}"))?;
        Ok(options)
    }

    /// `other`'s set fields replace this one's (pipeline keys one by one).
    pub fn overridden_by(mut self, other: CorrectConfig) -> CorrectConfig {
        macro_rules! take {
            ($($field:ident),*) => { $( if other.$field.is_some() { self.$field = other.$field; } )* };
        }
        take!(
            lattice,
            nn,
            calibrate,
            trust_inputs,
            polarity,
            mask,
            mask_polygon,
            plane_group,
            colormap,
            displacement,
            extent,
            channels,
            channel
        );
        if let Some(pipeline) = other.pipeline {
            let mut table = self.pipeline.take().unwrap_or_default();
            merge(&mut table, &pipeline);
            self.pipeline = Some(table);
        }
        let g = other.geometry;
        macro_rules! geometry {
            ($($field:ident),*) => { $( if g.$field.is_some() { self.geometry.$field = g.$field; } )* };
        }
        geometry!(
            pitch_x,
            pitch_y,
            pixel_period,
            line_time,
            turnaround_time,
            trace_fast,
            slow
        );
        self.overwrite |= other.overwrite;
        self
    }
}

/// `options` as a TOML table (every option; `None`s are left out).
pub fn pipeline_table(options: &PipelineOptions) -> Result<toml::Table> {
    toml::Table::try_from(options).context("cannot write the pipeline options as TOML")
}

/// Merges `given` into `base` key by key: tables recursively, anything else replaced. A
/// table whose `kind` differs (a different variant of a tagged option such as
/// `kernel` or `hysteresis`) replaces the base table whole.
fn merge(base: &mut toml::Table, given: &toml::Table) {
    for (key, value) in given {
        match (base.get_mut(key), value) {
            (Some(toml::Value::Table(old)), toml::Value::Table(new))
                if old.get("kind") == new.get("kind") || new.get("kind").is_none() =>
            {
                merge(old, new);
            }
            _ => {
                base.insert(key.clone(), value.clone());
            }
        }
    }
}

/// `message` with "did you mean" added when it reports an unknown field (serde's
/// "unknown field `x`, expected one of `a`, `b`"), and the field's place in `given`.
fn with_suggestion(message: &str, given: Option<&toml::Table>) -> String {
    let Some((unknown, valid)) = unknown_field(message) else {
        return message.to_string();
    };
    let mut text = message.trim_end().to_string();
    if let Some(path) = given.and_then(|t| key_path(t, &unknown)) {
        text.push_str(&format!(" (at pipeline.{path})"));
    }
    let closest = valid
        .iter()
        .map(|v| (edit_distance(&unknown, v), v))
        .min_by_key(|(d, _)| *d);
    if let Some((distance, name)) = closest
        && distance <= (unknown.chars().count() / 3).max(2)
    {
        text.push_str(&format!("; did you mean `{name}`?"));
    }
    text
}

/// The unknown field and the valid ones named by a serde error message.
fn unknown_field(message: &str) -> Option<(String, Vec<String>)> {
    let rest = message.split("unknown field `").nth(1)?;
    let unknown = rest.split('`').next()?.to_string();
    let expected = rest.split("expected ").nth(1).unwrap_or("");
    let valid = expected
        .split('`')
        .skip(1)
        .step_by(2)
        .map(str::to_string)
        .collect();
    Some((unknown, valid))
}

/// Where `key` occurs in `table`, as a dotted path (first occurrence, depth first).
fn key_path(table: &toml::Table, key: &str) -> Option<String> {
    for (name, value) in table {
        if name == key {
            return Some(name.clone());
        }
        if let toml::Value::Table(inner) = value
            && let Some(path) = key_path(inner, key)
        {
            return Some(format!("{name}.{path}"));
        }
    }
    None
}

/// Levenshtein distance between two names.
fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut previous = row[0];
        row[0] = i + 1;
        for (j, cb) in b.iter().enumerate() {
            let substitution = previous + usize::from(ca != *cb);
            previous = row[j + 1];
            row[j + 1] = substitution.min(previous + 1).min(row[j] + 1);
        }
    }
    row[b.len()]
}

/// The grid the corrected TIFF and GSF files are written on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Extent {
    /// The scan's own frame: what the correction moves outside it is cropped.
    #[default]
    Frame,
    /// Every corrected pixel (the paper's frame): a larger grid of the same pitch, no-data
    /// (NaN) around the image, its origin in the GSF's `XOffset`/`YOffset`.
    Full,
}

/// Which image channels are corrected besides the analysed one.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ChannelSet {
    /// Every image channel of the file.
    All,
}

/// Why the lattice and constant given cannot be combined, in quantities (the front ends
/// name their options: [`crate::hints`]).
#[derive(Debug, thiserror::Error)]
pub enum LatticeChoiceError {
    /// The nearest-neighbour distance is outside 0.1–100 nm.
    #[error(
        "{nn_m} m is not a plausible nearest-neighbour distance (expected 0.1–100 nm, e.g. \
         2.46 Å)"
    )]
    ImplausibleNn {
        /// The distance given, metres.
        nn_m: f64,
    },
    /// A catalogue shape without a constant, and no distance given.
    #[error("the {name} lattice needs its nearest-neighbour distance (or auto)")]
    NeedsConstant {
        /// The catalogue name.
        name: &'static str,
    },
    /// A distance given with a lattice file.
    #[error(
        "a lattice file cannot be rescaled by a nearest-neighbour distance; edit its vectors instead"
    )]
    FileRescaled,
}

/// The lattice named by `name` (a preset or a file), with its NN distance replaced by
/// `nn_m` if given.
pub fn build_lattice(name: &str, nn_m: Option<f64>) -> Result<Box<dyn Lattice + Send + Sync>> {
    if let Some(nn) = nn_m
        && !(nn.is_finite() && nn > 1e-11 && nn < 1e-7)
    {
        return Err(LatticeChoiceError::ImplausibleNn { nn_m: nn }.into());
    }
    if let Some(entry) = dhct_lattice::catalogue::lookup(name) {
        return entry.build(nn_m).map_err(|e| match e {
            LatticeError::NeedsConstant { name } => {
                LatticeChoiceError::NeedsConstant { name }.into()
            }
            other => other.into(),
        });
    }
    let path = Path::new(name);
    if std::fs::symlink_metadata(path).is_err() {
        bail!(
            "unknown lattice '{name}': use {}, or the path of a lattice file (TOML/JSON, see docs)",
            dhct_lattice::catalogue::names()
        );
    }
    let user =
        UserLattice::from_path(path).with_context(|| format!("cannot read lattice file {name}"))?;
    if nn_m.is_some() {
        return Err(LatticeChoiceError::FileRescaled.into());
    }
    let lattice: Box<dyn Lattice + Send + Sync> = Box::new(user);
    Ok(lattice)
}

#[cfg(test)]
mod tests {
    use super::*;
    use dhct_lattice::Hexagonal;

    #[test]
    fn presets_and_nn() {
        let g = build_lattice("graphite", None).unwrap();
        assert!((g.nearest_neighbour_distance() - 2.46e-10).abs() < 1e-15);
        let h = build_lattice("honeycomb", Some(1.42e-10)).unwrap();
        assert!((h.nearest_neighbour_distance() - 1.42e-10).abs() < 1e-14);
        let s = build_lattice("square", Some(3e-10)).unwrap();
        assert!((s.nearest_neighbour_distance() - 3e-10).abs() < 1e-15);
        assert!(build_lattice("square", None).is_err());
        assert!(build_lattice("graphite", Some(2.46)).is_err());
        let e = build_lattice("lieb", None).unwrap_err().to_string();
        assert!(e.contains("unknown lattice"), "{e}");
        // A catalogue entry without a known constant says what is missing; the front end
        // names its option (`--nn`, `nn=`).
        let e = build_lattice("kagome", None).unwrap_err();
        assert!(matches!(
            e.downcast_ref::<LatticeChoiceError>(),
            Some(LatticeChoiceError::NeedsConstant { name: "kagome" })
        ));
        let cli = crate::hints::explain_options(&e, crate::hints::Spelling::CommandLine);
        assert!(cli.contains("--lattice kagome needs --nn"), "{cli}");
        let k = build_lattice("kagome", Some(3e-10)).unwrap();
        assert!((k.nearest_neighbour_distance() - 3e-10).abs() < 1e-16);
    }

    #[test]
    fn toml_round_trip_and_override() {
        let text = "lattice = \"graphite\"\nnn = \"2.5A\"\npolarity = \"dark\"\n[geometry]\nline_time = 0.5\n";
        let config: CorrectConfig = toml::from_str(text).unwrap();
        assert_eq!(config.nn.as_ref().unwrap().metres().unwrap(), 2.5e-10);
        let cli = CorrectConfig {
            polarity: Some(Polarity::Bright),
            ..CorrectConfig::default()
        };
        let merged = config.overridden_by(cli);
        assert_eq!(merged.polarity, Some(Polarity::Bright));
        assert_eq!(merged.geometry.line_time, Some(0.5));
        assert!(toml::from_str::<CorrectConfig>("latice = \"x\"").is_err());
        // The fully resolved config (with every pipeline option) round-trips exactly.
        let graphite = Hexagonal::graphite();
        let options = PipelineOptions::for_lattice(&graphite);
        let full = CorrectConfig {
            pipeline: Some(pipeline_table(&options).unwrap()),
            ..merged
        };
        let text = toml::to_string(&full).unwrap();
        let back: CorrectConfig = toml::from_str(&text).unwrap();
        assert_eq!(back, full);
        assert_eq!(back.pipeline_options(&graphite).unwrap(), options);
    }

    /// The options a config holding only `section` gives for graphite.
    fn options_from(section: &str) -> Result<PipelineOptions> {
        let config: CorrectConfig = toml::from_str(section)?;
        config.check()?;
        config.pipeline_options(&Hexagonal::graphite())
    }

    #[test]
    fn a_partial_section_changes_only_its_keys_in_every_group() {
        let defaults = PipelineOptions::for_lattice(&Hexagonal::graphite());
        type Edit = fn(&mut PipelineOptions);
        let cases: Vec<(&str, Edit)> = vec![
            ("[pipeline.features]\nthreshold = 0.2", |o| {
                o.features.threshold = 0.2
            }),
            (
                "[pipeline.features.kernel]\nkind = \"gaussian-sigma\"\nsigma_px = 2.0",
                |o| {
                    o.features.kernel = dhct_features::KernelChoice::GaussianSigma { sigma_px: 2.0 }
                },
            ),
            ("[pipeline.dhct.neighbours]\nwindow = 0.3", |o| {
                o.dhct.neighbours.window = 0.3
            }),
            ("[pipeline.dhct.fit]\nrobust_rounds = 2", |o| {
                o.dhct.fit.robust_rounds = 2
            }),
            ("[pipeline.dhct]\nmethod = \"ellipse\"", |o| {
                o.dhct.method = Some(dhct_lattice::LocalDistortionMethod::Ellipse)
            }),
            ("[pipeline.lattice_fit]\ninitial_radius = 6.0", |o| {
                o.lattice_fit.initial_radius = 6.0
            }),
            ("[pipeline.regions]\nmin_features = 12", |o| {
                o.regions.min_features = 12
            }),
            ("[pipeline.unit_cell]\nresolution = 64", |o| {
                o.unit_cell.resolution = 64
            }),
            (
                "[pipeline.unit_cell.selection]\nexclude_outliers_sigma = 3.0",
                |o| o.unit_cell.selection.exclude_outliers_sigma = Some(3.0),
            ),
            ("[pipeline]\nkeep_correlation = false", |o| {
                o.keep_correlation = false
            }),
        ];
        for (section, edit) in cases {
            let mut expected = defaults.clone();
            edit(&mut expected);
            assert_ne!(expected, defaults, "{section}: the case changes nothing");
            let got = options_from(section).unwrap_or_else(|e| panic!("{section}: {e:#}"));
            assert_eq!(got, expected, "{section}");
        }
        // No section at all: exactly the defaults of a run without a config.
        assert_eq!(options_from("").unwrap(), defaults);
        // Flags and files merge key by key too.
        let file: CorrectConfig =
            toml::from_str("[pipeline.features]\nthreshold = 0.2\nline_correction = \"none\"")
                .unwrap();
        let flags: CorrectConfig = toml::from_str("[pipeline.features]\nthreshold = 0.3").unwrap();
        let merged = file.overridden_by(flags);
        let options = merged.pipeline_options(&Hexagonal::graphite()).unwrap();
        assert_eq!(options.features.threshold, 0.3);
        assert_eq!(
            options.features.line_correction,
            dhct_features::LineCorrection::None
        );
    }

    #[test]
    fn unknown_keys_are_errors_with_a_suggestion() {
        let error = format!(
            "{:#}",
            options_from("[pipeline.lattice_fit]\ninitial_radiuss = 3.0").unwrap_err()
        );
        assert!(
            error.contains("initial_radiuss")
                && error.contains("pipeline.lattice_fit.initial_radiuss")
                && error.contains("did you mean `initial_radius`"),
            "{error}"
        );
        let error = format!(
            "{:#}",
            options_from("[pipeline.features]\nthreshhold = 0.2").unwrap_err()
        );
        assert!(error.contains("did you mean `threshold`"), "{error}");
        let error = format!(
            "{:#}",
            options_from("[pipeline.dhct.neighbours]\nrdf_shell = 3").unwrap_err()
        );
        assert!(error.contains("did you mean `rdf_shells`"), "{error}");
        let error = format!(
            "{:#}",
            options_from("[pipeline.unitcell]\nresolution = 8").unwrap_err()
        );
        assert!(error.contains("did you mean `unit_cell`"), "{error}");
        let error = with_suggestion(
            &toml::from_str::<CorrectConfig>("latice = 'graphite'")
                .unwrap_err()
                .to_string(),
            None,
        );
        assert!(error.contains("did you mean `lattice`"), "{error}");
        assert_eq!(edit_distance("kitten", "sitting"), 3);
    }

    #[test]
    fn out_of_range_values_name_the_key_the_value_and_the_range() {
        for (section, key) in [
            ("[geometry]\npixel_period = 1e30", "pixel_period"),
            (
                "[pipeline.lattice_fit]\ninitial_radius = nan",
                "initial_radius",
            ),
        ] {
            let error = format!("{:#}", options_from(section).unwrap_err());
            assert!(
                error.contains(key) && error.contains("range"),
                "{section}: {error}"
            );
        }
    }
}
