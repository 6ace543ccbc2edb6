//! Writing a sequence: per frame its images (`frame_NN.sm4`, `frame_NN_trace.gsf`, …) and
//! one `sequence_truth.json`. Every file is written atomically. The per-pixel displacement
//! fields are not written (for 100 frames they would be gigabytes); the truth gives the
//! displacement at every feature and the session drift over time.

use std::path::{Path, PathBuf};

use dhct_sm4_io::WriteError;

use crate::SimulationError;
use crate::output::write_json;
use crate::sequence::simulation::{SequenceOutput, SequenceSimulation};
use crate::sequence::truth::{FrameTruth, SequenceTruth};

/// File name of the sequence's ground truth.
pub const SEQUENCE_TRUTH_FILE: &str = "sequence_truth.json";

/// The file-name prefix of frame `k` of `frames`: `frame_NN`, `NN` zero-padded to at least
/// two digits (three from 101 frames on).
pub fn frame_prefix(k: usize, frames: usize) -> String {
    let width = frames.saturating_sub(1).to_string().len().max(2);
    format!("frame_{k:0width$}")
}

impl SequenceTruth {
    /// Writes `sequence_truth.json` into `dir` (created if missing).
    pub fn write(&self, dir: &Path) -> Result<PathBuf, SimulationError> {
        std::fs::create_dir_all(dir).map_err(|source| WriteError::Io {
            path: dir.to_path_buf(),
            source,
        })?;
        let path = dir.join(SEQUENCE_TRUTH_FILE);
        write_json(&path, self)?;
        Ok(path)
    }
}

impl SequenceOutput {
    /// Writes every frame's images and `sequence_truth.json` into `dir` (created if
    /// missing); returns the paths written.
    pub fn write(&self, dir: &Path) -> Result<Vec<PathBuf>, SimulationError> {
        let mut written = Vec::new();
        for (k, frame) in self.frames.iter().enumerate() {
            let prefix = frame_prefix(k, self.frames.len());
            written.extend(frame.write_images(dir, Some(&prefix))?);
        }
        written.push(self.truth.write(dir)?);
        Ok(written)
    }
}

impl SequenceSimulation {
    /// Runs the frames one after another, writing each into `dir` (created if missing) as
    /// soon as it is done, so only one frame is in memory at a time; then writes
    /// `sequence_truth.json`. `on_frame` is called after each frame is written, with its
    /// truth and files. Returns the paths written.
    pub fn write(
        &self,
        dir: &Path,
        mut on_frame: impl FnMut(&FrameTruth, &[PathBuf]),
    ) -> Result<Vec<PathBuf>, SimulationError> {
        let frames = self.frame_count();
        let mut written = Vec::new();
        let mut truths = Vec::with_capacity(frames);
        for k in 0..frames {
            let frame = self.run_frame(k)?;
            let paths = frame
                .output
                .write_images(dir, Some(&frame_prefix(k, frames)))?;
            on_frame(&frame.truth, &paths);
            written.extend(paths);
            truths.push(frame.truth);
        }
        written.push(self.truth(truths).write(dir)?);
        Ok(written)
    }
}
