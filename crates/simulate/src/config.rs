//! The simulation config: serde types read from TOML or JSON (or built in Rust), and their
//! validation. Every length is metres, every time seconds, every angle radians; the unit is
//! in each field's name.
//!
//! ```toml
//! name = "example"
//! seed = 7
//!
//! [scan]
//! columns = 256
//! rows = 256
//! width_m = 4e-9
//! height_m = 4e-9
//! fast_speed_m_per_s = 50e-9
//! trace_fast = "right"
//! slow = "down"
//!
//! [surface]
//! lattice = { kind = "graphite" }
//! feature = { height_m = 40e-12, sigma_m = [0.6e-10, 0.6e-10] }
//!
//! [[effects]]
//! kind = "thermal-drift"
//! velocity_m_per_s = [2e-12, -3e-12]
//!
//! [noise]
//! white_sigma_m = 2e-12
//! ```

use std::path::Path;

use dhct_lattice::{Hexagonal, Honeycomb, Lattice, PlaneGroup, Rectangular, Square, UserLattice};
use dhct_scan::{ScanDirection, ScanGeometry};
use serde::{Deserialize, Serialize};

use crate::effects::EffectConfig;
use crate::error::{finite, finite2, fraction, invalid, non_negative, positive};
use crate::sequence::SequenceConfig;
use crate::{Region, SimulationError};

/// Memory a simulation takes per pixel, bytes (measured: 2048² px take 0.30 GB peak, about
/// 72 bytes per pixel for trace, retrace, displacement fields, truth and outputs; rounded up).
pub const BYTES_PER_PIXEL: u64 = 80;

/// Most memory the images of one simulation may take: 2 GiB.
pub const MAX_MEMORY_BYTES: u64 = 2 << 30;

/// Largest image the simulator accepts, pixels: [`MAX_MEMORY_BYTES`] / [`BYTES_PER_PIXEL`]
/// (26.8 million, e.g. 5120 × 5120; 16384² would need 21 GB).
pub const MAX_PIXELS: usize = (MAX_MEMORY_BYTES / BYTES_PER_PIXEL) as usize;

/// Largest number of random adatoms (and of listed adatom or vacancy positions).
pub const MAX_ADATOMS: usize = 1_000_000;

/// Most displacement effects in one simulation (each is evaluated at every pixel).
pub const MAX_EFFECTS: usize = 64;

/// Most steps, strain regions and lobes of a feature (each list).
pub const MAX_LIST: usize = 256;

/// Most lattice sites in the nominal scanned area (cells × motif sites): 2·10^7 (each
/// site takes tens of bytes in the site table).
pub const MAX_NOMINAL_SITES: f64 = 2e7;

/// Largest simulator config file read, bytes.
pub const MAX_CONFIG_BYTES: u64 = 16 << 20;

/// Everything one simulation needs. Deterministic: the same config gives bit-identical
/// output, whatever the number of threads.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimulationConfig {
    /// A short name, used in file metadata.
    #[serde(default)]
    pub name: String,
    /// What this simulation shows.
    #[serde(default)]
    pub description: String,
    /// Seed of every random choice (vacancies, adatoms, noise).
    #[serde(default)]
    pub seed: u64,
    /// Image size, scale, speed and directions.
    pub scan: ScanConfig,
    /// The sample.
    pub surface: SurfaceConfig,
    /// The tip's lateral resolution.
    #[serde(default)]
    pub tip: TipConfig,
    /// Random height noise.
    #[serde(default)]
    pub noise: NoiseConfig,
    /// Which files [`crate::SimulationOutput::write`] writes.
    #[serde(default)]
    pub output: OutputConfig,
    /// The displacement effects, summed.
    #[serde(default)]
    pub effects: Vec<EffectConfig>,
    /// If present, the config describes an image sequence (many frames of one area with
    /// drift continuous across them), run by [`crate::SequenceSimulation`]; the rest of the
    /// config is each frame's base.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sequence: Option<SequenceConfig>,
}

