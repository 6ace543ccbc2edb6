//! A detail of an image for a figure: a central crop a given number of metres wide.

use dhct_scan::ScanGeometry;

/// A crop of an image on the scan's grid, pixel bounds `[r0, r1) × [c0, c1)`.
pub(crate) struct Detail {
    pub r0: usize,
    pub r1: usize,
    pub c0: usize,
    pub c1: usize,
}

impl Detail {
    /// The central square `side_m` wide: at least 8 px a side, the whole image when
    /// smaller.
    pub fn central(geometry: &ScanGeometry, side_m: f64) -> Detail {
        let (rows, columns) = (geometry.rows(), geometry.columns());
        let side = |pitch: f64, n: usize| ((side_m / pitch).ceil() as usize).max(8).min(n);
        let (w, h) = (
            side(geometry.pitch_x(), columns),
            side(geometry.pitch_y(), rows),
        );
        let (c0, r0) = ((columns - w) / 2, (rows - h) / 2);
        Detail {
            r0,
            r1: r0 + h,
            c0,
            c1: c0 + w,
        }
    }

    /// Columns.
    pub fn width(&self) -> usize {
        self.c1 - self.c0
    }

    /// Rows.
    pub fn height(&self) -> usize {
        self.r1 - self.r0
    }

    /// Whether image pixel position `(x, y)` lies inside, `margin` px from the edges.
    pub fn contains(&self, x: f64, y: f64, margin: f64) -> bool {
        x >= self.c0 as f64 + margin
            && x <= self.c1 as f64 - 1.0 - margin
            && y >= self.r0 as f64 + margin
            && y <= self.r1 as f64 - 1.0 - margin
    }
}
