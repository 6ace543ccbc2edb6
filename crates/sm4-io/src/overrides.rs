use dhct_scan::{GeometryError, ScanDirection, ScanFile, ScanGeometry, ScanPair, ValueSource};
use serde::{Deserialize, Serialize};

use crate::placeholders::{
    ASSUMED_SCALE_KEY, ASSUMED_TIMING_KEY, PLAUSIBLE_LINE_TIME_S, PLAUSIBLE_PITCH_M,
    PLAUSIBLE_PIXEL_PERIOD_S, PLAUSIBLE_TURNAROUND_S, plausible,
};
use crate::{OverrideRangeError, ReadError};

/// Geometry values given by the user (command line, config or API) that replace or supply
/// what a file says. Unset fields keep the file's values.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GeometryOverrides {
    /// Pixel pitch along x (columns), metres.
    pub pitch_x: Option<f64>,
    /// Pixel pitch along y (rows), metres.
    pub pitch_y: Option<f64>,
    /// Seconds per pixel along the fast axis. Exclusive with `line_time`.
    pub pixel_period: Option<f64>,
    /// Seconds per line (one direction, scanning part only). Exclusive with `pixel_period`.
    pub line_time: Option<f64>,
    /// Dead time at each end of a line, seconds.
    pub turnaround_time: Option<f64>,
    /// Fast direction of the trace.
    pub trace_fast: Option<ScanDirection>,
    /// Slow scan direction.
    pub slow: Option<ScanDirection>,
}

impl GeometryOverrides {
    /// True when nothing is overridden.
    pub fn is_empty(&self) -> bool {
        *self == GeometryOverrides::default()
    }

    /// Checks every given value against its plausible range (the `PLAUSIBLE_*` constants of
    /// this crate: pitch 1 fm–1 mm, pixel period 1 ns–100 s, line time 1 µs–10^5 s,
    /// turnaround 0–100 s); NaN, infinities and e.g. `--pixel-period 1e30` are refused.
    pub fn validate(&self) -> Result<(), OverrideRangeError> {
        let checks = [
            ("pitch_x", self.pitch_x, &PLAUSIBLE_PITCH_M, "m"),
            ("pitch_y", self.pitch_y, &PLAUSIBLE_PITCH_M, "m"),
            (
                "pixel_period",
                self.pixel_period,
                &PLAUSIBLE_PIXEL_PERIOD_S,
                "s",
            ),
            ("line_time", self.line_time, &PLAUSIBLE_LINE_TIME_S, "s"),
            (
                "turnaround_time",
                self.turnaround_time,
                &PLAUSIBLE_TURNAROUND_S,
                "s",
            ),
        ];
        for (key, value, range, unit) in checks {
            if let Some(value) = value
                && !plausible(value, range)
            {
                return Err(OverrideRangeError {
                    key,
                    value,
                    unit,
                    low: *range.start(),
                    high: *range.end(),
                });
            }
        }
        Ok(())
    }

    /// `geometry` with the overridden values replaced. Overridden scale or timing become
    /// [`ValueSource::Stated`]. Values outside their plausible range (see
    /// [`GeometryOverrides::validate`]) are refused as [`GeometryError::Conflicting`].
    pub fn apply(&self, geometry: &ScanGeometry) -> Result<ScanGeometry, GeometryError> {
        if self.validate().is_err() {
            return Err(GeometryError::Conflicting(
                "a geometry override lies outside its plausible range (see GeometryOverrides::validate)",
            ));
        }
        if self.pixel_period.is_some() && self.line_time.is_some() {
            return Err(GeometryError::Conflicting(
                "pixel period and line time were both given; give one",
            ));
        }
        let pitch_x = self.pitch_x.unwrap_or(geometry.pitch_x());
        let pitch_y = self.pitch_y.unwrap_or(geometry.pitch_y());
        let trace_fast = self.trace_fast.unwrap_or(geometry.trace_fast());
        let slow = self.slow.unwrap_or(geometry.slow_direction());
        let columns = geometry.columns();
        let rows = geometry.rows();
        let mut out = match self.line_time {
            Some(line_time) => ScanGeometry::from_line_time(
                columns, rows, pitch_x, pitch_y, line_time, trace_fast, slow,
            )?,
            None => ScanGeometry::new(
                columns,
                rows,
                pitch_x,
                pitch_y,
                self.pixel_period.unwrap_or(geometry.pixel_period()),
                trace_fast,
                slow,
            )?,
        }
        .with_turnaround(self.turnaround_time.unwrap_or(geometry.turnaround_time()))?
        .with_scan_angle(geometry.scan_angle())?;
        let (offset_x, offset_y) = geometry.offset();
        out = out.with_offset(offset_x, offset_y)?;
        let scale_given = self.pitch_x.is_some() && self.pitch_y.is_some();
        let timing_given = self.pixel_period.is_some() || self.line_time.is_some();
        Ok(out
            .with_scale_source(if scale_given {
                ValueSource::Stated
            } else {
                geometry.scale_source()
            })
            .with_timing_source(if timing_given {
                ValueSource::Stated
            } else {
                geometry.timing_source()
            }))
    }

    /// Applies [`GeometryOverrides::apply`] to every channel of `file`; the notes of what the
    /// reader assumed are dropped for the values now given.
    pub fn apply_to_file(&self, file: ScanFile) -> Result<ScanFile, ReadError> {
        if self.is_empty() {
            return Ok(file);
        }
        if let Err(error) = self.validate() {
            return Err(ReadError::BadOverride(error));
        }
        let format = file.format;
        let mut metadata = file.metadata;
        if self.pitch_x.is_some() && self.pitch_y.is_some() {
            metadata.remove(ASSUMED_SCALE_KEY);
        }
        if self.pixel_period.is_some() || self.line_time.is_some() {
            metadata.remove(ASSUMED_TIMING_KEY);
        }
        let pairs = file
            .pairs
            .into_iter()
            .map(|pair| {
                let (geometry, trace, retrace) = pair.into_parts();
                let geometry = self.apply(&geometry)?;
                ScanPair::from_parts(geometry, trace, retrace)
            })
            .collect::<Result<Vec<_>, _>>()
            .map_err(|source| ReadError::geometry(format, source))?;
        Ok(ScanFile {
            format,
            pairs,
            metadata,
        })
    }
}