/// The raster scan. Both trace and retrace are simulated.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScanConfig {
    /// Pixels along x (≥ 1).
    pub columns: usize,
    /// Pixels along y (≥ 1).
    pub rows: usize,
    /// Image width, metres (`columns · pitch_x`).
    pub width_m: f64,
    /// Image height, metres (`rows · pitch_y`).
    pub height_m: f64,
    /// Controller tip speed along the fast axis, m/s (pixel period = fast pitch / speed).
    pub fast_speed_m_per_s: f64,
    /// Dead time at each end of every line, seconds.
    #[serde(default)]
    pub turnaround_s: f64,
    /// Fast direction of the trace.
    #[serde(default = "right")]
    pub trace_fast: ScanDirection,
    /// Slow direction.
    #[serde(default = "down")]
    pub slow: ScanDirection,
    /// Memory the simulation may take, GiB (default [`MAX_MEMORY_BYTES`], 2 GiB, which
    /// caps images at [`MAX_PIXELS`]); raise it for larger images on a machine that has the
    /// memory ([`BYTES_PER_PIXEL`] bytes per pixel; at most 256 GiB).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub memory_limit_gib: Option<f64>,
}

fn right() -> ScanDirection {
    ScanDirection::Right
}

fn down() -> ScanDirection {
    ScanDirection::Down
}

/// The sample: a lattice of features with defects, domains, steps and strain.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SurfaceConfig {
    /// The lattice.
    pub lattice: LatticeConfig,
    /// Rotation of the lattice, radians, from +x towards +y (clockwise on screen).
    #[serde(default)]
    pub angle_rad: f64,
    /// Position of the cell origin (n = m = 0), metres, sample frame.
    #[serde(default)]
    pub origin_m: [f64; 2],
    /// What one feature (atom or molecule) looks like.
    pub feature: FeatureShape,
    /// Vacancies and adatoms.
    #[serde(default)]
    pub defects: DefectConfig,
    /// A rotated domain replacing the lattice inside a region.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub second_domain: Option<SecondDomain>,
    /// Step edges: each raises its region by a height.
    #[serde(default)]
    pub steps: Vec<StepEdge>,
    /// The sample's tilt as a height gradient `[∂z/∂x, ∂z/∂y]` (metres per metre, sample
    /// frame): the plane a real sample never lies flat in, which moves with it under drift.
    #[serde(default, skip_serializing_if = "is_flat_plane")]
    pub plane_slope: [f64; 2],
    /// Regions of homogeneous sample strain.
    #[serde(default)]
    pub strain: Vec<StrainRegion>,
    /// Height modulations at fractional lattice frequencies: a superstructure's or a
    /// charge-density wave's satellites, a period doubling, an incommensurate moiré.
    #[serde(default)]
    pub modulations: Vec<Modulation>,
}

fn is_flat_plane(slope: &[f64; 2]) -> bool {
    *slope == [0.0, 0.0]
}

/// A height modulation `amplitude·cos(2π·G·(p − origin))` over the whole surface, with `G`
/// the lattice's reciprocal vector at a fractional index: `[0.5, 0]` doubles the period
/// along the lattice's first reflection, `[1/3, 1/3]` is a (√3×√3)R30° superstructure of
/// a hexagonal lattice. It rotates with the lattice (the first domain's angle).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Modulation {
    /// Index `(h, k)` in the reciprocal basis of the lattice's translation cell (any real
    /// numbers, not both 0).
    pub index: [f64; 2],
    /// Amplitude, metres.
    pub amplitude_m: f64,
}

/// Which lattice the surface follows.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case")]
pub enum LatticeConfig {
    /// HOPG's imaged atoms, a = 2.46 Å.
    Graphite,
    /// Graphene, both sublattices (a = 2.46 Å, C–C 1.42 Å).
    Graphene,
    /// The (√3×√3)R30° alkanethiol SAM on Au(111), a = 4.99 Å.
    SamSqrt3,
    /// A hexagonal lattice with one feature per cell.
    Hexagonal {
        /// Lattice constant (= nearest-neighbour distance), metres.
        a_m: f64,
    },
    /// A honeycomb (two sites per hexagonal cell of constant `a_m`).
    Honeycomb {
        /// Cell constant, metres.
        a_m: f64,
    },
    /// A square lattice.
    Square {
        /// Lattice constant, metres.
        a_m: f64,
    },
    /// A rectangular lattice `a × b`.
    Rectangular {
        /// Side along x, metres.
        a_m: f64,
        /// Side along y, metres.
        b_m: f64,
    },
    /// Any lattice, in the `dhct-lattice` user-lattice layout (name, length_unit, a1, a2,
    /// plane_group, motif).
    User(UserLattice),
    /// A lattice of the `dhct-lattice` catalogue by name (the names `dhct correct --lattice`
    /// takes), with its nearest-neighbour distance replaced by `nn_m` if given.
    Catalogue {
        /// The catalogue name, e.g. "si111-7x7".
        name: String,
        /// Nearest-neighbour distance, metres (needed by entries without a known constant).
        #[serde(default)]
        nn_m: Option<f64>,
    },
}

