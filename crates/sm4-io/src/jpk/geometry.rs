//! The scan geometry of a JPK file: pixel size, timing, directions, angle and offset from
//! the scan settings in page 0.

use std::collections::BTreeMap;

use dhct_scan::{ScanDirection, ScanGeometry, ValueSource};

use crate::ReadError;
use crate::placeholders::{
    ASSUMED_PITCH, ASSUMED_PIXEL_PERIOD, ASSUMED_SCALE_KEY, ASSUMED_TIMING_KEY,
    PLAUSIBLE_LINE_TIME_S, PLAUSIBLE_PITCH_M, PLAUSIBLE_PIXEL_PERIOD_S, PLAUSIBLE_SCAN_ANGLE_RAD,
    PLAUSIBLE_TURNAROUND_S, note, plausible,
};

use super::directory::*;

/// The file-wide scan settings from page 0, turned into a geometry per image size.
pub(super) struct GeometryFactory {
    /// Grid lengths along u (x) and v (y), metres, signed as stated.
    pub(super) lengths: Option<(f64, f64)>,
    pub(super) origin: Option<(f64, f64)>,
    pub(super) theta: Option<f64>,
    /// Line pair rate (Hz) and duty cycle.
    pub(super) frequency: Option<f64>,
    pub(super) duty: Option<f64>,
    /// `Some(true)`: bottomUp, `Some(false)`: topDown.
    pub(super) bottom_up: Option<bool>,
    pub(super) motion: Option<String>,
}

impl GeometryFactory {
    pub(super) fn new(tiff: &Tiff, global: &Page, metadata: &mut BTreeMap<String, String>) -> Self {
        let real = |t| tiff.real(global, t);
        let lengths = match (real(tag::GRID_U_LENGTH), real(tag::GRID_V_LENGTH)) {
            (Some(u), Some(v)) => Some((u, v)),
            _ => None,
        };
        let origin = match (real(tag::GRID_X0), real(tag::GRID_Y0)) {
            (Some(x), Some(y)) => Some((x, y)),
            _ => None,
        };
        let theta = real(tag::GRID_THETA);
        if let Some(theta) = theta
            && !plausible(theta, &PLAUSIBLE_SCAN_ANGLE_RAD)
        {
            metadata.insert(
                "ignored scan angle".to_string(),
                format!("Grid_Theta = {theta} rad is beyond a full turn"),
            );
        }
        let motion = tiff.text(global, tag::MOTION);
        let bottom_up = match motion.as_deref() {
            Some("bottomUp") => Some(true),
            Some("topDown") => Some(false),
            _ => None,
        };
        GeometryFactory {
            lengths,
            origin,
            // `+ 0.0` turns a stated −0 into 0.
            theta: theta
                .filter(|t| plausible(*t, &PLAUSIBLE_SCAN_ANGLE_RAD))
                .map(|t| t + 0.0),
            frequency: real(tag::SCANRATE_FREQUENCY),
            duty: real(tag::SCANRATE_DUTYCYCLE),
            bottom_up,
            motion,
        }
    }

    pub(super) fn build(
        &self,
        columns: usize,
        rows: usize,
        reflect: bool,
        metadata: &mut BTreeMap<String, String>,
    ) -> Result<ScanGeometry, ReadError> {
        let geometry_error = |source| ReadError::geometry(FORMAT, source);
        let (pitch_x, pitch_y, scale_source) = self.pitch(columns, rows, metadata);
        let (line_time, turnaround, timing) = self.timing(columns, metadata);
        let (slow, direction) = self.slow_direction(reflect, metadata);
        let timing_source = if timing == ValueSource::Stated && direction == ValueSource::Stated {
            ValueSource::Stated
        } else {
            ValueSource::Assumed
        };
        let mut geometry = ScanGeometry::from_line_time(
            columns,
            rows,
            pitch_x,
            pitch_y,
            line_time,
            ScanDirection::Right,
            slow,
        )
        .and_then(|g| g.with_turnaround(turnaround))
        .map_err(geometry_error)?
        .with_scale_source(scale_source)
        .with_timing_source(timing_source);
        if let Some(theta) = self.theta {
            geometry = geometry.with_scan_angle(theta).map_err(geometry_error)?;
        }
        if let Some((x, y)) = self.centre(reflect) {
            geometry = geometry.with_offset(x, y).map_err(geometry_error)?;
        }
        Ok(geometry)
    }

