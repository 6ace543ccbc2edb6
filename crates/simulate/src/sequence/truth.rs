//! The ground truth of a sequence: per frame its placement, effects and every imaged
//! feature (its common instrument-frame position and where each pass imaged it), and the
//! session drift sampled over the whole session.

use dhct_scan::{ScanGeometry, ScanPass};
use serde::{Deserialize, Serialize};

use crate::SimulationOutput;
use crate::config::SimulationConfig;
use crate::sequence::frame::FramePlacement;
use crate::sequence::motion::{CreepEvent, SessionMotion};
use crate::surface::FeatureKind;
use crate::truth::{EffectRecord, FeatureAcquisition};

/// Most samples of [`SequenceTruth::trajectory`]; longer sessions are sampled more coarsely.
pub const MAX_TRAJECTORY_SAMPLES: usize = 100_000;

/// Everything known about a simulated sequence (`sequence_truth.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SequenceTruth {
    /// `"dhct-simulate <version>"`.
    pub generator: String,
    /// The config (with its `[sequence]`).
    pub config: SimulationConfig,
    /// Duration of every frame, seconds.
    pub frame_duration_s: f64,
    /// Every creep of the session (instrument frame), in time order.
    pub creeps: Vec<CreepEvent>,
    /// One entry per frame, in order.
    pub frames: Vec<FrameTruth>,
    /// `D(T)` sampled over the session (every second, or coarser beyond
    /// [`MAX_TRAJECTORY_SAMPLES`]), metres, instrument frame.
    pub trajectory: Vec<TrajectorySample>,
}

/// One frame of the sequence.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrameTruth {
    /// Where and when it was taken.
    #[serde(flatten)]
    pub placement: FramePlacement,
    /// Its scan geometry (with scan angle, offset and start time).
    pub geometry: ScanGeometry,
    /// Its effects (the base effects, then the session drift and creeps as it sees them).
    pub effects: Vec<EffectRecord>,
    /// Every feature either pass imaged (on the image, solve converged).
    pub features: Vec<SequenceFeature>,
}

/// One true feature as imaged in one frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SequenceFeature {
    /// Lattice site (domain, cell `n, m`, motif site; the same in every frame) or adatom.
    pub kind: FeatureKind,
    /// True position, metres, instrument (session) frame: the same in every frame.
    pub instrument_position_m: [f64; 2],
    /// True position in this frame's simulated sample frame, metres
    /// (`from_instrument(instrument_position − D(T_k))`).
    pub frame_position_m: [f64; 2],
    /// Peak height before tip broadening, metres.
    pub amplitude_m: f64,
    /// Where and when the trace imaged it (controller position in this frame's pixels).
    pub trace: FeatureAcquisition,
    /// Where and when the retrace imaged it.
    pub retrace: FeatureAcquisition,
}

/// The session drift at one time.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TrajectorySample {
    /// `T`, seconds of session time.
    pub t_s: f64,
    /// `D_x(T)`, metres, instrument frame.
    pub x_m: f64,
    /// `D_y(T)`, metres, instrument frame.
    pub y_m: f64,
}

impl FrameTruth {
    /// The truth of one simulated frame placed at `placement`.
    pub fn new(placement: FramePlacement, output: &SimulationOutput) -> FrameTruth {
        let truth = &output.truth;
        let geometry = &truth.geometry;
        let features = truth
            .features
            .iter()
            .filter(|f| {
                ScanPass::BOTH.into_iter().any(|pass| {
                    let a = f.acquisition(pass);
                    a.in_image && a.converged
                })
            })
            .map(|f| SequenceFeature {
                kind: f.kind,
                instrument_position_m: placement.to_session(geometry, f.sample_position_m),
                frame_position_m: f.sample_position_m,
                amplitude_m: f.amplitude_m,
                trace: f.trace,
                retrace: f.retrace,
            })
            .collect();
        FrameTruth {
            placement,
            geometry: geometry.clone(),
            effects: truth.effects.clone(),
            features,
        }
    }

    /// The features imaged (on the image, converged) by `pass`.
    pub fn imaged_features(&self, pass: ScanPass) -> impl Iterator<Item = &SequenceFeature> {
        self.features.iter().filter(move |f| {
            let a = f.acquisition(pass);
            a.in_image && a.converged
        })
    }
}

impl SequenceFeature {
    /// Where and when `pass` imaged this feature.
    pub fn acquisition(&self, pass: ScanPass) -> &FeatureAcquisition {
        match pass {
            ScanPass::Trace => &self.trace,
            ScanPass::Retrace => &self.retrace,
        }
    }
}

/// `D(T)` from 0 to `end_s` every second (or every ⌈end/MAX⌉ seconds), the end included.
pub(crate) fn trajectory(motion: &SessionMotion, end_s: f64) -> Vec<TrajectorySample> {
    let step = (end_s / MAX_TRAJECTORY_SAMPLES as f64).ceil().max(1.0);
    let whole = (end_s / step).floor() as usize;
    let mut times: Vec<f64> = (0..=whole).map(|i| i as f64 * step).collect();
    if times.last().is_some_and(|t| *t < end_s) {
        times.push(end_s);
    }
    times
        .into_iter()
        .map(|t_s| {
            let [x_m, y_m] = motion.displacement(t_s);
            TrajectorySample { t_s, x_m, y_m }
        })
        .collect()
}
