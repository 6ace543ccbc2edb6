use thiserror::Error;

/// Why a scan geometry, channel or pair is inconsistent.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum GeometryError {
    #[error("image size must be at least 1 x 1 pixels, got {columns} x {rows}")]
    EmptyImage { columns: usize, rows: usize },
    #[error("{what} must be finite and positive, got {value}")]
    NotPositive { what: &'static str, value: f64 },
    #[error("{what} must be finite and non-negative, got {value}")]
    Negative { what: &'static str, value: f64 },
    #[error("{what} must be finite, got {value}")]
    NotFinite { what: &'static str, value: f64 },
    #[error(
        "fast direction {fast:?} and slow direction {slow:?} must be perpendicular \
         (one of Left/Right and one of Up/Down)"
    )]
    NotPerpendicular {
        fast: crate::ScanDirection,
        slow: crate::ScanDirection,
    },
    #[error("image data has {len} values but {rows} x {columns} = {expected} were expected")]
    DataLength {
        len: usize,
        rows: usize,
        columns: usize,
        expected: usize,
    },
    #[error(
        "{image} image is {columns} x {rows} px but the scan geometry says {geometry_columns} x {geometry_rows} px"
    )]
    ShapeMismatch {
        image: &'static str,
        columns: usize,
        rows: usize,
        geometry_columns: usize,
        geometry_rows: usize,
    },
    #[error("conflicting geometry values: {0}")]
    Conflicting(&'static str),
    #[error("a scan pair needs at least one of trace and retrace")]
    NoImages,
}
