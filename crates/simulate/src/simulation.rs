//! [`Simulation`]: a validated config ready to run, and what a run produces.

use dhct_lattice::Lattice;
use dhct_scan::{ImageChannel, ScanGeometry, ScanPair, ScanPass};
use nalgebra::Vector2;

use crate::config::SimulationConfig;
use crate::effects::{Effect, HeightEffect};
use crate::error::invalid;
use crate::noise::NoiseModel;
use crate::raster::{Displacer, RenderInput, displacement_field, render, visited_area};
use crate::surface::{SampleArea, Surface, Terrace};
use crate::truth::{DisplacementField, EffectRecord, GroundTruth, feature_truths};
use crate::{SimulationError, SimulationOutput};

/// Name of the simulated channel.
pub const CHANNEL_NAME: &str = "Topography";

/// A validated simulation: geometry, lattice, effects and noise built from a config.
#[derive(Debug)]
pub struct Simulation {
    config: SimulationConfig,
    geometry: ScanGeometry,
    lattice: Box<dyn Lattice>,
    effects: Vec<Box<dyn Effect>>,
    height_effects: Vec<Box<dyn HeightEffect>>,
    terrace: Terrace,
    noise: NoiseModel,
}

impl Simulation {
    /// Validates `config` and builds everything that does not depend on the run.
    ///
    /// A config with a `[sequence]` describes many frames and is refused here: run it with
    /// [`crate::SequenceSimulation`].
    pub fn from_config(config: &SimulationConfig) -> Result<Simulation, SimulationError> {
        if config.sequence.is_some() {
            return Err(invalid(
                "sequence",
                "this config describes an image sequence: run it with SequenceSimulation \
                 (`dhct simulate` does)",
            ));
        }
        config.validate()?;
        let geometry = config.scan.geometry()?;
        Self::with_geometry(config, geometry)
    }

    /// Builds `config` (validated, without `[sequence]`) on `geometry`, which is
    /// `config.scan.geometry()` placed in the instrument frame (scan angle, offset, start
    /// time): a frame of a sequence.
    pub(crate) fn with_geometry(
        config: &SimulationConfig,
        geometry: ScanGeometry,
    ) -> Result<Simulation, SimulationError> {
        let lattice = config.surface.lattice.build()?;
        let effects = config
            .effects
            .iter()
            .enumerate()
            .map(|(index, effect)| effect.build(&format!("effects[{index}]")))
            .collect::<Result<Vec<_>, _>>()?;
        let height_effects = config
            .effects
            .iter()
            .filter_map(|effect| effect.height_effect())
            .collect();
        Ok(Simulation {
            terrace: Terrace::new(&config.surface, config.tip.sigma_m),
            noise: NoiseModel::new(&config.noise, config.seed),
            config: config.clone(),
            geometry,
            lattice,
            effects,
            height_effects,
        })
    }

    /// The config.
    pub fn config(&self) -> &SimulationConfig {
        &self.config
    }

    /// The scan geometry of both images.
    pub fn geometry(&self) -> &ScanGeometry {
        &self.geometry
    }

    /// The lattice of the surface.
    pub fn lattice(&self) -> &dyn Lattice {
        self.lattice.as_ref()
    }

    /// The displacement effects, in config order.
    pub fn effects(&self) -> &[Box<dyn Effect>] {
        &self.effects
    }

    /// Total tip displacement `p_sample − p_ctrl` (metres) with the controller at pixel
    /// position `(x, y)` during `pass`.
    pub fn displacement(&self, pass: ScanPass, x: f64, y: f64) -> Vector2<f64> {
        self.displacer().displacement(pass, x, y)
    }

    fn displacer(&self) -> Displacer<'_> {
        Displacer::new(&self.geometry, &self.effects, &self.terrace)
    }

    /// Runs the simulation: trace and retrace images plus the ground truth.
    pub fn run(&self) -> Result<SimulationOutput, SimulationError> {
        let displacer = self.displacer();
        let fields = [
            displacement_field(&displacer, ScanPass::Trace),
            displacement_field(&displacer, ScanPass::Retrace),
        ];
        let visited = visited_area(&self.geometry, &fields);
        let nominal = SampleArea {
            min_m: [0.0, 0.0],
            max_m: [
                (self.geometry.columns() as f64 - 1.0) * self.geometry.pitch_x(),
                (self.geometry.rows() as f64 - 1.0) * self.geometry.pitch_y(),
            ],
        };
        let surface = Surface::build(
            &self.config.surface,
            self.lattice.as_ref(),
            self.config.tip.sigma_m,
            self.config.seed,
            visited,
            nominal,
        )?;
        let correlated = self.noise.correlated(&self.geometry);
        let mut images = Vec::with_capacity(2);
        for (pass, (dx, dy)) in ScanPass::BOTH.into_iter().zip(&fields) {
            let z = render(&RenderInput {
                geometry: &self.geometry,
                pass,
                surface: &surface,
                dx,
                dy,
                height_effects: &self.height_effects,
                noise: &self.noise,
                correlated: &correlated[match pass {
                    ScanPass::Trace => 0,
                    ScanPass::Retrace => 1,
                }],
            });
            images.push(ImageChannel::new(CHANNEL_NAME, "m", z));
        }
        let retrace = images.pop();
        let trace = images
            .pop()
            .unwrap_or_else(|| unreachable!("two images were rendered"));
        let pair = ScanPair::new(self.geometry.clone(), trace, retrace)?;
        let features = feature_truths(&displacer, surface.features());
        let displacement = ScanPass::BOTH
            .into_iter()
            .zip(fields)
            .map(|(pass, (dx, dy))| DisplacementField {
                pass,
                dx: ImageChannel::new(format!("dx {}", pass.name()), "m", dx),
                dy: ImageChannel::new(format!("dy {}", pass.name()), "m", dy),
            })
            .collect();
        let truth = GroundTruth {
            generator: format!("dhct-simulate {}", env!("CARGO_PKG_VERSION")),
            config: self.config.clone(),
            geometry: self.geometry.clone(),
            visited_area: visited,
            effects: self
                .effects
                .iter()
                .map(|e| EffectRecord::of(e.as_ref()))
                .collect(),
            features,
            displacement,
        };
        Ok(SimulationOutput { pair, truth })
    }
}
