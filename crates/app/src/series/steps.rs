//! Frames placed against the frame before from their images ([`correlation`]): each
//! consecutive pair's trace images read again, pairs side by side, and the step they show
//! handed to the series fit, with a note for each frame so placed.

use anyhow::Result;
use dhct_distortion::series::ObservedStep;
use rayon::prelude::*;

use super::{Timed, correlation};
use crate::analysis::FrameModel;
use crate::setup::CorrectConfig;

/// A frame's step from the frame before, seen in the two images.
#[derive(Debug, Clone, Copy)]
pub struct SeenStep {
    /// The step, for the series fit.
    pub step: ObservedStep,
    /// The image shift it comes from, pixels.
    shift_px: [f64; 2],
    /// The correlation's next best peak over the best.
    next_peak_ratio: f64,
    /// The best peak over what noise alone reaches (standard deviations).
    significance: f64,
}

/// Per frame in time order, the step its trace image shows against the frame before's
/// ([`correlation::frame_offset`]) where the two share size, pitch and scan angle and one
/// correlation peak stands out; `None` elsewhere (and for the first frame). The images are
/// read again, two per pair.
pub fn observed(
    corrected: &[FrameModel],
    timed: &[Timed],
    config: &CorrectConfig,
) -> Result<Vec<Option<SeenStep>>> {
    let trace = |t: &Timed| -> Result<ndarray::Array2<f64>> {
        let pair = t.source.read(config)?;
        Ok(pair
            .images()
            .next()
            .map(|(_, image)| image.z.clone())
            .unwrap_or_default())
    };
    // Consecutive pairs side by side, each reading its two frames (reading is cheap, the
    // correlation is not): memory holds two frames' traces per worker thread.
    let pairs: Vec<Option<SeenStep>> = (1..timed.len())
        .into_par_iter()
        .map(|k| -> Result<Option<SeenStep>> {
            let (before, current) = (trace(&timed[k - 1])?, trace(&timed[k])?);
            Ok(pair_step(
                corrected,
                (&timed[k - 1], &timed[k]),
                &before,
                &current,
            ))
        })
        .collect::<Result<_>>()?;
    Ok(std::iter::once(None).chain(pairs).collect())
}

/// The step the traces `before` and `current` of the consecutive frames `timed` show, where
/// the frames share size, pitch and scan angle and one correlation peak stands out.
fn pair_step(
    corrected: &[FrameModel],
    timed: (&Timed, &Timed),
    before: &ndarray::Array2<f64>,
    current: &ndarray::Array2<f64>,
) -> Option<SeenStep> {
    let (g0, g1) = (
        &corrected[timed.0.input].geometry,
        &corrected[timed.1.input].geometry,
    );
    let comparable = (g0.columns(), g0.rows()) == (g1.columns(), g1.rows())
        && g0.pitch_x() == g1.pitch_x()
        && g0.pitch_y() == g1.pitch_y()
        && g0.scan_angle() == g1.scan_angle();
    // Blurred over one nearest-neighbour distance: the lattice gone (its strongest
    // reflection down by e^-26; half the distance left e^-6.6, as strong as the noise and
    // coherent over the frame), defects kept as blobs.
    let nn = corrected[timed.1.input]
        .lattice
        .nearest_neighbour_distance();
    let blur_px = nn / g1.pitch_x().max(g1.pitch_y());
    comparable
        .then(|| correlation::frame_offset(before, current, blur_px))
        .flatten()
        .map(|offset| SeenStep {
            step: ObservedStep {
                step_m: correlation::displacement_step(g0, g1, offset.shift_px),
                frame_time_s: correlation::shared_time_s(g1, offset.shift_px),
            },
            shift_px: offset.shift_px,
            next_peak_ratio: offset.next_peak_ratio,
            significance: offset.significance,
        })
}

/// Which frames were placed from their images, for the notes.
pub fn notes(steps: &[Option<SeenStep>]) -> Vec<String> {
    steps
        .iter()
        .enumerate()
        .filter_map(|(k, step)| {
            let s = step.as_ref()?;
            Some(format!(
                "frame {k} placed from its image's correlation with frame {}: shifted ({:.2}, \
                 {:.2}) px, D changed by ({}, {}) {:.0} s into both (the next correlation peak {:.0} % of the \
                 best, the best {:.1}σ above noise)",
                k - 1,
                s.shift_px[0],
                s.shift_px[1],
                dhct_scan::quantity::length(s.step.step_m[0]),
                dhct_scan::quantity::length(s.step.step_m[1]),
                s.step.frame_time_s,
                100.0 * s.next_peak_ratio,
                s.significance
            ))
        })
        .collect()
}
