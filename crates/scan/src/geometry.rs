use ndarray::Array2;
use serde::{Deserialize, Serialize};

use crate::{Axis, GeometryError, ScanDirection, ScanPass};

/// Where an image lies and when each of its pixels was acquired.
///
/// All lengths are metres and all times seconds. Images are in display orientation
/// (see the crate docs): `columns` along x, `rows` along y.
///
/// # Timing model
///
/// Let `N_f` be the number of pixels along the fast axis, `P` the pixel period and `T_t` the
/// turnaround time spent at each end of a line. One line takes `T_L = N_f·P + T_t`
/// ([`ScanGeometry::line_period`]), one slow step (trace + retrace) `2·T_L`. A point at fast
/// index `i_f` and slow index `i_s` (both counted from where that pass starts, fractional for
/// sub-pixel positions) is acquired at
///
/// * time since its line start: `(i_f + ½)·P` — the middle of the pixel's dwell;
/// * time since frame start: `2·T_L·i_s + (T_L if retrace) + (i_f + ½)·P`.
///
/// The trace runs along [`ScanGeometry::trace_fast`], the retrace the opposite way;
/// both share the slow direction.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "RawScanGeometry", into = "RawScanGeometry")]
pub struct ScanGeometry {
    columns: usize,
    rows: usize,
    pitch_x: f64,
    pitch_y: f64,
    pixel_period: f64,
    turnaround_time: f64,
    trace_fast: ScanDirection,
    slow: ScanDirection,
    scan_angle: f64,
    offset_x: f64,
    offset_y: f64,
    scale_source: ValueSource,
    timing_source: ValueSource,
    frame: usize,
    start_time: Option<f64>,
}

/// Where a geometry value came from.
///
/// Readers of formats that lack a value (timing in ISO 28600 or NPY files, scale in NPY)
/// fill a documented placeholder and mark it `Assumed`, so later stages can warn or ask
/// the user instead of reporting velocities in made-up units.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ValueSource {
    /// Stated by the file header or by the caller.
    #[default]
    Stated,
    /// A placeholder: the file did not say.
    Assumed,
}

/// When a point was acquired (seconds).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct AcquisitionTime {
    /// Seconds since the start of the frame (the first trace line's start).
    pub since_frame_start: f64,
    /// Seconds since the start of the line the point lies on, in that pass's own direction.
    pub since_line_start: f64,
}

impl ScanGeometry {
    /// A geometry with no turnaround, zero scan angle and zero offset.
    ///
    /// * `columns`, `rows`: image size in pixels;
    /// * `pitch_x`, `pitch_y`: pixel pitch along x (columns) and y (rows), metres, positive;
    /// * `pixel_period`: seconds per pixel along the fast axis;
    /// * `trace_fast`: fast direction of the trace; `slow`: slow direction (perpendicular).
    pub fn new(
        columns: usize,
        rows: usize,
        pitch_x: f64,
        pitch_y: f64,
        pixel_period: f64,
        trace_fast: ScanDirection,
        slow: ScanDirection,
    ) -> Result<ScanGeometry, GeometryError> {
        let geometry = ScanGeometry {
            columns,
            rows,
            pitch_x,
            pitch_y,
            pixel_period,
            turnaround_time: 0.0,
            trace_fast,
            slow,
            scan_angle: 0.0,
            offset_x: 0.0,
            offset_y: 0.0,
            scale_source: ValueSource::Stated,
            timing_source: ValueSource::Stated,
            frame: 0,
            start_time: None,
        };
        geometry.validate()?;
        Ok(geometry)
    }

    /// Like [`ScanGeometry::new`], but from the time of one line (one direction, including
    /// any turnaround given later with [`ScanGeometry::with_turnaround`]). The pixel period
    /// becomes `line_time / N_f`.
    pub fn from_line_time(
        columns: usize,
        rows: usize,
        pitch_x: f64,
        pitch_y: f64,
        line_time: f64,
        trace_fast: ScanDirection,
        slow: ScanDirection,
    ) -> Result<ScanGeometry, GeometryError> {
        let n_fast = match trace_fast.axis() {
            Axis::Horizontal => columns,
            Axis::Vertical => rows,
        };
        positive("line time", line_time)?;
        Self::new(
            columns,
            rows,
            pitch_x,
            pitch_y,
            line_time / n_fast.max(1) as f64,
            trace_fast,
            slow,
        )
    }

