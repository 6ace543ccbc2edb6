//! Placeholder geometry values for what a file does not say.
//!
//! Readers that cannot find a value use these and mark it
//! [`dhct_scan::ValueSource::Assumed`], so later stages can warn or ask the user (e.g. with
//! [`crate::GeometryOverrides`]) instead of reporting numbers in made-up units.

/// Placeholder pixel pitch, metres along x and y: 1 Å per pixel (NPY and TIFF carry no
/// scale; SM4/SXM/GSF/ISO files with a zero, missing or non-length scale).
pub const ASSUMED_PITCH: f64 = 1e-10;

/// Placeholder pixel period, seconds per pixel along the fast axis: 1 ms (ISO 28600, NPY,
/// TIFF and plain GSF carry no timing; SM4/SXM files with a zero or missing period).
pub const ASSUMED_PIXEL_PERIOD: f64 = 1e-3;
