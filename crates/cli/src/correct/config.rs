//! The `dhct correct` configuration: a TOML file, overridden by command-line flags, and
//! written back fully resolved (every pipeline option) into the output directory so that
//! `dhct correct --config OUTDIR/config.toml INPUT -o NEWDIR` repeats the run.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use dhct_features::Polarity;
use dhct_lattice::{Hexagonal, Honeycomb, Lattice, PlaneGroup, Square, UserLattice};
use dhct_pipeline::PipelineOptions;
use dhct_sm4_io::GeometryOverrides;
use dhct_sm4_io::png_file::Colormap;
use serde::{Deserialize, Serialize};

use crate::units;

/// A length given as metres or as text with a unit ("2.46A", "0.246nm").
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Length {
    Metres(f64),
    Text(String),
}

impl Length {
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
    /// graphite, square, honeycomb, sam-sqrt3, or the path of a user lattice (TOML/JSON).
    pub lattice: Option<String>,
    /// Nearest-neighbour distance; replaces the preset's.
    pub nn: Option<Length>,
    /// bright (atoms are maxima) or dark (minima).
    pub polarity: Option<Polarity>,
    /// Mask image (PNG, NPY, ...; true above half its range), raw-image pixels.
    pub mask: Option<PathBuf>,
    /// Mask polygon, vertices in raw-image pixels (x = column, y = row).
    pub mask_polygon: Option<Vec<[f64; 2]>>,
    /// Plane group of the symmetry average (default: the lattice's).
    pub plane_group: Option<PlaneGroup>,
    /// Colour map of the pictures.
    pub colormap: Option<Colormap>,
    /// Scan geometry replacing the file's (SI units).
    pub geometry: GeometryOverrides,
    /// Every option of the chain (features, model, lattice fit, unit cells).
    pub pipeline: Option<PipelineOptions>,
}

impl CorrectConfig {
    pub fn read(path: &Path) -> Result<CorrectConfig> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read config {}", path.display()))?;
        toml::from_str(&text).with_context(|| format!("config {} is not valid", path.display()))
    }

    /// `other`'s set fields replace this one's.
    pub fn overridden_by(mut self, other: CorrectConfig) -> CorrectConfig {
        macro_rules! take {
            ($($field:ident),*) => { $( if other.$field.is_some() { self.$field = other.$field; } )* };
        }
        take!(
            lattice,
            nn,
            polarity,
            mask,
            mask_polygon,
            plane_group,
            colormap,
            pipeline
        );
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
        self
    }
}

/// The lattice named by `name` (a preset or a file), with its NN distance replaced by
/// `nn_m` if given.
pub fn build_lattice(name: &str, nn_m: Option<f64>) -> Result<Box<dyn Lattice + Send + Sync>> {
    if let Some(nn) = nn_m
        && !(nn.is_finite() && nn > 1e-11 && nn < 1e-7)
    {
        bail!(
            "--nn {nn} m is not a plausible nearest-neighbour distance (expected 0.1–100 nm, e.g. 2.46A)"
        );
    }
    let lattice: Box<dyn Lattice + Send + Sync> = match name.to_ascii_lowercase().as_str() {
        "graphite" | "hopg" => match nn_m {
            Some(a) => Box::new(Hexagonal::new("graphite", a, PlaneGroup::P3m1)?),
            None => Box::new(Hexagonal::graphite()),
        },
        "hexagonal" | "trigonal" => Box::new(Hexagonal::new(
            "hexagonal",
            nn_m.context("--lattice hexagonal needs --nn")?,
            PlaneGroup::P6mm,
        )?),
        "sam-sqrt3" | "sam" => match nn_m {
            Some(a) => Box::new(Hexagonal::new("sam-sqrt3", a, PlaneGroup::P6mm)?),
            None => Box::new(Hexagonal::sam_sqrt3()),
        },
        "honeycomb" | "graphene" => match nn_m {
            Some(nn) => Box::new(Honeycomb::new(nn * 3f64.sqrt())?),
            None => Box::new(Honeycomb::graphene()),
        },
        "square" => Box::new(Square::new(
            nn_m.context("--lattice square needs --nn (its lattice constant)")?,
        )?),
        _ => {
            let path = Path::new(name);
            if !path.exists() {
                bail!(
                    "unknown lattice '{name}': use graphite, honeycomb, sam-sqrt3, hexagonal, \
                     square, or the path of a lattice file (TOML/JSON, see docs)"
                );
            }
            let user = UserLattice::from_path(path)
                .with_context(|| format!("cannot read lattice file {name}"))?;
            if nn_m.is_some() {
                bail!("--nn cannot rescale a lattice file; edit its vectors instead");
            }
            Box::new(user)
        }
    };
    Ok(lattice)
}

#[cfg(test)]
mod tests {
    use super::*;

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
        let e = build_lattice("kagome", None).unwrap_err().to_string();
        assert!(e.contains("unknown lattice"), "{e}");
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
        // The fully resolved config (with every pipeline option) round-trips.
        let full = CorrectConfig {
            pipeline: Some(PipelineOptions::default()),
            ..merged
        };
        let text = toml::to_string(&full).unwrap();
        let back: CorrectConfig = toml::from_str(&text).unwrap();
        assert_eq!(back.lattice, full.lattice);
        assert_eq!(
            back.pipeline.unwrap().unit_cell,
            full.pipeline.unwrap().unit_cell
        );
    }
}