impl LatticeConfig {
    /// Builds the lattice.
    pub fn build(&self) -> Result<Box<dyn Lattice>, SimulationError> {
        Ok(match self {
            // The named lattices are the catalogue's (one registry for every front end).
            LatticeConfig::Graphite => catalogue_lattice("graphite", None)?,
            LatticeConfig::Graphene => catalogue_lattice("honeycomb", None)?,
            LatticeConfig::SamSqrt3 => catalogue_lattice("sam-sqrt3", None)?,
            LatticeConfig::Hexagonal { a_m } => {
                Box::new(Hexagonal::new("hexagonal", *a_m, PlaneGroup::P6mm)?)
            }
            LatticeConfig::Honeycomb { a_m } => Box::new(Honeycomb::new(*a_m)?),
            LatticeConfig::Square { a_m } => Box::new(Square::new(*a_m)?),
            LatticeConfig::Rectangular { a_m, b_m } => Box::new(Rectangular::new(*a_m, *b_m)?),
            LatticeConfig::User(lattice) => Box::new(lattice.clone()),
            LatticeConfig::Catalogue { name, nn_m } => catalogue_lattice(name, *nn_m)?,
        })
    }
}

/// The catalogue lattice `name`, with its nearest-neighbour distance `nn_m` (metres) if
/// given.
fn catalogue_lattice(name: &str, nn_m: Option<f64>) -> Result<Box<dyn Lattice>, SimulationError> {
    let entry =
        dhct_lattice::catalogue::lookup(name).ok_or_else(|| SimulationError::InvalidConfig {
            field: "surface.lattice.name".into(),
            reason: format!(
                "unknown catalogue lattice '{name}' (use {})",
                dhct_lattice::catalogue::names()
            ),
        })?;
    Ok(entry.build(nn_m)?)
}

/// One feature: a sum of 2-D Gaussians ("lobes") centred on the lattice site.
///
/// Heights are peak heights in metres for a motif site of relative height 1; shapes are
/// given in the lattice frame and rotate with the lattice (and with a second domain).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FeatureShape {
    /// Peak height, metres (negative for dark features).
    pub height_m: f64,
    /// Standard deviations along the feature's own axes `[σ1, σ2]`, metres (> 0).
    pub sigma_m: [f64; 2],
    /// Rotation of the σ1 axis from +x towards +y, radians.
    #[serde(default)]
    pub angle_rad: f64,
    /// If not empty, the feature is these lobes instead of one centred Gaussian (a molecule).
    #[serde(default)]
    pub lobes: Vec<Lobe>,
}

/// One Gaussian of a molecule-like feature.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Lobe {
    /// Offset from the lattice site, metres, lattice frame.
    pub offset_m: [f64; 2],
    /// Peak height relative to [`FeatureShape::height_m`].
    #[serde(default = "one")]
    pub relative_height: f64,
    /// `[σ1, σ2]`, metres; the feature's when omitted.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma_m: Option<[f64; 2]>,
    /// Rotation of σ1 from +x towards +y, radians; the feature's when omitted.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub angle_rad: Option<f64>,
}

fn one() -> f64 {
    1.0
}

