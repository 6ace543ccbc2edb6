//! [`SequenceSimulation`]: a validated sequence config, run frame by frame.

use dhct_scan::ScanGeometry;

use crate::config::SimulationConfig;
use crate::error::invalid;
use crate::sequence::config::SequenceConfig;
use crate::sequence::frame::{FramePlacement, frame_config};
use crate::sequence::motion::SessionMotion;
use crate::sequence::timeline::Timeline;
use crate::sequence::truth::{FrameTruth, SequenceTruth, trajectory};
use crate::{Simulation, SimulationError, SimulationOutput};

/// A validated image sequence: the base config, the frame timeline and the session drift.
#[derive(Debug, Clone)]
pub struct SequenceSimulation {
    config: SimulationConfig,
    base: SimulationConfig,
    sequence: SequenceConfig,
    geometry: ScanGeometry,
    timeline: Timeline,
    motion: SessionMotion,
}

/// One simulated frame of a sequence.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameOutput {
    /// The frame's images and its own ground truth (in its simulated sample frame).
    pub output: SimulationOutput,
    /// The frame's part of the sequence truth.
    pub truth: FrameTruth,
}

/// Every frame of a sequence and its truth, from [`SequenceSimulation::run`].
#[derive(Debug, Clone, PartialEq)]
pub struct SequenceOutput {
    /// Frame `k`'s images and its own ground truth, in order.
    pub frames: Vec<SimulationOutput>,
    /// The truth of the whole sequence.
    pub truth: SequenceTruth,
}

impl SequenceSimulation {
    /// Validates `config` (which must have a `[sequence]` table) and plans the session.
    pub fn from_config(config: &SimulationConfig) -> Result<SequenceSimulation, SimulationError> {
        let Some(sequence) = config.sequence.clone() else {
            return Err(invalid(
                "sequence",
                "missing: this config describes one frame; run it with Simulation",
            ));
        };
        config.validate()?;
        let mut base = config.clone();
        base.sequence = None;
        let geometry = base.scan.geometry()?;
        let timeline = Timeline::new(sequence.frames, geometry.frame_duration(), sequence.pause_s);
        let motion = SessionMotion::new(&sequence, &timeline);
        Ok(SequenceSimulation {
            config: config.clone(),
            base,
            sequence,
            geometry,
            timeline,
            motion,
        })
    }

    /// The config (with its `[sequence]`).
    pub fn config(&self) -> &SimulationConfig {
        &self.config
    }

    /// The `[sequence]` table.
    pub fn sequence(&self) -> &SequenceConfig {
        &self.sequence
    }

    /// Number of frames.
    pub fn frame_count(&self) -> usize {
        self.timeline.frames()
    }

    /// When each frame starts.
    pub fn timeline(&self) -> &Timeline {
        &self.timeline
    }

    /// The session drift `D(T)`.
    pub fn motion(&self) -> &SessionMotion {
        &self.motion
    }

    /// `D(T)` at session time `t_s` (seconds), metres, instrument frame.
    pub fn session_displacement(&self, t_s: f64) -> [f64; 2] {
        self.motion.displacement(t_s)
    }

    /// Where and when frame `k` is taken.
    pub fn placement(&self, k: usize) -> Result<FramePlacement, SimulationError> {
        FramePlacement::of(k, &self.sequence, &self.timeline, &self.motion).ok_or_else(|| {
            invalid(
                "frame",
                format!("frame {k} does not exist ({} frames)", self.frame_count()),
            )
        })
    }

    /// Frame `k` as an ordinary simulation (config and geometry of that frame).
    pub fn frame_simulation(&self, k: usize) -> Result<Simulation, SimulationError> {
        let placement = self.placement(k)?;
        let geometry = placement.geometry(&self.geometry)?;
        let config = frame_config(
            &self.base,
            &self.motion,
            &placement,
            &geometry,
            self.sequence.scanner_gain,
        );
        config.validate()?;
        Simulation::with_geometry(&config, geometry)
    }

    /// Runs frame `k`: its images and truth. Frames are independent, so a long sequence
    /// can be run one frame at a time.
    pub fn run_frame(&self, k: usize) -> Result<FrameOutput, SimulationError> {
        let placement = self.placement(k)?;
        let output = self.frame_simulation(k)?.run()?;
        let truth = FrameTruth::new(placement, &output);
        Ok(FrameOutput { output, truth })
    }

    /// Runs every frame and keeps them all in memory (see
    /// [`SequenceSimulation::write`] for a run that keeps one frame at a time).
    pub fn run(&self) -> Result<SequenceOutput, SimulationError> {
        let mut frames = Vec::with_capacity(self.frame_count());
        let mut truths = Vec::with_capacity(self.frame_count());
        for k in 0..self.frame_count() {
            let frame = self.run_frame(k)?;
            frames.push(frame.output);
            truths.push(frame.truth);
        }
        Ok(SequenceOutput {
            frames,
            truth: self.truth(truths),
        })
    }

    /// The truth of the sequence made of the frames' truths.
    pub fn truth(&self, frames: Vec<FrameTruth>) -> SequenceTruth {
        SequenceTruth {
            generator: format!("dhct-simulate {}", env!("CARGO_PKG_VERSION")),
            config: self.config.clone(),
            frame_duration_s: self.timeline.frame_duration_s(),
            creeps: self.motion.creeps().to_vec(),
            frames,
            trajectory: trajectory(&self.motion, self.timeline.end_s()),
        }
    }
}