    /// Pixel pitch along x and y (metres) from the grid lengths, or the placeholder.
    fn pitch(
        &self,
        columns: usize,
        rows: usize,
        metadata: &mut BTreeMap<String, String>,
    ) -> (f64, f64, ValueSource) {
        let pitch = self
            .lengths
            .map(|(u, v)| (u.abs() / columns as f64, v.abs() / rows as f64));
        match pitch {
            Some((x, y))
                if plausible(x, &PLAUSIBLE_PITCH_M) && plausible(y, &PLAUSIBLE_PITCH_M) =>
            {
                (x, y, ValueSource::Stated)
            }
            _ => {
                note(
                    metadata,
                    ASSUMED_SCALE_KEY,
                    match self.lengths {
                        Some((u, v)) => format!(
                            "Grid_uLength {u:e} m / Grid_vLength {v:e} m give an implausible \
                             pixel size for {columns} x {rows} px"
                        ),
                        None => "no Grid_uLength / Grid_vLength (0x8042/0x8043)".to_string(),
                    },
                );
                (ASSUMED_PITCH, ASSUMED_PITCH, ValueSource::Assumed)
            }
        }
    }

    /// Line time per pass and turnaround (seconds) from the line rate and duty cycle, or
    /// the placeholder; the source says which.
    fn timing(
        &self,
        columns: usize,
        metadata: &mut BTreeMap<String, String>,
    ) -> (f64, f64, ValueSource) {
        let mut timing_source = ValueSource::Stated;
        // The line pair period and the part of it spent scanning.
        let pair_period = self
            .frequency
            .filter(|f| *f > 0.0)
            .map(|f| 1.0 / f)
            .filter(|p| plausible(p / 2.0, &PLAUSIBLE_LINE_TIME_S));
        let (line_time, turnaround) = match pair_period {
            Some(period) => {
                let duty = self.duty.filter(|d| *d > 0.0 && *d <= 1.0);
                let duty = duty.unwrap_or_else(|| {
                    note(
                        metadata,
                        ASSUMED_TIMING_KEY,
                        "no usable Scanrate_Dutycycle (0x804A): no turnaround assumed",
                    );
                    1.0
                });
                (duty * period / 2.0, (1.0 - duty) * period / 2.0)
            }
            None => {
                timing_source = ValueSource::Assumed;
                note(
                    metadata,
                    ASSUMED_TIMING_KEY,
                    match self.frequency {
                        Some(f) => format!("Scanrate_Frequency (0x8049) of {f} Hz is implausible"),
                        None => "no Scanrate_Frequency (0x8049), as in QI (force map) images"
                            .to_string(),
                    },
                );
                (ASSUMED_PIXEL_PERIOD * columns as f64, 0.0)
            }
        };
        let line_time_usable = plausible(line_time / columns as f64, &PLAUSIBLE_PIXEL_PERIOD_S)
            && plausible(turnaround, &PLAUSIBLE_TURNAROUND_S);
        let (line_time, turnaround) = if line_time_usable {
            (line_time, turnaround)
        } else {
            timing_source = ValueSource::Assumed;
            note(
                metadata,
                ASSUMED_TIMING_KEY,
                format!(
                    "a line time of {line_time:e} s gives an implausible pixel period for \
                     {columns} px"
                ),
            );
            (ASSUMED_PIXEL_PERIOD * columns as f64, 0.0)
        };
        (line_time, turnaround, timing_source)
    }

    /// The slow direction in display orientation, assumed when `Motion` is unknown or the
    /// grid is reflected.
    fn slow_direction(
        &self,
        reflect: bool,
        metadata: &mut BTreeMap<String, String>,
    ) -> (ScanDirection, ValueSource) {
        let mut timing_source = ValueSource::Stated;
        // Which end of the stored rows was acquired first, and where it is displayed.
        let first_stored_first = match self.bottom_up {
            Some(bottom_up) => bottom_up,
            None => {
                timing_source = ValueSource::Assumed;
                note(
                    metadata,
                    ASSUMED_TIMING_KEY,
                    match &self.motion {
                        Some(m) => format!(
                            "unknown Motion \"{m}\" (0x804B): lines taken as acquired in \
                             stored order"
                        ),
                        None => "no Motion (0x804B): lines taken as acquired in stored order"
                            .to_string(),
                    },
                );
                true
            }
        };
        if reflect {
            timing_source = ValueSource::Assumed;
            note(
                metadata,
                ASSUMED_TIMING_KEY,
                "Grid_Reflect is set: the slow direction follows Motion on the unreversed rows \
                 (unverified, no such file was available)",
            );
        }
        // Unreflected, the first stored row is the bottom of the displayed image.
        let slow = if first_stored_first != reflect {
            ScanDirection::Up
        } else {
            ScanDirection::Down
        };
        (slow, timing_source)
    }

    /// The grid's centre (metres): the origin corner plus half the grid, rotated by θ;
    /// `None` when the grid is reflected or its origin or lengths are missing.
    fn centre(&self, reflect: bool) -> Option<(f64, f64)> {
        let ((x0, y0), (u, v)) = (self.origin?, self.lengths?);
        if reflect {
            return None;
        }
        let (sin, cos) = self.theta.unwrap_or(0.0).sin_cos();
        let centre = (
            x0 + 0.5 * (u * cos - v * sin),
            y0 + 0.5 * (u * sin + v * cos),
        );
        (centre.0.is_finite() && centre.1.is_finite()).then_some(centre)
    }
}
