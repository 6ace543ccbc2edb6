//! How the stored sample order and the signs of the x/y scales relate to display orientation
//! and to the slow scan direction. Shared by the reader and the writer so they stay inverse.
//!
//! Stored data are `y_size` rows of `x_size` samples. The physical position of stored sample
//! `(i, j)` (row `i`, column `j`) is `x = x_offset + j·x_scale`, `y = y_offset + i·y_scale`
//! with y pointing *up* on the sample. Display orientation has x to the right and row 0 at
//! the top, so:
//!
//! * `x_scale < 0`: stored column 0 is the rightmost → columns are mirrored;
//! * `y_scale > 0`: stored row 0 is the bottom → rows are flipped;
//!   `y_scale < 0` (the usual case, a downward scan): stored row 0 is the top, kept as is.
//!
//! Lines are stored in acquisition order, so the slow direction points away from the display
//! edge that holds stored line 0: for a horizontal fast axis `Down` when `y_scale < 0`,
//! `Up` when `y_scale > 0`; for a vertical fast axis `Left` when `x_scale < 0`, else `Right`.

use dhct_scan::{Axis, ScanDirection};

/// The mapping between stored (file) sample positions and display positions.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Orientation {
    /// Stored column `j` is display column `columns - 1 - j`.
    pub(crate) mirror_columns: bool,
    /// Stored row `i` is display row `rows - 1 - i`.
    pub(crate) flip_rows: bool,
}

impl Orientation {
    /// The orientation implied by the signs of the page's x and y scales.
    pub(crate) fn from_scales(x_scale: f64, y_scale: f64) -> Orientation {
        Orientation {
            mirror_columns: x_scale < 0.0,
            flip_rows: y_scale > 0.0,
        }
    }

    /// Display `(row, column)` of stored `(row, column)`; the map is its own inverse.
    pub(crate) fn map(
        self,
        row: usize,
        column: usize,
        rows: usize,
        columns: usize,
    ) -> (usize, usize) {
        let row = if self.flip_rows {
            rows.saturating_sub(1).saturating_sub(row)
        } else {
            row
        };
        let column = if self.mirror_columns {
            columns.saturating_sub(1).saturating_sub(column)
        } else {
            column
        };
        (row, column)
    }
}

/// The slow direction implied by the fast direction and the scale signs (see module docs).
pub(crate) fn slow_direction(fast: ScanDirection, x_scale: f64, y_scale: f64) -> ScanDirection {
    match fast.axis() {
        Axis::Horizontal if y_scale > 0.0 => ScanDirection::Up,
        Axis::Horizontal => ScanDirection::Down,
        Axis::Vertical if x_scale < 0.0 => ScanDirection::Left,
        Axis::Vertical => ScanDirection::Right,
    }
}

/// Signs `(x, y)` (±1) of the scales the writer stores for a scan with these directions.
///
/// For a horizontal fast axis x is always negative, as RHK software writes it (and as
/// Gwyddion, which always mirrors columns, assumes); y encodes the slow direction.
/// For a vertical fast axis x encodes the slow direction and y is negative.
pub(crate) fn scale_signs(fast: ScanDirection, slow: ScanDirection) -> (f64, f64) {
    match (fast.axis(), slow) {
        (Axis::Horizontal, ScanDirection::Up) => (-1.0, 1.0),
        (Axis::Horizontal, _) => (-1.0, -1.0),
        (Axis::Vertical, ScanDirection::Right) => (1.0, -1.0),
        (Axis::Vertical, _) => (-1.0, -1.0),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ScanDirection::*;

    #[test]
    fn writer_signs_read_back_as_the_same_slow_direction() {
        for (fast, slow) in [
            (Right, Down),
            (Right, Up),
            (Left, Down),
            (Left, Up),
            (Up, Left),
            (Up, Right),
            (Down, Left),
            (Down, Right),
        ] {
            let (sx, sy) = scale_signs(fast, slow);
            assert_eq!(slow_direction(fast, sx, sy), slow, "{fast:?} {slow:?}");
        }
    }

    #[test]
    fn negative_x_mirrors_and_positive_y_flips() {
        let o = Orientation::from_scales(-1.0, -1.0);
        assert_eq!(o.map(0, 0, 3, 4), (0, 3));
        let o = Orientation::from_scales(1.0, 1.0);
        assert_eq!(o.map(0, 0, 3, 4), (2, 0));
        let o = Orientation::from_scales(-1.0, 1.0);
        assert_eq!(o.map(1, 1, 3, 4), (1, 2));
    }
}