/// Point defects.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DefectConfig {
    /// Probability that a lattice site is empty (chosen from the seed and the site's
    /// indices, so it does not depend on the scanned area).
    #[serde(default)]
    pub vacancy_fraction: f64,
    /// Seed of the vacancies' choice (default: the simulation's seed). A sequence sets it
    /// to its own seed in every frame, so that each frame shows the same sites empty.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub vacancy_seed: Option<u64>,
    /// Sites to remove: the site nearest each point (within half the nearest-neighbour
    /// distance), metres, sample frame.
    #[serde(default)]
    pub vacancy_positions_m: Vec<[f64; 2]>,
    /// Number of adatoms placed uniformly at random over the nominal image area.
    #[serde(default)]
    pub adatom_count: usize,
    /// Adatoms at given positions, metres, sample frame.
    #[serde(default)]
    pub adatom_positions_m: Vec<[f64; 2]>,
    /// Adatom peak height relative to [`FeatureShape::height_m`]; an adatom is one
    /// Gaussian with the feature's σ.
    #[serde(default = "adatom_height")]
    pub adatom_relative_height: f64,
}

fn adatom_height() -> f64 {
    1.5
}

impl Default for DefectConfig {
    fn default() -> Self {
        DefectConfig {
            vacancy_fraction: 0.0,
            vacancy_seed: None,
            vacancy_positions_m: Vec::new(),
            adatom_count: 0,
            adatom_positions_m: Vec::new(),
            adatom_relative_height: adatom_height(),
        }
    }
}

/// A second rotational domain of the same lattice, filling `region`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SecondDomain {
    /// Where the second domain replaces the first.
    pub region: Region,
    /// Its lattice rotation, radians (absolute, like [`SurfaceConfig::angle_rad`]).
    pub angle_rad: f64,
    /// Its cell origin, metres.
    #[serde(default)]
    pub origin_m: [f64; 2],
}

/// A step edge: `region` (the upper terrace) is raised by `height_m`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StepEdge {
    /// The upper terrace.
    pub region: Region,
    /// Step height, metres (e.g. 3.35e-10 for graphite).
    pub height_m: f64,
}

/// Homogeneous strain of the sample inside a region: a site at `r` (inside the region) moves
/// by `ε·(r − anchor)`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StrainRegion {
    /// Where the strain acts (tested on the unstrained site positions).
    pub region: Region,
    /// Displacement gradient `[[ε_xx, ε_xy], [ε_yx, ε_yy]]`, dimensionless.
    pub strain: [[f64; 2]; 2],
    /// The point that does not move, metres.
    pub anchor_m: [f64; 2],
}

/// The tip's lateral resolution.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TipConfig {
    /// Standard deviation of a Gaussian tip response, metres (0 = ideal tip). Gaussian
    /// features broaden to `σ² + σ_tip²` (keeping their volume), steps to an erf profile.
    #[serde(default)]
    pub sigma_m: f64,
}

/// Random height noise (all zero by default).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NoiseConfig {
    /// RMS of white (per-pixel, independent) height noise, metres.
    #[serde(default)]
    pub white_sigma_m: f64,
    /// RMS of 1/f (pink) height noise over the acquisition sequence, metres.
    #[serde(default)]
    pub pink_sigma_m: f64,
    /// RMS of a random height offset per scan line (each pass separately), metres.
    #[serde(default)]
    pub line_offset_sigma_m: f64,
    /// Probability that a pixel holds a spike.
    #[serde(default)]
    pub spike_probability: f64,
    /// Typical spike height, metres (each spike is ±0.5–1.5 × this).
    #[serde(default)]
    pub spike_height_m: f64,
}

/// Files written besides the ground truth.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OutputConfig {
    /// Image formats: any of "sm4", "gsf", "npy", "png".
    #[serde(default = "default_formats")]
    pub formats: Vec<OutputFormat>,
}

impl Default for OutputConfig {
    fn default() -> Self {
        OutputConfig {
            formats: default_formats(),
        }
    }
}

fn default_formats() -> Vec<OutputFormat> {
    vec![OutputFormat::Sm4, OutputFormat::Png]
}

/// An image file format for the simulated pair.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum OutputFormat {
    /// `simulation.sm4`: trace and retrace pages.
    Sm4,
    /// `trace.gsf`, `retrace.gsf`.
    Gsf,
    /// `trace.npy`, `retrace.npy` (float64, metres).
    Npy,
    /// `trace.png`, `retrace.png` (colour-mapped previews).
    Png,
}

impl SimulationConfig {
    /// Parses TOML text (not validated; see [`SimulationConfig::validate`]).
    pub fn from_toml_str(text: &str) -> Result<SimulationConfig, SimulationError> {
        toml::from_str(text).map_err(|e| SimulationError::Parse {
            path: None,
            message: e.to_string(),
        })
    }

