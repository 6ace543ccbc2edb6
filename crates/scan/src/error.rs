use thiserror::Error;

/// Why a scan geometry, channel or pair is inconsistent.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum GeometryError {
    /// The image has no pixels.
    #[error("image size must be at least 1 x 1 pixels, got {columns} x {rows}")]
    EmptyImage {
        /// Columns given (pixels along x).
        columns: usize,
        /// Rows given (pixels along y).
        rows: usize,
    },
    /// A value that must be positive is not (or is not finite).
    #[error("{what} must be finite and positive, got {value}")]
    NotPositive {
        /// Which value, e.g. "x pixel pitch".
        what: &'static str,
        /// The value given, SI units (metres or seconds).
        value: f64,
    },
    /// A value that must be non-negative is negative (or not finite).
    #[error("{what} must be finite and non-negative, got {value}")]
    Negative {
        /// Which value, e.g. "turnaround time".
        what: &'static str,
        /// The value given, seconds.
        value: f64,
    },
    /// A value is NaN or infinite.
    #[error("{what} must be finite, got {value}")]
    NotFinite {
        /// Which value, e.g. "scan angle".
        what: &'static str,
        /// The value given, SI units (metres or radians).
        value: f64,
    },
    /// Fast and slow scan directions lie along the same axis.
    #[error(
        "fast direction {fast:?} and slow direction {slow:?} must be perpendicular \
         (one of Left/Right and one of Up/Down)"
    )]
    NotPerpendicular {
        /// The fast-axis direction given.
        fast: crate::ScanDirection,
        /// The slow-axis direction given.
        slow: crate::ScanDirection,
    },
    /// The number of values does not match the image size.
    #[error("image data has {len} values but {rows} x {columns} = {expected} were expected")]
    DataLength {
        /// Values given.
        len: usize,
        /// Rows of the image.
        rows: usize,
        /// Columns of the image.
        columns: usize,
        /// Values the image needs, `rows × columns`.
        expected: usize,
    },
    /// An image's size differs from its scan geometry's.
    #[error(
        "{image} image is {columns} x {rows} px but the scan geometry says {geometry_columns} x {geometry_rows} px"
    )]
    ShapeMismatch {
        /// Which image: "trace" or "retrace".
        image: &'static str,
        /// The image's columns, pixels.
        columns: usize,
        /// The image's rows, pixels.
        rows: usize,
        /// The geometry's columns, pixels.
        geometry_columns: usize,
        /// The geometry's rows, pixels.
        geometry_rows: usize,
    },
    /// Values given together contradict each other or are implausible.
    #[error("conflicting geometry values: {0}")]
    Conflicting(&'static str),
    /// A scan pair has neither a trace nor a retrace image.
    #[error("a scan pair needs at least one of trace and retrace")]
    NoImages,
}
