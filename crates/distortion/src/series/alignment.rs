//! Placing every frame in the session frame before the joint fit: each frame's start
//! displacement `D(T_k)` predicted from the frame before it (the step the two images show
//! where their correlation has one clear peak, else its own drift carried over the frame
//! and the pause), then moved to the lattice translation that puts its features on the
//! first frame's lattice. A perfect lattice fixes the placement only modulo a lattice
//! vector; the drift's continuity in time picks which one (the prediction must be right to
//! half a cell).

use dhct_lattice::{Lattice, LatticeFitOptions, fit_lattice};
use nalgebra::{Matrix2, Vector2};

use super::frame::{SeriesFeature, SeriesFrame};
use crate::DistortionError;
use crate::registration::MAX_INDEX_DEVIATION;
use crate::thinning::thin;

/// Most features per frame and pass used to place and index a frame (evenly thinned).
pub const MAX_PLACED_PER_PASS: usize = 1500;

/// The frame's features inside its masks, thinned, as `(input, feature index)`.
fn kept(frame: &SeriesFrame) -> Vec<Vec<(usize, usize)>> {
    frame
        .inputs
        .iter()
        .enumerate()
        .map(|(k, input)| {
            let raw: Vec<[f64; 2]> = input.features.iter().map(|f| [f.x_px, f.y_px]).collect();
            let inside = crate::neighbours::inside_mask(&raw, input.mask);
            let all: Vec<(usize, usize)> = (0..raw.len())
                .filter(|&i| inside[i])
                .map(|i| (k, i))
                .collect();
            thin(&all, MAX_PLACED_PER_PASS)
        })
        .collect()
}

/// Instrument-frame positions of `kept` features under the frame's own model, shifted by
/// `shift`.
fn positions(frame: &SeriesFrame, kept: &[(usize, usize)], shift: [f64; 2]) -> Vec<[f64; 2]> {
    kept.iter()
        .map(|&(k, i)| {
            let p = frame.own_position(k, i);
            [p[0] + shift[0], p[1] + shift[1]]
        })
        .collect()
}

/// `Δ` reduced to the shortest equivalent modulo the lattice's translations `basis`
/// (columns: the fitted `a1`, `a2`, metres).
fn reduce(delta: [f64; 2], basis: &Matrix2<f64>) -> [f64; 2] {
    let Some(inverse) = basis.try_inverse() else {
        return delta;
    };
    let f = inverse * Vector2::from(delta);
    let mut best = Vector2::from(delta);
    let base = f.map(|x| x.round());
    for i in -1..=1 {
        for j in -1..=1 {
            let n = base + Vector2::new(f64::from(i), f64::from(j));
            let candidate = basis * (f - n);
            if candidate.norm() < best.norm() {
                best = candidate;
            }
        }
    }
    [best.x, best.y]
}

/// RMS deviation (metres) of each frame's features, placed by its own model, from one
/// lattice fitted to that frame alone (each pass its own offset): what the frame's own
/// model leaves, the yardstick for the series model.
pub fn own_rms(frames: &[SeriesFrame], lattice: &dyn Lattice) -> Vec<f64> {
    frames
        .iter()
        .map(|frame| {
            let sets: Vec<Vec<[f64; 2]>> = kept(frame)
                .iter()
                .map(|pass| positions(frame, pass, [0.0; 2]))
                .collect();
            let refs: Vec<&[[f64; 2]]> = sets.iter().map(|s| s.as_slice()).collect();
            fit_lattice(lattice, &refs, &LatticeFitOptions::default())
                .map_or(f64::NAN, |fit| fit.rms_deviation_m)
        })
        .collect()
}

