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
    pub values: Array2<f64>,
    /// Cells averaged.
    pub cells: usize,
    /// Cells skipped because part of them lay outside the image or on missing data.
    pub skipped: usize,
}

/// Bilinear sample of `image` at pixel position `(x, y)`; `None` outside or on NaN.
fn bilinear(image: ArrayView2<f64>, x: f64, y: f64) -> Option<f64> {
    let (rows, cols) = image.dim();
    if !(x >= 0.0 && y >= 0.0 && x <= (cols - 1) as f64 && y <= (rows - 1) as f64) {
        return None;
    }
    let (c0, r0) = (
        (x.floor() as usize).min(cols.saturating_sub(2)),
        (y.floor() as usize).min(rows.saturating_sub(2)),
    );
    let (c1, r1) = ((c0 + 1).min(cols - 1), (r0 + 1).min(rows - 1));
    let (fx, fy) = (x - c0 as f64, y - r0 as f64);
    let value = image[[r0, c0]] * (1.0 - fx) * (1.0 - fy)
        + image[[r0, c1]] * fx * (1.0 - fy)
        + image[[r1, c0]] * (1.0 - fx) * fy
        + image[[r1, c1]] * fx * fy;
    value.is_finite().then_some(value)
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
    // Cells are summed in fixed-size chunks in parallel and the chunk sums added in chunk
    // order, so the result does not depend on the number of threads.
    const CHUNK: usize = 128;
    let partial: Vec<(Array2<f64>, usize, usize)> = cells
        .par_chunks(CHUNK)
        .map(|chunk| {
            let mut sum = Array2::<f64>::zeros((resolution, resolution));
            let mut sample = Array2::<f64>::zeros((resolution, resolution));
            let (mut used, mut skipped) = (0usize, 0usize);
            'cells: for cell in chunk {
                let t = cell.transform();
                let origin = Vector2::from(cell.origin_m);
                for ((i, j), value) in sample.indexed_iter_mut() {
                    let (u, v) = (j as f64 / resolution as f64, i as f64 / resolution as f64);
                    let p = origin + t * (a1 * u + a2 * v);
                    match bilinear(image, p.x / pitch.0, p.y / pitch.1) {
                        Some(z) => *value = z,
                        None => {
                            skipped += 1;
                            continue 'cells;
                        }
                    }
                }
                sum += &sample;
                used += 1;
            }
            (sum, used, skipped)
        })
        .collect();
    let mut sum = Array2::<f64>::zeros((resolution, resolution));
    let (mut used, mut skipped) = (0usize, 0usize);
    for (chunk_sum, chunk_used, chunk_skipped) in &partial {
        sum += chunk_sum;
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