    /// Sets the dead time spent at each end of every line (seconds, ≥ 0).
    pub fn with_turnaround(mut self, turnaround_time: f64) -> Result<ScanGeometry, GeometryError> {
        non_negative("turnaround time", turnaround_time)?;
        self.turnaround_time = turnaround_time;
        Ok(self)
    }

    /// The same scan with another pixel pitch (metres), e.g. calibrated from the lattice
    /// the image shows; timing, directions and sources are kept.
    pub fn with_pitch(mut self, pitch_x: f64, pitch_y: f64) -> Result<ScanGeometry, GeometryError> {
        positive("x pixel pitch", pitch_x)?;
        positive("y pixel pitch", pitch_y)?;
        self.pitch_x = pitch_x;
        self.pitch_y = pitch_y;
        Ok(self)
    }

    /// The same area sampled at every `factor`-th pixel along both axes (`factor` ≥ 1): a
    /// `factor`-th of the columns and rows (rounded down), `factor` times the pitch and the
    /// pixel period (a line of a length divisible by `factor` takes as long); angle, offset,
    /// turnaround and sources are kept. An error when fewer than `factor` columns or rows are left to bin.
    pub fn binned(&self, factor: usize) -> Result<ScanGeometry, GeometryError> {
        let factor = factor.max(1);
        let f = factor as f64;
        let binned = ScanGeometry {
            columns: self.columns / factor,
            rows: self.rows / factor,
            pitch_x: self.pitch_x * f,
            pitch_y: self.pitch_y * f,
            pixel_period: self.pixel_period * f,
            ..self.clone()
        };
        binned.validate()?;
        Ok(binned)
    }

    /// Sets the scan angle (radians, counter-clockwise, scan frame relative to the instrument).
    pub fn with_scan_angle(mut self, scan_angle: f64) -> Result<ScanGeometry, GeometryError> {
        finite("scan angle", scan_angle)?;
        self.scan_angle = scan_angle;
        Ok(self)
    }

    /// Sets the scan-frame centre in the instrument frame (metres).
    pub fn with_offset(
        mut self,
        offset_x: f64,
        offset_y: f64,
    ) -> Result<ScanGeometry, GeometryError> {
        finite("x offset", offset_x)?;
        finite("y offset", offset_y)?;
        self.offset_x = offset_x;
        self.offset_y = offset_y;
        Ok(self)
    }

    /// Marks where the pixel pitch came from (default [`ValueSource::Stated`]).
    pub fn with_scale_source(mut self, source: ValueSource) -> ScanGeometry {
        self.scale_source = source;
        self
    }

    /// Marks where the pixel period, turnaround and directions came from
    /// (default [`ValueSource::Stated`]).
    pub fn with_timing_source(mut self, source: ValueSource) -> ScanGeometry {
        self.timing_source = source;
        self
    }

    /// Sets which frame of a multi-frame file this is (see [`ScanGeometry::frame`]).
    pub fn with_frame(mut self, frame: usize) -> ScanGeometry {
        self.frame = frame;
        self
    }

    /// Which recording of its file this geometry belongs to: 0 for a file of one frame;
    /// 0, 1, … in file order for a file that holds several frames recorded one after
    /// another (SPECS `.mul` and `.flm`). Channels of one frame share its timing; channels
    /// of different frames were recorded at different times, so one frame's distortion
    /// model does not apply to another.
    pub fn frame(&self) -> usize {
        self.frame
    }

    /// Sets when the frame started (see [`ScanGeometry::start_time`]); a non-finite value
    /// clears it.
    pub fn with_start_time(mut self, seconds: Option<f64>) -> ScanGeometry {
        self.start_time = seconds.filter(|s| s.is_finite());
        self
    }