    /// Parses JSON text (not validated).
    pub fn from_json_str(text: &str) -> Result<SimulationConfig, SimulationError> {
        serde_json::from_str(text).map_err(|e| SimulationError::Parse {
            path: None,
            message: e.to_string(),
        })
    }

    /// Reads and validates a `.toml` or `.json` config (JSON if the text starts with `{`).
    /// Only a regular file of at most [`MAX_CONFIG_BYTES`] is read: a FIFO, device or
    /// directory is refused before it is opened.
    pub fn from_path(path: &Path) -> Result<SimulationConfig, SimulationError> {
        let text = dhct_sm4_io::read_regular_text(path, MAX_CONFIG_BYTES).map_err(|error| {
            SimulationError::Io {
                path: path.to_path_buf(),
                source: std::io::Error::other(error.to_string()),
            }
        })?;
        let parsed = if text.trim_start().starts_with('{') {
            Self::from_json_str(&text)
        } else {
            Self::from_toml_str(&text)
        };
        let config = parsed.map_err(|error| match error {
            SimulationError::Parse { message, .. } => SimulationError::Parse {
                path: Some(path.to_path_buf()),
                message,
            },
            other => other,
        })?;
        config.validate()?;
        Ok(config)
    }

    /// The config as TOML text.
    pub fn to_toml_string(&self) -> Result<String, SimulationError> {
        toml::to_string(self).map_err(|e| SimulationError::Parse {
            path: None,
            message: format!("cannot write TOML: {e}"),
        })
    }

    /// The config as pretty JSON text.
    pub fn to_json_string(&self) -> Result<String, SimulationError> {
        serde_json::to_string_pretty(self).map_err(|e| SimulationError::Parse {
            path: None,
            message: format!("cannot write JSON: {e}"),
        })
    }

    /// Checks every value; errors name the field (`scan.width_m`, `effects[1].t0_s` ...).
    /// Besides ranges, counts are capped so that memory and time stay bounded: pixels
    /// ([`MAX_PIXELS`]), effects ([`MAX_EFFECTS`]), lists ([`MAX_LIST`], [`MAX_ADATOMS`])
    /// and lattice sites in the scanned area ([`MAX_NOMINAL_SITES`]). A `[sequence]` table is
    /// checked too ([`SequenceConfig::validate`]), with what it refuses in the base config.
    pub fn validate(&self) -> Result<(), SimulationError> {
        self.scan.validate()?;
        self.surface.validate()?;
        self.check_sites()?;
        if self.effects.len() > MAX_EFFECTS {
            return Err(invalid(
                "effects",
                format!(
                    "{} effects exceed the limit of {MAX_EFFECTS} (each is evaluated at every pixel)",
                    self.effects.len()
                ),
            ));
        }
        non_negative("tip.sigma_m", self.tip.sigma_m)?;
        self.noise.validate()?;
        for (index, effect) in self.effects.iter().enumerate() {
            effect.validate(&format!("effects[{index}]"))?;
        }
        if let Some(sequence) = &self.sequence {
            sequence.validate(self)?;
        }
        Ok(())
    }
}

impl SimulationConfig {
    /// Refuses a lattice whose scanned area holds more than [`MAX_NOMINAL_SITES`] sites.
    fn check_sites(&self) -> Result<(), SimulationError> {
        let Ok(lattice) = self.surface.lattice.build() else {
            return Ok(()); // reported by SurfaceConfig::validate
        };
        let sites = self.scan.width_m * self.scan.height_m / lattice.cell_area()
            * lattice.motif().len() as f64;
        if sites.is_finite() && sites <= MAX_NOMINAL_SITES {
            return Ok(());
        }
        Err(invalid(
            "surface.lattice",
            format!(
                "the {:.3e} x {:.3e} m scan holds {sites:.3e} lattice sites, more than the \
                 limit of {MAX_NOMINAL_SITES:.0e}: a smaller area or a larger lattice constant",
                self.scan.width_m, self.scan.height_m
            ),
        ))
    }
}

/// `list` may hold at most `max` entries.
fn check_len<T>(field: &str, list: &[T], max: usize) -> Result<(), SimulationError> {
    if list.len() <= max {
        Ok(())
    } else {
        Err(invalid(
            field,
            format!("{} entries exceed the limit of {max}", list.len()),
        ))
    }
}

