use ndarray::{Array2, ArrayView1, ArrayViewMut1};
use serde::{Deserialize, Serialize};

use crate::{Axis, GeometryError};

/// One 2-D image of a physical quantity, in display orientation (row 0 at the top).
///
/// `z[[row, col]]` is in SI units named by `unit` (metres for topography, amperes for current).
/// Missing samples (e.g. an aborted scan) are NaN.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ImageChannel {
    /// Channel name as the instrument calls it, e.g. "Topography".
    pub name: String,
    /// SI unit of z, e.g. "m", "A", "V".
    pub unit: String,
    /// Values, shape `(rows, columns)`, row-major.
    pub z: Array2<f64>,
}

impl ImageChannel {
    /// Wraps an array of shape `(rows, columns)`.
    pub fn new(name: impl Into<String>, unit: impl Into<String>, z: Array2<f64>) -> ImageChannel {
        ImageChannel {
            name: name.into(),
            unit: unit.into(),
            z,
        }
    }

    /// Builds a channel from row-major values, checking the length.
    pub fn from_row_major(
        name: impl Into<String>,
        unit: impl Into<String>,
        rows: usize,
        columns: usize,
        values: Vec<f64>,
    ) -> Result<ImageChannel, GeometryError> {
        let expected = rows.saturating_mul(columns);
        if values.len() != expected {
            return Err(GeometryError::DataLength {
                len: values.len(),
                rows,
                columns,
                expected,
            });
        }
        let z = Array2::from_shape_vec((rows, columns), values).map_err(|_| {
            GeometryError::DataLength {
                len: expected,
                rows,
                columns,
                expected,
            }
        })?;
        Ok(ImageChannel::new(name, unit, z))
    }

    /// Number of rows (pixels along y).
    pub fn rows(&self) -> usize {
        self.z.nrows()
    }

    /// Number of columns (pixels along x).
    pub fn columns(&self) -> usize {
        self.z.ncols()
    }

    /// Scan line `index` when the fast scan runs along `fast_axis`: row `index` for a
    /// horizontal fast axis, column `index` for a vertical one (display order along it).
    pub fn line(&self, fast_axis: Axis, index: usize) -> ArrayView1<'_, f64> {
        match fast_axis {
            Axis::Horizontal => self.z.row(index),
            Axis::Vertical => self.z.column(index),
        }
    }

    /// [`ImageChannel::line`], mutable.
    pub fn line_mut(&mut self, fast_axis: Axis, index: usize) -> ArrayViewMut1<'_, f64> {
        match fast_axis {
            Axis::Horizontal => self.z.row_mut(index),
            Axis::Vertical => self.z.column_mut(index),
        }
    }

    /// Minimum and maximum of the finite values, or `None` if there are none.
    pub fn finite_range(&self) -> Option<(f64, f64)> {
        self.z
            .iter()
            .copied()
            .filter(|v| v.is_finite())
            .fold(None, |acc, v| match acc {
                None => Some((v, v)),
                Some((lo, hi)) => Some((lo.min(v), hi.max(v))),
            })
    }

    /// Number of non-finite (NaN or infinite) values.
    pub fn non_finite_count(&self) -> usize {
        self.z.iter().filter(|v| !v.is_finite()).count()
    }
}
