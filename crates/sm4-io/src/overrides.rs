use dhct_scan::{GeometryError, ScanDirection, ScanFile, ScanGeometry, ScanPair, ValueSource};
use serde::{Deserialize, Serialize};

use crate::ReadError;

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

    /// `geometry` with the overridden values replaced. Overridden scale or timing become
    /// [`ValueSource::Stated`].
    pub fn apply(&self, geometry: &ScanGeometry) -> Result<ScanGeometry, GeometryError> {
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

    /// Applies [`GeometryOverrides::apply`] to every channel of `file`.
    pub fn apply_to_file(&self, file: ScanFile) -> Result<ScanFile, ReadError> {
        if self.is_empty() {
            return Ok(file);
        }
        let format = file.format;
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
        Ok(ScanFile { pairs, ..file })
    }
}
