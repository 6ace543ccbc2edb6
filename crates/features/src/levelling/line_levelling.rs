//! How the scan lines were levelled before the fits, and on what evidence: what a run
//! reports so that the levelling is read as a choice the data made, not a silent default.

use std::fmt;

use serde::{Deserialize, Serialize};

use crate::LineCorrection;

/// How one image's scan lines were levelled before its features were fitted.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct LineLevelling {
    /// The line correction asked for.
    pub requested: LineCorrection,
    /// Whether a level was subtracted from each line before the fits.
    pub levelled: bool,
    /// For `lattice`: how far the lines' levels (the image minus its lattice model, per
    /// line) vary from line to line, as their variance over the variance pixel noise alone
    /// gives; about 1 without line offsets. `None` when it was not measured or cannot be
    /// told.
    pub offsets_over_noise: Option<f64>,
    /// For `lattice`: the value of `offsets_over_noise` from which the lines are levelled
    /// (below it levelling would only add noise shared along each line).
    pub evidence_threshold: Option<f64>,
    /// Lines cut at height steps they cross (each piece levelled on its own).
    pub lines_cut_at_steps: usize,
}

impl LineLevelling {
    /// A correction applied as asked, without evidence (every mode but `lattice`).
    pub(crate) fn as_requested(requested: LineCorrection) -> Self {
        LineLevelling {
            requested,
            levelled: requested != LineCorrection::None,
            ..LineLevelling::default()
        }
    }
}

impl fmt::Display for LineLevelling {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let requested = self.requested.name();
        let evidence = match (self.offsets_over_noise, self.evidence_threshold) {
            (Some(o), Some(t)) => format!(
                "; line levels vary {o:.1} × what pixel noise gives, {} the threshold {t}",
                if o >= t { "at or above" } else { "below" }
            ),
            _ => String::new(),
        };
        let steps = match self.lines_cut_at_steps {
            0 => String::new(),
            n => format!("; {n} lines cut at height steps"),
        };
        let what = if self.levelled {
            "lines levelled"
        } else {
            "lines left as recorded"
        };
        write!(f, "{what} (`{requested}`{evidence}{steps})")
    }
}
