//! A validation set as data: what its scans' physics looks like ([`ScanForm`]) and which
//! seeds it runs ([`ValidationSet`]), read from `sets.toml` ([`Catalogue`]).

use std::collections::HashSet;

use dhct_diagnose::Candidate;
use serde::{Deserialize, Deserializer, Serialize};

/// The sets shipped with the crate (`crates/validation/sets.toml`).
const SHIPPED: &str = include_str!("../sets.toml");

/// Most seeds one range may name (a typo in a range must not allocate without bound).
const MAX_RANGE: u64 = 100_000;

/// Why a set file cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum SetError {
    /// Not TOML of the expected shape.
    #[error("the validation sets are not readable: {0}")]
    Syntax(#[from] toml::de::Error),
    /// A set's numbers are out of range.
    #[error("validation set `{set}`: {problem}")]
    Invalid {
        /// The set's name.
        set: String,
        /// What is wrong.
        problem: String,
    },
    /// Two sets share a name.
    #[error("two validation sets are named `{0}`")]
    Duplicate(String),
    /// No set has the name asked for.
    #[error("no validation set is named `{asked}` (known: {known})")]
    Unknown {
        /// The name asked for.
        asked: String,
        /// The names there are, comma-separated.
        known: String,
    },
}

/// The fast-scan hysteresis law of a set's base model.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum BaseForm {
    /// dhct's default power law, randomised per seed ([`crate::base_config`]).
    PowerLaw,
    /// Cubic, quartic, exponential or power by seed ([`crate::BaseLaw::of_seed`]).
    LawBySeed,
}

/// How a set's slow-scan hysteresis relaxes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SlowRelaxation {
    /// Within 1–3 % of the frame, i.e. mostly within the first row of features.
    FirstRows,
    /// Over 3–10 % of the frame, moving the slow axis by 40 pm × the magnitude in all.
    OverRows,
}

/// The localisation noise of a set's position path.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum NoiseForm {
    /// Independent per feature.
    #[default]
    White,
    /// 36 % of the variance correlated over one second ([`crate::PositionNoise::of_form`]).
    Correlated,
}

/// What the scans of a set look like: the physics drawn for each of its seeds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScanForm {
    /// The base model's fast-scan hysteresis law.
    pub base: BaseForm,
    /// Rendered as images and found by the feature finder (else positions with noise).
    #[serde(default)]
    pub images: bool,
    /// How slow-scan hysteresis relaxes.
    pub slow_hysteresis: SlowRelaxation,
    /// Localisation noise of the position path.
    #[serde(default)]
    pub position_noise: NoiseForm,
    /// Bands an effect's magnitude factor (× nominal) is drawn from: one band, or a low and
    /// a high one, picked at random per effect.
    pub magnitude: Vec<[f64; 2]>,
    /// Band of a vibration's frequency, Hz.
    pub vibration_hz: [f64; 2],
    /// Band of the sample's tilt, |∇z| (metres per metre; azimuth drawn per seed): the
    /// plane every real image has, below the line offsets. None: flat.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plane_slope: Option<[f64; 2]>,
    /// Band of the height jump at a tip change, metres (sign drawn per seed). None: the
    /// tip jumps laterally only.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tip_height_m: Option<[f64; 2]>,
}

/// One validation set: its scans' form and its seeds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ValidationSet {
    /// Short name, e.g. `"held-out"`.
    pub name: String,
    /// Its history: when it was fixed, run and what it showed.
    pub about: String,
    /// Never looked at while the method changed: its numbers are evidence.
    pub evidence: bool,
    /// The acceptance targets are checked on it.
    pub judged: bool,
    /// Run by the default sweep.
    pub sweep: bool,
    /// Seeds of the single-effect cases (each effect, each seed).
    #[serde(deserialize_with = "seeds")]
    pub seeds: Vec<u64>,
    /// Effects this set simulates one at a time besides the sweep's.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub added_effects: Vec<Candidate>,
    /// Seeds of the effect-free cases.
    #[serde(deserialize_with = "seeds")]
    pub null_seeds: Vec<u64>,
    /// Seeds of the out-of-library cases (each foreign effect, each seed).
    #[serde(default, deserialize_with = "seeds")]
    pub foreign_seeds: Vec<u64>,
    /// Added to every mixture seed, so that each set's mixtures are its own scans.
    pub mixture_offset: u64,
    /// What its scans look like.
    pub scans: ScanForm,
}

/// The default sweep's cases beyond the sets' own.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SweepPlan {
    /// Effects simulated one at a time.
    pub effects: Vec<Candidate>,
    /// Two-effect mixtures.
    pub mixtures: Vec<[Candidate; 2]>,
    /// Seeds of the mixtures (each set adds its `mixture_offset`).
    pub mixture_seeds: Vec<u64>,
    /// Localisation noise of the position path, metres per axis.
    pub noise_m: f64,
}

/// Every set of a set file, in report order, with the sweep's plan.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Catalogue {
    /// The default sweep.
    pub sweep: SweepPlan,
    /// The sets.
    #[serde(rename = "set")]
    pub sets: Vec<ValidationSet>,
}

/// Seeds as a list or as an inclusive range `{ first, last }`.
#[derive(Deserialize)]
#[serde(untagged)]
enum SeedSpec {
    List(Vec<u64>),
    Range { first: u64, last: u64 },
}

