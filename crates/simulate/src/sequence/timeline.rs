//! When each frame of a sequence starts, in session time.

/// Frame start times of a sequence, seconds of session time `T` (since frame 0's start).
///
/// `T_0 = 0`; `T_k = T_{k−1} + ⌈frame_duration + pause⌉`: each frame starts the pause
/// after the previous one ends, rounded up to a whole second (files store start times to
/// the second). Since `T_{k−1}` is whole, this is `⌈T_{k−1} + frame_duration + pause⌉`.
#[derive(Debug, Clone, PartialEq)]
pub struct Timeline {
    starts: Vec<f64>,
    frame_duration: f64,
}

impl Timeline {
    /// The timeline of `frames` frames of `frame_duration` seconds each, `pause` seconds
    /// apart before rounding.
    pub fn new(frames: usize, frame_duration: f64, pause: f64) -> Timeline {
        let step = (frame_duration + pause).ceil();
        Timeline {
            starts: (0..frames).map(|k| k as f64 * step).collect(),
            frame_duration,
        }
    }

    /// `T_k`, seconds (whole); `None` past the last frame.
    pub fn start_s(&self, k: usize) -> Option<f64> {
        self.starts.get(k).copied()
    }

    /// Every frame's start, seconds.
    pub fn starts(&self) -> &[f64] {
        &self.starts
    }

    /// Number of frames.
    pub fn frames(&self) -> usize {
        self.starts.len()
    }

    /// Duration of one frame, seconds ([`dhct_scan::ScanGeometry::frame_duration`]).
    pub fn frame_duration_s(&self) -> f64 {
        self.frame_duration
    }

    /// When the last frame ends, seconds.
    pub fn end_s(&self) -> f64 {
        self.starts.last().copied().unwrap_or(0.0) + self.frame_duration
    }
}