/// The start displacement `D(T_k)` of every frame (instrument frame, metres; 0 for the
/// first): the previous frame's placement plus the step its images show
/// ([`SeriesFrame::observed_step`], less each frame's own drift up to when it was seen) or, without one, its own drift carried to this
/// frame's start, corrected to the nearest translation that puts this frame's trace on the first frame's
/// lattice.
pub fn frame_shifts(
    frames: &[SeriesFrame],
    lattice: &dyn Lattice,
) -> Result<Vec<[f64; 2]>, DistortionError> {
    let first_kept = kept(&frames[0]);
    let reference = positions(&frames[0], &first_kept[0], [0.0; 2]);
    let [a1, a2] = lattice.primitive_vectors();
    let mut shifts = vec![[0.0; 2]];
    for k in 1..frames.len() {
        let (before, frame) = (&frames[k - 1], &frames[k]);
        // The step seen at time τ into both frames, less what each frame's own drift did
        // by then: the step between their starts.
        let carried = match frame.observed_step {
            Some(seen) => {
                let (here, there) = (
                    frame.own_drift(seen.frame_time_s),
                    before.own_drift(seen.frame_time_s),
                );
                [
                    seen.step_m[0] - here[0] + there[0],
                    seen.step_m[1] - here[1] + there[1],
                ]
            }
            None => before.own_drift(frame.start_s - before.start_s),
        };
        let last = shifts[k - 1];
        let predicted = [last[0] + carried[0], last[1] + carried[1]];
        let this = kept(frame);
        let moved = positions(frame, &this[0], predicted);
        let fit = fit_lattice(
            lattice,
            &[&reference, &moved],
            &LatticeFitOptions::default(),
        )
        .map_err(DistortionError::Indexing)?;
        let transform = fit.transform();
        let basis = Matrix2::from_columns(&[transform * a1, transform * a2]);
        let delta = reduce(fit.set_offsets_m[1], &basis);
        shifts.push([predicted[0] - delta[0], predicted[1] - delta[1]]);
    }
    Ok(shifts)
}

/// Every kept feature of every frame, placed by `place` (frame index, feature) → session
/// position, indexed on one lattice (the first frame's trace seeds it): features within
/// [`MAX_INDEX_DEVIATION`] of their site, with that site.
pub fn index_series(
    frames: &[SeriesFrame],
    lattice: &dyn Lattice,
    place: &dyn Fn(&SeriesFeature) -> [f64; 2],
) -> Result<Vec<SeriesFeature>, DistortionError> {
    let mut features: Vec<Vec<SeriesFeature>> = Vec::new();
    for (index, frame) in frames.iter().enumerate() {
        for pass in kept(frame) {
            let set = pass
                .iter()
                .map(|&(k, i)| SeriesFeature::of(index, frame, k, i))
                .collect();
            features.push(set);
        }
    }
    let placed: Vec<Vec<[f64; 2]>> = features
        .iter()
        .map(|set| set.iter().map(place).collect())
        .collect();
    let sets: Vec<&[[f64; 2]]> = placed.iter().map(|s| s.as_slice()).collect();
    let fit = fit_lattice(lattice, &sets, &LatticeFitOptions::default())
        .map_err(DistortionError::Indexing)?;
    let limit =
        MAX_INDEX_DEVIATION * lattice.nearest_neighbour_distance() * fit.scale[0].max(fit.scale[1]);
    let [a1, a2] = lattice.primitive_vectors();
    let mut indexed = Vec::new();
    for (set, points) in features.iter().zip(&fit.points) {
        for (feature, point) in set.iter().zip(points) {
            if point.deviation_m[0].hypot(point.deviation_m[1]) > limit {
                continue;
            }
            let site =
                a1 * point.n as f64 + a2 * point.m as f64 + lattice.site_position(point.site);
            indexed.push(SeriesFeature {
                site_m: [site.x, site.y],
                ..*feature
            });
        }
    }
    Ok(indexed)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reduction_keeps_the_shortest_equivalent() {
        let basis = Matrix2::new(1.0, 0.5, 0.0, 0.866);
        let r = reduce([2.3, 0.1], &basis);
        assert!(
            (r[0] - 0.3).abs() < 1e-12 && (r[1] - 0.1).abs() < 1e-12,
            "{r:?}"
        );
        let r = reduce([0.45, 0.8], &basis);
        assert!(
            (r[0] + 0.05).abs() < 1e-9 && (r[1] + 0.066).abs() < 1e-9,
            "{r:?}"
        );
    }
}