impl ScanConfig {
    /// Checks sizes, scale, speed and directions.
    pub fn validate(&self) -> Result<(), SimulationError> {
        if self.columns == 0 {
            return Err(invalid("scan.columns", "must be at least 1"));
        }
        if self.rows == 0 {
            return Err(invalid("scan.rows", "must be at least 1"));
        }
        let memory_limit = self.memory_limit_bytes()?;
        let max_pixels = (memory_limit / BYTES_PER_PIXEL) as usize;
        match self.columns.checked_mul(self.rows) {
            Some(pixels) if pixels <= max_pixels => {}
            pixels => {
                let gigabytes =
                    pixels.map_or(f64::INFINITY, |p| p as f64) * BYTES_PER_PIXEL as f64 / 1e9;
                return Err(invalid(
                    "scan.columns × scan.rows",
                    format!(
                        "{} x {} px would need about {gigabytes:.1} GB; the limit is \
                         {max_pixels} pixels ({:.1} GB; scan.memory_limit_gib raises it)",
                        self.columns,
                        self.rows,
                        memory_limit as f64 / 1e9
                    ),
                ));
            }
        }
        positive("scan.width_m", self.width_m)?;
        positive("scan.height_m", self.height_m)?;
        positive("scan.fast_speed_m_per_s", self.fast_speed_m_per_s)?;
        non_negative("scan.turnaround_s", self.turnaround_s)?;
        if self.trace_fast.axis() == self.slow.axis() {
            return Err(invalid(
                "scan.slow",
                format!(
                    "must be perpendicular to scan.trace_fast ({:?}), got {:?}",
                    self.trace_fast, self.slow
                ),
            ));
        }
        Ok(())
    }

    /// The memory the simulation may take, bytes: `memory_limit_gib` or 2 GiB.
    fn memory_limit_bytes(&self) -> Result<u64, SimulationError> {
        match self.memory_limit_gib {
            None => Ok(MAX_MEMORY_BYTES),
            Some(gib) if gib.is_finite() && gib > 0.0 && gib <= 256.0 => {
                Ok((gib * (1u64 << 30) as f64) as u64)
            }
            Some(gib) => Err(invalid(
                "scan.memory_limit_gib",
                format!("must lie in (0, 256] GiB, got {gib}"),
            )),
        }
    }

    /// The scan geometry: pitch = size / pixels, pixel period = fast pitch / fast speed.
    pub fn geometry(&self) -> Result<ScanGeometry, SimulationError> {
        self.validate()?;
        let pitch_x = self.width_m / self.columns as f64;
        let pitch_y = self.height_m / self.rows as f64;
        let fast_pitch = match self.trace_fast.axis() {
            dhct_scan::Axis::Horizontal => pitch_x,
            dhct_scan::Axis::Vertical => pitch_y,
        };
        let geometry = ScanGeometry::new(
            self.columns,
            self.rows,
            pitch_x,
            pitch_y,
            fast_pitch / self.fast_speed_m_per_s,
            self.trace_fast,
            self.slow,
        )?
        .with_turnaround(self.turnaround_s)?;
        Ok(geometry)
    }
}

