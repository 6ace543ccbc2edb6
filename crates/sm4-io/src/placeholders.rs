//! Placeholder geometry values for what a file does not say, and the plausible ranges a
//! stated value must lie in.
//!
//! Readers that cannot find a value (or find one that is not finite, not positive or far
//! outside these ranges) use a placeholder, mark it [`dhct_scan::ValueSource::Assumed`] and
//! record why in the file's metadata under [`ASSUMED_SCALE_KEY`] or [`ASSUMED_TIMING_KEY`],
//! so later stages can warn (see [`assumption_warnings`]) or the user can supply the value
//! (e.g. with [`crate::GeometryOverrides`]) instead of getting numbers in made-up units.

use std::ops::RangeInclusive;

use dhct_scan::{ScanFile, ScanGeometry, ValueSource};

/// Placeholder pixel pitch, metres along x and y: 1 Å per pixel (NPY and TIFF carry no
/// scale; SM4/SXM/GSF/ISO files with a zero, missing or non-length scale).
pub const ASSUMED_PITCH: f64 = 1e-10;

/// Placeholder pixel period, seconds per pixel along the fast axis: 1 ms (ISO 28600, NPY,
/// TIFF and plain GSF carry no timing; SM4/SXM files with a zero or missing period).
pub const ASSUMED_PIXEL_PERIOD: f64 = 1e-3;

/// Pixel pitches dhct accepts, metres: 1 fm to 1 mm.
pub const PLAUSIBLE_PITCH_M: RangeInclusive<f64> = 1e-15..=1e-3;

/// Pixel periods dhct accepts, seconds per pixel: 1 ns to 100 s.
pub const PLAUSIBLE_PIXEL_PERIOD_S: RangeInclusive<f64> = 1e-9..=100.0;

/// Line times (one direction) dhct accepts, seconds: 1 µs to 10^5 s.
pub const PLAUSIBLE_LINE_TIME_S: RangeInclusive<f64> = 1e-6..=1e5;

/// Turnaround times dhct accepts, seconds: 0 to 100 s.
pub const PLAUSIBLE_TURNAROUND_S: RangeInclusive<f64> = 0.0..=100.0;

/// Scan angles dhct accepts, radians: one full turn either way.
pub const PLAUSIBLE_SCAN_ANGLE_RAD: RangeInclusive<f64> =
    -std::f64::consts::TAU..=std::f64::consts::TAU;

/// Metadata key listing why the pixel pitch was assumed (set by readers).
pub const ASSUMED_SCALE_KEY: &str = "assumed scale";

/// Metadata key listing why the timing was assumed, or which of two disagreeing pages'
/// timing was used (set by readers).
pub const ASSUMED_TIMING_KEY: &str = "assumed timing";

/// True when `value` is finite and inside `range`.
pub fn plausible(value: f64, range: &RangeInclusive<f64>) -> bool {
    value.is_finite() && range.contains(&value)
}

/// Appends `note` to the metadata entry `key` (notes separated by "; ").
pub(crate) fn note(
    metadata: &mut std::collections::BTreeMap<String, String>,
    key: &str,
    text: impl Into<String>,
) {
    let text = text.into();
    metadata
        .entry(key.to_string())
        .and_modify(|existing| {
            if !existing.split("; ").any(|n| n == text) {
                existing.push_str("; ");
                existing.push_str(&text);
            }
        })
        .or_insert(text);
}

/// One warning per assumed value of `geometry`, with the reason a reader recorded in
/// `file`'s metadata when there is one. Empty when scale and timing are stated (read from
/// the file or given by the user).
pub fn assumption_warnings(file: Option<&ScanFile>, geometry: &ScanGeometry) -> Vec<String> {
    let reason = |key: &str| {
        file.and_then(|f| f.metadata.get(key))
            .map(|r| format!(" ({r})"))
            .unwrap_or_default()
    };
    let mut warnings = Vec::new();
    if geometry.scale_source() == ValueSource::Assumed {
        warnings.push(format!(
            "the pixel pitch is not stated usably by the file{}: {:.4e} x {:.4e} m per pixel \
             is assumed, so lengths are in made-up units; give --pitch",
            reason(ASSUMED_SCALE_KEY),
            geometry.pitch_x(),
            geometry.pitch_y()
        ));
    }
    if geometry.timing_source() == ValueSource::Assumed {
        warnings.push(format!(
            "the scan timing is not stated usably by the file{}: {:.4e} s per pixel is \
             assumed, so drift and creep rates are in made-up units; give --pixel-period \
             or --line-time",
            reason(ASSUMED_TIMING_KEY),
            geometry.pixel_period()
        ));
    }
    warnings
}
