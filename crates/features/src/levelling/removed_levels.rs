//! The line levels the lattice levelling subtracted before the fits, looked up at a
//! feature: what was taken out at its centre (`Feature::removed_level`) and whether its fit
//! disc holds a step the levelling cut a line at (such features are dropped as
//! [`Rejection::OnStep`]).

use dhct_scan::Axis;

use crate::levelling::line_steps::LineLevel;
use crate::{Feature, LineCorrection, LineLevelling, RejectedCandidate, Rejection};

/// The line levels the lattice levelling subtracted (none when the lines were left as
/// recorded).
pub(crate) struct RemovedLevels {
    /// Along which axis the lines run.
    pub fast_axis: Axis,
    /// Each line's level (empty: none subtracted).
    pub levels: Vec<LineLevel>,
    /// The first levels' [`crate::levelling::lattice_levels::LineLevels::offsets_over_noise`], on
    /// which the lines were levelled or not (NaN: not measured).
    pub offsets_over_noise: f64,
}

impl RemovedLevels {
    /// Nothing subtracted, on the evidence `offsets_over_noise` (NaN: not measured).
    pub fn none(fast_axis: Axis, offsets_over_noise: f64) -> Self {
        RemovedLevels {
            fast_axis,
            levels: Vec::new(),
            offsets_over_noise,
        }
    }

    /// The lattice levelling as reported: whether the lines were levelled, the evidence
    /// and the `threshold` it was compared with, and how many lines were cut at steps.
    pub fn levelling(&self, threshold: f64) -> LineLevelling {
        LineLevelling {
            requested: LineCorrection::Lattice,
            levelled: !self.levels.is_empty(),
            offsets_over_noise: self
                .offsets_over_noise
                .is_finite()
                .then_some(self.offsets_over_noise),
            evidence_threshold: Some(threshold),
            lines_cut_at_steps: self.levels.iter().filter(|l| l.steps() > 0).count(),
        }
    }

    /// `(line, along)` px of the point `(x, y)` px.
    fn line_and_along(&self, x: f64, y: f64) -> (f64, f64) {
        match self.fast_axis {
            Axis::Horizontal => (y, x),
            Axis::Vertical => (x, y),
        }
    }

    /// Whether a line crossing the disc of `radius` px around `(x, y)` px steps inside it.
    fn has_step_within(&self, x: f64, y: f64, radius: f64) -> bool {
        let (line, along) = self.line_and_along(x, y);
        let first = (line - radius).ceil().max(0.0) as usize;
        let last = (line + radius).floor().max(0.0) as usize;
        (first..=last.min(self.levels.len().saturating_sub(1))).any(|l| {
            let half = (radius * radius - (l as f64 - line).powi(2))
                .max(0.0)
                .sqrt();
            self.levels[l]
                .step_positions()
                .any(|p| (p - 0.5 - along).abs() <= half + 0.5)
        })
    }

    /// The level subtracted at `(x, y)` px (signed z units), on the nearest line.
    pub fn at(&self, x: f64, y: f64) -> f64 {
        let (line, along) = self.line_and_along(x, y);
        let line = line.round().max(0.0) as usize;
        self.levels
            .get(line)
            .or(self.levels.last())
            .map_or(0.0, |level| level.at(along))
    }
}

/// Drops the features whose fit disc (radius `radius_px`) holds a height step that the
/// lattice levelling found within a line ([`crate::levelling::line_steps`]).
pub(crate) fn drop_on_steps(
    features: &mut Vec<Feature>,
    removed: &RemovedLevels,
    radius_px: f64,
    rejected: &mut Vec<RejectedCandidate>,
) {
    if removed.levels.iter().all(|l| l.steps() == 0) {
        return;
    }
    features.retain(|f| {
        let keep = !removed.has_step_within(f.x_px, f.y_px, radius_px);
        if !keep {
            rejected.push(RejectedCandidate {
                x_px: f.x_px,
                y_px: f.y_px,
                reason: Rejection::OnStep,
            });
        }
        keep
    });
}