impl SurfaceConfig {
    /// Checks the lattice, shape, defects, domains, steps and strain.
    pub fn validate(&self) -> Result<(), SimulationError> {
        self.lattice.build().map_err(|error| match error {
            SimulationError::Lattice(source) => invalid("surface.lattice", source.to_string()),
            other => other,
        })?;
        finite("surface.angle_rad", self.angle_rad)?;
        finite2("surface.origin_m", self.origin_m)?;
        finite2("surface.plane_slope", self.plane_slope)?;
        self.feature.validate("surface.feature")?;
        self.defects.validate()?;
        check_len("surface.steps", &self.steps, MAX_LIST)?;
        check_len("surface.strain", &self.strain, MAX_LIST)?;
        check_len("surface.modulations", &self.modulations, MAX_LIST)?;
        for (index, modulation) in self.modulations.iter().enumerate() {
            let field = format!("surface.modulations[{index}]");
            finite2(&format!("{field}.index"), modulation.index)?;
            finite(&format!("{field}.amplitude_m"), modulation.amplitude_m)?;
            if modulation.index == [0.0, 0.0] {
                return Err(invalid(
                    format!("{field}.index"),
                    "must not be (0, 0): that is no modulation but a height offset",
                ));
            }
        }
        if let Some(domain) = &self.second_domain {
            domain.region.validate("surface.second_domain.region")?;
            finite("surface.second_domain.angle_rad", domain.angle_rad)?;
            finite2("surface.second_domain.origin_m", domain.origin_m)?;
        }
        for (index, step) in self.steps.iter().enumerate() {
            step.region
                .validate(&format!("surface.steps[{index}].region"))?;
            finite(&format!("surface.steps[{index}].height_m"), step.height_m)?;
        }
        for (index, strain) in self.strain.iter().enumerate() {
            let field = format!("surface.strain[{index}]");
            strain.region.validate(&format!("{field}.region"))?;
            finite2(&format!("{field}.anchor_m"), strain.anchor_m)?;
            for row in strain.strain {
                if !row.iter().all(|e| e.is_finite() && e.abs() < 0.5) {
                    return Err(invalid(
                        format!("{field}.strain"),
                        format!(
                            "components must be finite with |ε| < 0.5, got {:?}",
                            strain.strain
                        ),
                    ));
                }
            }
        }
        Ok(())
    }
}

impl FeatureShape {
    /// Checks heights, widths and angles.
    pub fn validate(&self, field: &str) -> Result<(), SimulationError> {
        finite(&format!("{field}.height_m"), self.height_m)?;
        for sigma in self.sigma_m {
            positive(&format!("{field}.sigma_m"), sigma)?;
        }
        finite(&format!("{field}.angle_rad"), self.angle_rad)?;
        check_len(&format!("{field}.lobes"), &self.lobes, MAX_LIST)?;
        for (index, lobe) in self.lobes.iter().enumerate() {
            let lobe_field = format!("{field}.lobes[{index}]");
            finite2(&format!("{lobe_field}.offset_m"), lobe.offset_m)?;
            finite(
                &format!("{lobe_field}.relative_height"),
                lobe.relative_height,
            )?;
            if let Some(sigma) = lobe.sigma_m {
                for s in sigma {
                    positive(&format!("{lobe_field}.sigma_m"), s)?;
                }
            }
            if let Some(angle) = lobe.angle_rad {
                finite(&format!("{lobe_field}.angle_rad"), angle)?;
            }
        }
        Ok(())
    }
}

impl DefectConfig {
    /// Checks fractions, counts and positions.
    pub fn validate(&self) -> Result<(), SimulationError> {
        fraction("surface.defects.vacancy_fraction", self.vacancy_fraction)?;
        check_len(
            "surface.defects.vacancy_positions_m",
            &self.vacancy_positions_m,
            MAX_ADATOMS,
        )?;
        check_len(
            "surface.defects.adatom_positions_m",
            &self.adatom_positions_m,
            MAX_ADATOMS,
        )?;
        for (index, p) in self.vacancy_positions_m.iter().enumerate() {
            finite2(&format!("surface.defects.vacancy_positions_m[{index}]"), *p)?;
        }
        if self.adatom_count > MAX_ADATOMS {
            return Err(invalid(
                "surface.defects.adatom_count",
                format!("must be at most {MAX_ADATOMS}, got {}", self.adatom_count),
            ));
        }
        for (index, p) in self.adatom_positions_m.iter().enumerate() {
            finite2(&format!("surface.defects.adatom_positions_m[{index}]"), *p)?;
        }
        finite(
            "surface.defects.adatom_relative_height",
            self.adatom_relative_height,
        )
    }
}

impl NoiseConfig {
    /// Checks every amplitude is ≥ 0 and the spike probability in [0, 1].
    pub fn validate(&self) -> Result<(), SimulationError> {
        non_negative("noise.white_sigma_m", self.white_sigma_m)?;
        non_negative("noise.pink_sigma_m", self.pink_sigma_m)?;
        non_negative("noise.line_offset_sigma_m", self.line_offset_sigma_m)?;
        fraction("noise.spike_probability", self.spike_probability)?;
        non_negative("noise.spike_height_m", self.spike_height_m)
    }
}