fn seeds<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<u64>, D::Error> {
    match SeedSpec::deserialize(d)? {
        SeedSpec::List(v) => Ok(v),
        SeedSpec::Range { first, last } if last >= first && last - first < MAX_RANGE => {
            Ok((first..=last).collect())
        }
        SeedSpec::Range { first, last } => Err(serde::de::Error::custom(format!(
            "seed range {first}..={last} is empty or longer than {MAX_RANGE}"
        ))),
    }
}

impl Catalogue {
    /// The sets shipped with the crate.
    pub fn shipped() -> Catalogue {
        Catalogue::parse(SHIPPED).expect("the shipped sets.toml is checked by a test")
    }

    /// Reads and checks a set file's text.
    pub fn parse(text: &str) -> Result<Catalogue, SetError> {
        let catalogue: Catalogue = toml::from_str(text)?;
        let mut names = HashSet::new();
        for set in &catalogue.sets {
            if !names.insert(set.name.as_str()) {
                return Err(SetError::Duplicate(set.name.clone()));
            }
            set.check()?;
        }
        Ok(catalogue)
    }

    /// The set named `name`.
    pub fn named(&self, name: &str) -> Result<&ValidationSet, SetError> {
        self.sets
            .iter()
            .find(|s| s.name == name)
            .ok_or_else(|| SetError::Unknown {
                asked: name.to_string(),
                known: self
                    .sets
                    .iter()
                    .map(|s| s.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", "),
            })
    }
}

impl ValidationSet {
    /// The shipped set named `name` (tests and examples: `ValidationSet::named("tuned")`).
    pub fn named(name: &str) -> Result<ValidationSet, SetError> {
        Catalogue::shipped().named(name).cloned()
    }

    fn check(&self) -> Result<(), SetError> {
        let invalid = |problem: String| SetError::Invalid {
            set: self.name.clone(),
            problem,
        };
        let band_ok = |[lo, hi]: [f64; 2]| lo.is_finite() && hi.is_finite() && 0.0 < lo && lo < hi;
        let magnitude = &self.scans.magnitude;
        if magnitude.is_empty() || magnitude.len() > 2 {
            return Err(invalid(format!(
                "`magnitude` holds {} bands; give one, or a low and a high one",
                magnitude.len()
            )));
        }
        if let Some(band) = magnitude.iter().find(|b| !band_ok(**b)) {
            return Err(invalid(format!(
                "magnitude band {band:?} is not 0 < low < high"
            )));
        }
        if !band_ok(self.scans.vibration_hz) {
            return Err(invalid(format!(
                "vibration band {:?} Hz is not 0 < low < high",
                self.scans.vibration_hz
            )));
        }
        if let Some(band) = self
            .scans
            .plane_slope
            .filter(|b| !band_ok(*b) || b[1] > 1.0)
        {
            return Err(invalid(format!(
                "plane slope band {band:?} is not 0 < low < high ≤ 1"
            )));
        }
        if let Some(band) = self
            .scans
            .tip_height_m
            .filter(|b| !band_ok(*b) || b[1] > 1e-9)
        {
            return Err(invalid(format!(
                "tip height band {band:?} m is not 0 < low < high ≤ 1 nm"
            )));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shipped_sets_parse_with_unique_names_and_ranges_expanded() {
        let catalogue = Catalogue::parse(SHIPPED).expect("parses");
        assert_eq!(catalogue.sets.len(), 15);
        let held_out = catalogue.named("held-out").expect("exists");
        assert_eq!(held_out.null_seeds.len(), 40);
        assert_eq!(held_out.null_seeds[0], 12101);
        assert!(held_out.evidence && held_out.judged);
        assert_eq!(catalogue.sweep.effects.len(), 9);
    }

    #[test]
    fn broken_set_files_are_named() {
        let base = SHIPPED.replacen("magnitude = [[0.8, 1.2]]", "magnitude = [[1.2, 0.8]]", 1);
        let err = Catalogue::parse(&base).expect_err("reversed band");
        assert!(err.to_string().contains("`tuned`"), "{err}");
        let twice = format!(
            "{SHIPPED}\n{}",
            &SHIPPED[SHIPPED.find("\n[[set]]").expect("a set")..]
        );
        assert!(matches!(
            Catalogue::parse(&twice),
            Err(SetError::Duplicate(_))
        ));
        let huge = SHIPPED.replacen(
            "null_seeds = { first = 100, last = 119 }",
            "null_seeds = { first = 100, last = 100000000 }",
            1,
        );
        let huge = Catalogue::parse(&huge);
        assert!(matches!(huge, Err(SetError::Syntax(_))), "{huge:?}");
        let unknown = Catalogue::shipped().named("nope").expect_err("unknown");
        assert!(unknown.to_string().contains("held-out"), "{unknown}");
        let steep = SHIPPED.replacen("plane_slope = [0.02, 0.08]", "plane_slope = [0.5, 2.0]", 1);
        let err = Catalogue::parse(&steep).expect_err("a slope of 2");
        assert!(err.to_string().contains("`tilted-dev`"), "{err}");
        let tall = SHIPPED.replacen(
            "tip_height_m = [20e-12, 80e-12]",
            "tip_height_m = [0.1, 1.0]",
            1,
        );
        let err = Catalogue::parse(&tall).expect_err("a 1 m tip jump");
        assert!(err.to_string().contains("tip height"), "{err}");
    }
}