    /// When the frame's first line started, seconds since 1970-01-01 on the file's own
    /// clock ([`crate::clock`]), as the file recorded it; `None` when it did not. Frames of
    /// one session are ordered and spaced in time by it.
    pub fn start_time(&self) -> Option<f64> {
        self.start_time
    }

    /// The instrument-frame position (metres, display axes: x right, y down, of the
    /// unrotated scanner) of controller position `p` (metres, this image's display frame):
    /// the image centre goes to [`ScanGeometry::offset`], and the scan frame is turned by
    /// [`ScanGeometry::scan_angle`] counter-clockwise as seen on screen:
    /// `O + R(φ)·(p − c)`, `R(φ) = [[cos φ, sin φ], [−sin φ, cos φ]]` in display axes.
    pub fn to_instrument(&self, p: [f64; 2]) -> [f64; 2] {
        let c = self.centre();
        let (s, co) = self.scan_angle.sin_cos();
        let (x, y) = (p[0] - c[0], p[1] - c[1]);
        [
            self.offset_x + co * x + s * y,
            self.offset_y - s * x + co * y,
        ]
    }

    /// The inverse of [`ScanGeometry::to_instrument`]: controller position (metres, this
    /// image's display frame) of instrument-frame position `q`.
    pub fn from_instrument(&self, q: [f64; 2]) -> [f64; 2] {
        let c = self.centre();
        let (s, co) = self.scan_angle.sin_cos();
        let (x, y) = (q[0] - self.offset_x, q[1] - self.offset_y);
        [c[0] + co * x - s * y, c[1] + s * x + co * y]
    }

    /// Vector `v` (metres, instrument display axes) in this image's display frame.
    pub fn vector_from_instrument(&self, v: [f64; 2]) -> [f64; 2] {
        let (s, co) = self.scan_angle.sin_cos();
        [co * v[0] - s * v[1], s * v[0] + co * v[1]]
    }

    /// Vector `v` (metres, this image's display frame) in instrument display axes.
    pub fn vector_to_instrument(&self, v: [f64; 2]) -> [f64; 2] {
        let (s, co) = self.scan_angle.sin_cos();
        [co * v[0] + s * v[1], -s * v[0] + co * v[1]]
    }

    /// The image centre, controller metres: `((N_x − 1)·pitch_x/2, (N_y − 1)·pitch_y/2)`.
    pub fn centre(&self) -> [f64; 2] {
        [
            (self.columns as f64 - 1.0) * self.pitch_x / 2.0,
            (self.rows as f64 - 1.0) * self.pitch_y / 2.0,
        ]
    }

    /// Where the pixel pitch came from.
    pub fn scale_source(&self) -> ValueSource {
        self.scale_source
    }

    /// Where the pixel period, turnaround and scan directions came from.
    pub fn timing_source(&self) -> ValueSource {
        self.timing_source
    }

    fn validate(&self) -> Result<(), GeometryError> {
        if self.columns == 0 || self.rows == 0 {
            return Err(GeometryError::EmptyImage {
                columns: self.columns,
                rows: self.rows,
            });
        }
        positive("x pixel pitch", self.pitch_x)?;
        positive("y pixel pitch", self.pitch_y)?;
        positive("pixel period", self.pixel_period)?;
        non_negative("turnaround time", self.turnaround_time)?;
        finite("scan angle", self.scan_angle)?;
        finite("x offset", self.offset_x)?;
        finite("y offset", self.offset_y)?;
        if self.trace_fast.axis() == self.slow.axis() {
            return Err(GeometryError::NotPerpendicular {
                fast: self.trace_fast,
                slow: self.slow,
            });
        }
        Ok(())
    }

