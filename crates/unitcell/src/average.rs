use dhct_lattice::Lattice;
use nalgebra::Vector2;
use ndarray::{Array2, ArrayView2};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::{LocalCell, UnitCellError};

/// A translationally averaged unit cell on a grid of fractional coordinates: sample
/// `values[[i, j]]` is at `u = j / resolution` along a1 and `v = i / resolution` along a2.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AveragedCell {
    /// The averaged image values on the `resolution × resolution` grid, z units.
    pub values: Array2<f64>,
    /// Cells averaged.
    pub cells: usize,
    /// Cells skipped because part of them lay outside the image or on missing data.
    pub skipped: usize,
}

/// Bilinear sampling of a contiguous row-major image at pixel positions `(x, y)` (x along
/// columns). NaN pixels give NaN.
struct Sampler<'a> {
    data: &'a [f64],
    rows: usize,
    cols: usize,
}

impl<'a> Sampler<'a> {
    fn new(image: ArrayView2<'a, f64>) -> Self {
        let (rows, cols) = image.dim();
        let data = image
            .to_slice()
            .expect("the caller makes the view contiguous");
        Sampler { data, rows, cols }
    }

    /// Whether `p` lies within the pixel centres (where bilinear sampling is defined).
    fn contains(&self, p: Vector2<f64>) -> bool {
        self.rows >= 2
            && self.cols >= 2
            && p.x >= 0.0
            && p.y >= 0.0
            && p.x <= (self.cols - 1) as f64
            && p.y <= (self.rows - 1) as f64
    }

    /// The bilinear value at `(x, y)`, which must satisfy [`Sampler::contains`].
    #[inline]
    fn at(&self, x: f64, y: f64) -> f64 {
        let cols = self.cols;
        let c0 = (x as usize).min(cols - 2);
        let r0 = (y as usize).min(self.rows - 2);
        let (fx, fy) = (x - c0 as f64, y - r0 as f64);
        // The four neighbours in one slice: one bounds check.
        let start = r0 * cols + c0;
        let d = &self.data[start..start + cols + 2];
        let upper = d[0] + fx * (d[1] - d[0]);
        let lower = d[cols] + fx * (d[cols + 1] - d[cols]);
        upper + fy * (lower - upper)
    }
}

/// Averages `image` (pixel pitch `pitch` = (x, y) metres) over `cells`, each resampled
/// through its own linear map onto a `resolution x resolution` fractional grid.
pub fn average_unit_cell(
    image: ArrayView2<f64>,
    pitch: (f64, f64),
    lattice: &dyn Lattice,
    cells: &[LocalCell],
    resolution: usize,
) -> Result<AveragedCell, UnitCellError> {
    if resolution < 2 {
        return Err(UnitCellError::BadResolution(resolution));
    }
    if !(pitch.0.is_finite() && pitch.1.is_finite() && pitch.0 > 0.0 && pitch.1 > 0.0) {
        return Err(UnitCellError::BadPitch(pitch.0, pitch.1));
    }
    let [a1, a2] = lattice.primitive_vectors();
    // A contiguous row-major copy only when the view is not one already.
    let owned;
    let image = match image.as_slice() {
        Some(_) => image,
        None => {
            owned = image.as_standard_layout().into_owned();
            owned.view()
        }
    };
    let sampler = Sampler::new(image);
    let pixel = |p: Vector2<f64>| Vector2::new(p.x / pitch.0, p.y / pitch.1);
    // Cells are summed in fixed-size chunks in parallel and the chunk sums added in chunk
    // order, so the result does not depend on the number of threads.
    const CHUNK: usize = 128;
    let partial: Vec<(Vec<f64>, usize, usize)> = cells
        .par_chunks(CHUNK)
        .map(|chunk| {
            let mut sum = vec![0.0; resolution * resolution];
            let mut sample = vec![0.0; resolution * resolution];
            let (mut used, mut skipped) = (0usize, 0usize);
            for cell in chunk {
                // The cell is an affine image of the fractional grid: its sample positions
                // (pixels) are `p0 + j·du + i·dv`, all inside when the four corners are.
                let t = cell.transform();
                let p0 = pixel(Vector2::from(cell.origin_m));
                let du = pixel(t * a1) / resolution as f64;
                let dv = pixel(t * a2) / resolution as f64;
                let last = (resolution - 1) as f64;
                let corners_inside = [(0.0, 0.0), (last, 0.0), (0.0, last), (last, last)]
                    .iter()
                    .all(|&(j, i)| sampler.contains(p0 + du * j + dv * i));
                let mut finite = corners_inside;
                if corners_inside {
                    for (i, row) in sample.chunks_exact_mut(resolution).enumerate() {
                        let start = p0 + dv * i as f64;
                        for (j, value) in row.iter_mut().enumerate() {
                            let p = start + du * j as f64;
                            *value = sampler.at(p.x, p.y);
                        }
                        finite &= row.iter().all(|v| v.is_finite());
                    }
                }
                if finite {
                    sum.iter_mut().zip(&sample).for_each(|(s, v)| *s += v);
                    used += 1;
                } else {
                    skipped += 1;
                }
            }
            (sum, used, skipped)
        })
        .collect();
    let mut sum = Array2::<f64>::zeros((resolution, resolution));
    let sum_slice = sum.as_slice_mut().expect("a new array is contiguous");
    let (mut used, mut skipped) = (0usize, 0usize);
    for (chunk_sum, chunk_used, chunk_skipped) in &partial {
        sum_slice
            .iter_mut()
            .zip(chunk_sum)
            .for_each(|(s, v)| *s += v);
        used += chunk_used;
        skipped += chunk_skipped;
    }
    if used == 0 {
        return Err(UnitCellError::NoCompleteCell);
    }
    Ok(AveragedCell {
        values: sum / used as f64,
        cells: used,
        skipped,
    })
}

/// `nx x ny` copies of the averaged cell side by side in fractional coordinates, to check that
/// its boundaries join seamlessly.
pub fn tile(cell: &AveragedCell, nx: usize, ny: usize) -> Array2<f64> {
    let (rows, cols) = cell.values.dim();
    Array2::from_shape_fn((rows * ny, cols * nx), |(i, j)| {
        cell.values[[i % rows, j % cols]]
    })
}
