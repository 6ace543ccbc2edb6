//! How a feature's localisation error reaches its residual.
//!
//! A feature's acquisition time is assigned from its measured position, so an error `δ` in
//! that position also moves the time at which the model evaluates the distortion. The
//! residual `r = p − site + D(t(p), τ(p), p)` then carries `G·δ`, with the timing gain
//! `G = I + ∂D/∂p` (2 × 2, controller frame): along the slow axis `1 + v·Δt_line/pitch`
//! for a displacement moving at `v` (a 14 pm/s drift on 16 pm pixels scanned 0.24 s apart
//! gives 1.22), along the fast axis the local hysteresis stretch. Measured on effect-free
//! rendered graphite (`rendered-dev`, seed 62014): the base model's y residual was 1.22 ×
//! the centres' error about the truth, enough to turn a floor that was right into a gap
//! of 1.2.
//!
//! The fits' 1σ describe `δ`, so the diagnosis compares `W·r` with them, `W = G⁻¹` of
//! the model the base fit found first (held fixed afterwards, so that no later fit can
//! shrink its residuals by steepening its own distortion).

use dhct_scan::ScanGeometry;

use crate::model::data::{NO_WHITENING, Observation};
use crate::model::global::{GlobalModel, context};

/// Position step of the central difference, pixels.
const STEP_PX: f64 = 0.05;

/// A gain whose determinant lies outside this range (a displacement that folds the scan
/// over, or one that jumps within the step, e.g. at a tip change) is not inverted: that
/// feature keeps `W = I`.
const DETERMINANT_RANGE: (f64, f64) = (0.25, 4.0);

/// `o` seen `step_px` pixels further along controller axis `axis`, with the acquisition
/// times its new position gets (changed by the geometry's timing, whatever their origin).
fn moved(geometry: &ScanGeometry, o: &Observation, axis: usize, step_px: f64) -> Observation {
    let pitch = [geometry.pitch_x(), geometry.pitch_y()];
    let px = [o.controller_m[0] / pitch[0], o.controller_m[1] / pitch[1]];
    let mut to = px;
    to[axis] += step_px;
    let before = geometry.acquisition_time(o.pass, px[0], px[1]);
    let after = geometry.acquisition_time(o.pass, to[0], to[1]);
    let mut out = *o;
    out.controller_m[axis] += step_px * pitch[axis];
    out.time_s += after.since_frame_start - before.since_frame_start;
    out.line_time_s += after.since_line_start - before.since_line_start;
    out
}

/// The model's total displacement at `o` (metres, not whitened).
fn displacement(model: &GlobalModel, geometry: &ScanGeometry, o: &Observation) -> [f64; 2] {
    let at = context(geometry, o);
    model.terms.iter().fold([0.0; 2], |acc, term| {
        let d = term.effect.displacement(&at);
        [acc[0] + d.x, acc[1] + d.y]
    })
}

/// `G⁻¹` at `o` for `model`, or the identity where `G` is not safely invertible.
fn whitening(model: &GlobalModel, geometry: &ScanGeometry, o: &Observation) -> [[f64; 2]; 2] {
    let pitch = [geometry.pitch_x(), geometry.pitch_y()];
    let mut g = NO_WHITENING;
    for axis in 0..2 {
        let plus = displacement(model, geometry, &moved(geometry, o, axis, STEP_PX));
        let minus = displacement(model, geometry, &moved(geometry, o, axis, -STEP_PX));
        for (row, gain) in g.iter_mut().enumerate() {
            gain[axis] += (plus[row] - minus[row]) / (2.0 * STEP_PX * pitch[axis]);
        }
    }
    let det = g[0][0] * g[1][1] - g[0][1] * g[1][0];
    if !(det.is_finite() && (DETERMINANT_RANGE.0..=DETERMINANT_RANGE.1).contains(&det)) {
        return NO_WHITENING;
    }
    [
        [g[1][1] / det, -g[0][1] / det],
        [-g[1][0] / det, g[0][0] / det],
    ]
}

/// `observations` with the whitening of `model` at each.
pub(crate) fn whitened(
    model: &GlobalModel,
    geometry: &ScanGeometry,
    observations: &[Observation],
) -> Vec<Observation> {
    observations
        .iter()
        .map(|o| Observation {
            whitening: whitening(model, geometry, o),
            ..*o
        })
        .collect()
}