    /// Image width in pixels (number of columns).
    pub fn columns(&self) -> usize {
        self.columns
    }
    /// Image height in pixels (number of rows).
    pub fn rows(&self) -> usize {
        self.rows
    }
    /// Pixel pitch along x (columns), metres.
    pub fn pitch_x(&self) -> f64 {
        self.pitch_x
    }
    /// Pixel pitch along y (rows), metres.
    pub fn pitch_y(&self) -> f64 {
        self.pitch_y
    }
    /// Image width in metres (`columns · pitch_x`).
    pub fn width(&self) -> f64 {
        self.columns as f64 * self.pitch_x
    }
    /// Image height in metres (`rows · pitch_y`).
    pub fn height(&self) -> f64 {
        self.rows as f64 * self.pitch_y
    }
    /// Seconds per pixel along the fast axis.
    pub fn pixel_period(&self) -> f64 {
        self.pixel_period
    }
    /// Dead time at each end of a line, seconds.
    pub fn turnaround_time(&self) -> f64 {
        self.turnaround_time
    }
    /// Fast direction of the trace.
    pub fn trace_fast(&self) -> ScanDirection {
        self.trace_fast
    }
    /// Slow direction (shared by trace and retrace).
    pub fn slow_direction(&self) -> ScanDirection {
        self.slow
    }
    /// Scan angle, radians counter-clockwise.
    pub fn scan_angle(&self) -> f64 {
        self.scan_angle
    }
    /// Scan-frame centre in the instrument frame, metres.
    pub fn offset(&self) -> (f64, f64) {
        (self.offset_x, self.offset_y)
    }

    /// Fast direction of the given pass (the retrace runs opposite to the trace).
    pub fn fast_direction(&self, pass: ScanPass) -> ScanDirection {
        match pass {
            ScanPass::Trace => self.trace_fast,
            ScanPass::Retrace => self.trace_fast.reversed(),
        }
    }

    /// The axis the fast scan runs along.
    pub fn fast_axis(&self) -> Axis {
        self.trace_fast.axis()
    }

    /// Pixels per line (along the fast axis).
    pub fn fast_len(&self) -> usize {
        self.len_along(self.fast_axis())
    }

    /// Number of lines (pixels along the slow axis).
    pub fn slow_len(&self) -> usize {
        self.len_along(self.slow.axis())
    }

    /// Pixel pitch along the fast axis, metres.
    pub fn fast_pitch(&self) -> f64 {
        self.pitch_along(self.fast_axis())
    }

    /// Pixel pitch along the slow axis, metres.
    pub fn slow_pitch(&self) -> f64 {
        self.pitch_along(self.slow.axis())
    }

    /// Duration of one line including one turnaround, seconds (`N_f·P + T_t`).
    pub fn line_period(&self) -> f64 {
        self.fast_len() as f64 * self.pixel_period + self.turnaround_time
    }

    /// Duration of the scanning part of one line (`N_f·P`), seconds.
    pub fn line_scan_time(&self) -> f64 {
        self.fast_len() as f64 * self.pixel_period
    }

    /// Duration of the whole frame (all trace and retrace lines), seconds.
    pub fn frame_duration(&self) -> f64 {
        2.0 * self.line_period() * self.slow_len() as f64
    }

    /// Tip speed along the fast axis, m/s.
    pub fn fast_speed(&self) -> f64 {
        self.fast_pitch() / self.pixel_period
    }

    /// Mean tip speed along the slow axis (one pixel per line pair), m/s.
    pub fn slow_speed(&self) -> f64 {
        self.slow_pitch() / (2.0 * self.line_period())
    }

    fn len_along(&self, axis: Axis) -> usize {
        match axis {
            Axis::Horizontal => self.columns,
            Axis::Vertical => self.rows,
        }
    }

    fn pitch_along(&self, axis: Axis) -> f64 {
        match axis {
            Axis::Horizontal => self.pitch_x,
            Axis::Vertical => self.pitch_y,
        }
    }

    /// Index counted from where `direction` starts, for a display coordinate along its axis.
    fn index_from_start(&self, direction: ScanDirection, coordinate: f64) -> f64 {
        let last = (self.len_along(direction.axis()) - 1) as f64;
        if direction.is_increasing() {
            coordinate
        } else {
            last - coordinate
        }
    }

    /// Fast index of display position `(x, y)` in pixels, counted from the start of the
    /// line in this pass's own direction (0 = first pixel acquired in the line).
    pub fn fast_index(&self, pass: ScanPass, x: f64, y: f64) -> f64 {
        let direction = self.fast_direction(pass);
        let coordinate = match direction.axis() {
            Axis::Horizontal => x,
            Axis::Vertical => y,
        };
        self.index_from_start(direction, coordinate)
    }

