//! One frame of a series as the series fit sees it, and its features on the session clock.

use dhct_scan::{ScanGeometry, ScanPass};

use crate::{DistortionModel, PassInput};

/// One frame of a series: its scan, its features (one [`PassInput`] per pass), a model
/// fitted to this frame alone (the start of the series fit, and how the frame is placed
/// before it), and when it started.
#[derive(Debug, Clone)]
pub struct SeriesFrame<'a> {
    /// The frame's scan (size, pitch, timing, directions, scan angle, offset).
    pub geometry: &'a ScanGeometry,
    /// Its features, one entry per pass.
    pub inputs: Vec<PassInput<'a>>,
    /// The model fitted to this frame alone.
    pub model: &'a DistortionModel,
    /// Session time of the frame's start, seconds since the first frame's start.
    pub start_s: f64,
    /// Where this frame lies against the frame before, when the two images show it (their
    /// correlation); `None`: the frame before's own drift is carried over instead.
    pub observed_step: Option<ObservedStep>,
}

/// How far the sample moved under the tip from the frame before to this one, seen in the
/// two images: the same sample point at controller positions `step_m` apart.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObservedStep {
    /// `D` of this frame minus `D` of the frame before, each at [`ObservedStep::frame_time_s`]
    /// into its frame (instrument frame, metres).
    pub step_m: [f64; 2],
    /// When within both frames the step was seen (the middle of what they share), seconds
    /// since each frame's start.
    pub frame_time_s: f64,
}

impl SeriesFrame<'_> {
    /// Instrument-frame position (metres) of feature `i` of pass input `k` under the
    /// frame's own model, before the frame is placed in the session (its start at 0).
    pub fn own_position(&self, k: usize, i: usize) -> [f64; 2] {
        let f = &self.inputs[k].features[i];
        let p = self.model.to_sample(self.geometry, f.pass, f.x_px, f.y_px);
        self.geometry.to_instrument(p)
    }

    /// The frame's own drift/creep displacement (instrument frame, metres) `t` seconds
    /// after its start, extrapolated beyond its end at its end velocity.
    pub fn own_drift(&self, t: f64) -> [f64; 2] {
        let end = self.geometry.frame_duration();
        let d = if t <= end {
            self.model.drift.displacement(t)
        } else {
            let (d, v) = (
                self.model.drift.displacement(end),
                self.model.drift.velocity(end),
            );
            [d[0] + v[0] * (t - end), d[1] + v[1] * (t - end)]
        };
        self.geometry.vector_to_instrument(d)
    }
}

/// One indexed feature of a series: where the controller put it (instrument frame), when
/// (session clock), how its hysteresis lag acts, and which lattice site it is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SeriesFeature {
    /// Index of its frame in the series.
    pub frame: usize,
    /// Index of its pass input in the frame.
    pub input: usize,
    /// Index of the feature in that input.
    pub feature_index: usize,
    /// Trace or retrace.
    pub pass: ScanPass,
    /// `to_instrument(p_c)`, metres: the controller position in the instrument frame.
    pub controller_m: [f64; 2],
    /// Its frame's centre in the instrument frame (the header offset), metres.
    pub centre_m: [f64; 2],
    /// Session time of acquisition, seconds.
    pub time_s: f64,
    /// Seconds since its line start (its pass's direction).
    pub line_time_s: f64,
    /// Instrument-frame displacement per second of hysteresis lag, m/s (`−v_f·ê_trace`
    /// turned into the instrument frame).
    pub lag_direction_m_per_s: [f64; 2],
    /// Its ideal site in the lattice's own frame, metres.
    pub site_m: [f64; 2],
}

impl SeriesFeature {
    /// The feature of `input`'s feature `i` in `frame` (index `frame_index`), site unset.
    pub fn of(frame_index: usize, frame: &SeriesFrame, input: usize, i: usize) -> SeriesFeature {
        let f = &frame.inputs[input].features[i];
        SeriesFeature {
            frame: frame_index,
            input,
            feature_index: i,
            ..SeriesFeature::at_pixel(frame.geometry, frame.start_s, f.pass, f.x_px, f.y_px)
        }
    }

    /// The point at pixel position `(x, y)` of `pass` of a frame of `geometry` that
    /// started `start_s` into the session (frame 0, indices 0, site unset).
    pub fn at_pixel(
        geometry: &ScanGeometry,
        start_s: f64,
        pass: ScanPass,
        x_px: f64,
        y_px: f64,
    ) -> SeriesFeature {
        let g = geometry;
        let time = g.acquisition_time(pass, x_px, y_px);
        let (trace_fast, _) = crate::model::scan_basis(g, ScanPass::Trace);
        let v = g.fast_speed();
        SeriesFeature {
            frame: 0,
            input: 0,
            feature_index: 0,
            pass,
            controller_m: g.to_instrument([x_px * g.pitch_x(), y_px * g.pitch_y()]),
            centre_m: [g.offset().0, g.offset().1],
            time_s: start_s + time.since_frame_start,
            line_time_s: time.since_line_start,
            lag_direction_m_per_s: g.vector_to_instrument([-v * trace_fast[0], -v * trace_fast[1]]),
            site_m: [0.0; 2],
        }
    }
}