    /// Slow index (line number, fractional between lines) of display position `(x, y)`.
    pub fn slow_index(&self, x: f64, y: f64) -> f64 {
        let coordinate = match self.slow.axis() {
            Axis::Horizontal => x,
            Axis::Vertical => y,
        };
        self.index_from_start(self.slow, coordinate)
    }

    /// The display position `(x, y)` (pixels) of fast index `fast` on line `slow` of `pass`;
    /// the inverse of [`ScanGeometry::fast_index`] and [`ScanGeometry::slow_index`].
    pub fn position_of(&self, pass: ScanPass, fast: f64, slow: f64) -> (f64, f64) {
        let along_fast = self.index_from_start(self.fast_direction(pass), fast);
        let along_slow = self.index_from_start(self.slow, slow);
        match self.fast_axis() {
            Axis::Horizontal => (along_fast, along_slow),
            Axis::Vertical => (along_slow, along_fast),
        }
    }

    /// When the tip was at display position `(x, y)` (pixels, sub-pixel allowed) during `pass`.
    pub fn acquisition_time(&self, pass: ScanPass, x: f64, y: f64) -> AcquisitionTime {
        let since_line_start = (self.fast_index(pass, x, y) + 0.5) * self.pixel_period;
        let line_period = self.line_period();
        let retrace_delay = match pass {
            ScanPass::Trace => 0.0,
            ScanPass::Retrace => line_period,
        };
        AcquisitionTime {
            since_frame_start: 2.0 * line_period * self.slow_index(x, y)
                + retrace_delay
                + since_line_start,
            since_line_start,
        }
    }

    /// Acquisition times of every pixel of `pass`, as two `rows x columns` arrays:
    /// (seconds since frame start, seconds since line start).
    pub fn acquisition_time_maps(&self, pass: ScanPass) -> (Array2<f64>, Array2<f64>) {
        let shape = (self.rows, self.columns);
        let mut frame = Array2::zeros(shape);
        let mut line = Array2::zeros(shape);
        for ((row, col), value) in frame.indexed_iter_mut() {
            let t = self.acquisition_time(pass, col as f64, row as f64);
            *value = t.since_frame_start;
            line[[row, col]] = t.since_line_start;
        }
        (frame, line)
    }
}

fn positive(what: &'static str, value: f64) -> Result<(), GeometryError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(GeometryError::NotPositive { what, value })
    }
}

fn non_negative(what: &'static str, value: f64) -> Result<(), GeometryError> {
    if value.is_finite() && value >= 0.0 {
        Ok(())
    } else {
        Err(GeometryError::Negative { what, value })
    }
}

fn finite(what: &'static str, value: f64) -> Result<(), GeometryError> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(GeometryError::NotFinite { what, value })
    }
}

/// The serialised form of [`ScanGeometry`], with units in the field names; validated on load.
#[derive(Serialize, Deserialize)]
struct RawScanGeometry {
    columns: usize,
    rows: usize,
    pitch_x_m: f64,
    pitch_y_m: f64,
    pixel_period_s: f64,
    #[serde(default)]
    turnaround_time_s: f64,
    trace_fast: ScanDirection,
    slow: ScanDirection,
    #[serde(default)]
    scan_angle_rad: f64,
    #[serde(default)]
    offset_x_m: f64,
    #[serde(default)]
    offset_y_m: f64,
    #[serde(default)]
    scale_source: ValueSource,
    #[serde(default)]
    timing_source: ValueSource,
    #[serde(default, skip_serializing_if = "is_zero")]
    frame: usize,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    start_time_s: Option<f64>,
}

fn is_zero(frame: &usize) -> bool {
    *frame == 0
}

impl TryFrom<RawScanGeometry> for ScanGeometry {
    type Error = GeometryError;
    fn try_from(raw: RawScanGeometry) -> Result<Self, Self::Error> {
        ScanGeometry::new(
            raw.columns,
            raw.rows,
            raw.pitch_x_m,
            raw.pitch_y_m,
            raw.pixel_period_s,
            raw.trace_fast,
            raw.slow,
        )?
        .with_turnaround(raw.turnaround_time_s)?
        .with_scan_angle(raw.scan_angle_rad)?
        .with_offset(raw.offset_x_m, raw.offset_y_m)
        .map(|g| {
            g.with_scale_source(raw.scale_source)
                .with_timing_source(raw.timing_source)
                .with_frame(raw.frame)
                .with_start_time(raw.start_time_s)
        })
    }
}

impl From<ScanGeometry> for RawScanGeometry {
    fn from(g: ScanGeometry) -> Self {
        RawScanGeometry {
            columns: g.columns,
            rows: g.rows,
            pitch_x_m: g.pitch_x,
            pitch_y_m: g.pitch_y,
            pixel_period_s: g.pixel_period,
            turnaround_time_s: g.turnaround_time,
            trace_fast: g.trace_fast,
            slow: g.slow,
            scan_angle_rad: g.scan_angle,
            offset_x_m: g.offset_x,
            offset_y_m: g.offset_y,
            scale_source: g.scale_source,
            timing_source: g.timing_source,
            frame: g.frame,
            start_time_s: g.start_time,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Binned, a scan covers the same area (the odd column left out) with fewer, larger
    /// pixels, its lines (20 px, divisible) taking as long; everything else is kept, and too
    /// few pixels to bin are an error.
    #[test]
    fn a_binned_scan_keeps_its_area_line_time_and_placement() {
        let g = ScanGeometry::new(
            11,
            20,
            1.0,
            2.0,
            1e-3,
            ScanDirection::Down,
            ScanDirection::Left,
        )
        .unwrap()
        .with_turnaround(0.25)
        .unwrap()
        .with_scan_angle(0.3)
        .unwrap()
        .with_offset(100.0, 200.0)
        .unwrap();
        let b = g.binned(2).unwrap();
        assert_eq!((b.columns(), b.rows()), (5, 10));
        assert_eq!((b.pitch_x(), b.pitch_y()), (2.0, 4.0));
        assert_eq!(b.line_scan_time(), g.line_scan_time());
        assert_eq!(b.turnaround_time(), g.turnaround_time());
        assert_eq!((b.scan_angle(), b.offset()), (g.scan_angle(), g.offset()));
        assert_eq!(
            (b.trace_fast(), b.slow_direction()),
            (g.trace_fast(), g.slow_direction())
        );
        assert_eq!(g.binned(1).unwrap(), g);
        assert!(g.binned(12).is_err());
    }

    #[test]
    fn instrument_frame_round_trips_and_turns_counter_clockwise_on_screen() {
        let g = ScanGeometry::new(
            11,
            21,
            1.0,
            1.0,
            1e-3,
            ScanDirection::Right,
            ScanDirection::Down,
        )
        .unwrap()
        .with_scan_angle(std::f64::consts::FRAC_PI_2)
        .unwrap()
        .with_offset(100.0, 200.0)
        .unwrap();
        assert_eq!(g.centre(), [5.0, 10.0]);
        assert_eq!(g.to_instrument([5.0, 10.0]), [100.0, 200.0]);
        // The scan's +x (right on its own screen) is up on the instrument's screen (−y).
        let q = g.to_instrument([6.0, 10.0]);
        assert!(
            (q[0] - 100.0).abs() < 1e-12 && (q[1] - 199.0).abs() < 1e-12,
            "{q:?}"
        );
        let p = g.from_instrument([103.0, 190.0]);
        let back = g.to_instrument(p);
        assert!((back[0] - 103.0).abs() < 1e-12 && (back[1] - 190.0).abs() < 1e-12);
        let v = g.vector_from_instrument(g.vector_to_instrument([0.3, -0.7]));
        assert!((v[0] - 0.3).abs() < 1e-12 && (v[1] + 0.7).abs() < 1e-12);
        let json = serde_json::to_string(&g.clone().with_start_time(Some(1.5e9))).unwrap();
        let back: ScanGeometry = serde_json::from_str(&json).unwrap();
        assert_eq!(back.start_time(), Some(1.5e9));
        assert!(!serde_json::to_string(&g).unwrap().contains("start_time"));
    }
}
