//! How well two registered images agree, measured from the pixels alone, as an outsider
//! would check a registration: the sub-pixel shift `d` that best maps one onto the other
//! over their overlap, fitted by Gauss–Newton (Lucas–Kanade) with a height gain, offset and
//! tilt of its own (frames differ in contrast and plane). A periodic image is matched only
//! to within a lattice translation: a frame placed a whole period off is not seen here.
//! The interpolation of a finely sampled lattice (a period of 8 px) reads a shift about
//! 2–4 % long: an error in proportion to the shift, so two images registered alike read
//! ~0 and one 0.1 px off reads 0.1 px.

use nalgebra::{SMatrix, SVector};
use ndarray::Array2;

/// The fit stops once the shift is larger than this (pixels): it is then reported as it
/// stands, far beyond any registration error worth a sub-pixel figure.
pub const MAX_SHIFT_PX: f64 = 2.0;

/// Pixels this far from the grid's edge (or from a pixel without a value) are left out, so
/// that every sample shifted by up to [`MAX_SHIFT_PX`], its gradient's neighbours and their
/// cubic-convolution support (two samples either way) fall on values.
const MARGIN: usize = 5;

/// Gauss–Newton steps at most; the fit stops earlier once a step moves `d` less than
/// [`CONVERGED_PX`].
const MAX_STEPS: usize = 30;

/// A step shorter than this (pixels) ends the fit.
const CONVERGED_PX: f64 = 1e-5;

/// Fewest overlapping pixels a shift is measured on.
const MIN_OVERLAP: usize = 400;

/// The shift `d` (columns, rows, pixels) of `moving` against `reference` (same grid; NaN
/// where an image has no value): `moving(p) ≈ gain·reference(p + d) + offset + tilt·p`, 0
/// when the two are registered alike (beyond [`MAX_SHIFT_PX`]: at least this). Searched
/// from zero; `None` when they overlap too little or the fit is singular.
/// Every sample stays inside the images: the shift is at most [`MAX_SHIFT_PX`] (plus one
/// step) and [`MARGIN`] leaves room for it.
/// Over a large overlap the pixels are taken on a regular sub-grid of at most
/// [`SHIFT_PIXELS`] (every second row and column of a 512² frame): the shift's precision
/// then stays far below a thousandth of a pixel, at a fraction of the cost.
pub fn image_shift(reference: &Array2<f64>, moving: &Array2<f64>) -> Option<[f64; 2]> {
    let usable = Usable::of(reference, moving);
    image_shift_over(
        reference,
        moving,
        &usable.thinned(thinning_stride(usable.count())),
    )
}

/// Most pixels [`image_shift`] fits a shift over.
const SHIFT_PIXELS: usize = 1 << 16;

/// The smallest stride `s` such that every `s`-th row and column of `count` pixels leaves
/// at most [`SHIFT_PIXELS`] of them (1 when they are that few already).
fn thinning_stride(count: usize) -> usize {
    (1..).find(|s| count <= SHIFT_PIXELS * s * s).unwrap_or(1)
}

/// [`image_shift`] over `pixels` only (`(row, column)`, each from [`overlap`]): a part of
/// the images, such as a band of lines.
pub fn image_shift_over(
    reference: &Array2<f64>,
    moving: &Array2<f64>,
    pixels: &[(usize, usize)],
) -> Option<[f64; 2]> {
    if pixels.len() < MIN_OVERLAP {
        return None;
    }
    let reference = Reference::of(reference);
    let mut d = [0.0f64; 2];
    for _ in 0..MAX_STEPS {
        let step = gauss_newton_step(&reference, moving, pixels, d)?;
        d = [d[0] + step[0], d[1] + step[1]];
        if d[0].abs() > MAX_SHIFT_PX || d[1].abs() > MAX_SHIFT_PX {
            break;
        }
        if step[0].hypot(step[1]) < CONVERGED_PX {
            break;
        }
    }
    Some(d)
}

/// The pixels where both images, and every neighbour within [`MARGIN`], hold values.
pub fn overlap(a: &Array2<f64>, b: &Array2<f64>) -> Vec<(usize, usize)> {
    Usable::of(a, b).thinned(1)
}

/// Which pixels of two images of one grid [`overlap`] keeps.
struct Usable {
    /// Per pixel, whether it and every pixel within [`MARGIN`] along both axes hold values
    /// in both images (false within [`MARGIN`] of the edge; empty for images of different
    /// sizes or too small).
    free: Array2<bool>,
}

impl Usable {
    fn of(a: &Array2<f64>, b: &Array2<f64>) -> Usable {
        let (rows, columns) = a.dim();
        if b.dim() != (rows, columns) || rows <= 2 * MARGIN || columns <= 2 * MARGIN {
            return Usable {
                free: Array2::from_elem((0, 0), false),
            };
        }
        // Per line, how many pixels within MARGIN along it lack a value in either image
        // (prefix counts along the line); then, line by line, the sum of those over the
        // lines within MARGIN (a running sum of whole lines: contiguous memory throughout).
        let mut along = Array2::<u32>::zeros((rows, columns));
        let mut prefix = vec![0u32; columns + 1];
        for ((ra, rb), mut out) in a.rows().into_iter().zip(b.rows()).zip(along.rows_mut()) {
            for (k, (x, y)) in ra.iter().zip(rb.iter()).enumerate() {
                prefix[k + 1] = prefix[k] + u32::from(!(x.is_finite() && y.is_finite()));
            }
            for (k, n) in out.iter_mut().enumerate() {
                let (from, to) = (k.saturating_sub(MARGIN), (k + MARGIN + 1).min(columns));
                *n = prefix[to] - prefix[from];
            }
        }
        let mut free = Array2::from_elem((rows, columns), false);
        let mut window = vec![0u32; columns];
        for r in 0..rows.min(MARGIN) {
            window
                .iter_mut()
                .zip(along.row(r))
                .for_each(|(w, n)| *w += n);
        }
        for r in 0..rows {
            if r + MARGIN < rows {
                let entering = along.row(r + MARGIN);
                window.iter_mut().zip(entering).for_each(|(w, n)| *w += n);
            }
            if r > MARGIN {
                let leaving = along.row(r - MARGIN - 1);
                window.iter_mut().zip(leaving).for_each(|(w, n)| *w -= n);
            }
            if (MARGIN..rows - MARGIN).contains(&r) {
                let mut line = free.row_mut(r);
                for c in MARGIN..columns - MARGIN {
                    line[c] = window[c] == 0;
                }
            }
        }
        Usable { free }
    }

    /// How many pixels are usable.
    fn count(&self) -> usize {
        self.free.iter().filter(|f| **f).count()
    }

    /// The usable pixels (`(row, column)`, row by row) on every `stride`-th row and column.
    fn thinned(&self, stride: usize) -> Vec<(usize, usize)> {
        let stride = stride.max(1);
        self.free
            .indexed_iter()
            .filter(|&((r, c), f)| *f && r % stride == 0 && c % stride == 0)
            .map(|(p, _)| p)
            .collect()
    }
}

/// The reference image with its gradient (central differences, per pixel; NaN at the
/// edges). Cubic convolution commutes with whole-pixel shifts, so the gradient image
/// interpolated at a point is exactly the central difference of the interpolated image
/// there, at a third of the cost.
struct Reference<'a> {
    z: &'a Array2<f64>,
    gradient_x: Array2<f64>,
    gradient_y: Array2<f64>,
}

impl<'a> Reference<'a> {
    fn of(z: &'a Array2<f64>) -> Reference<'a> {
        let (rows, columns) = z.dim();
        let central = |r: usize, c: usize, along_x: bool| {
            let inside = if along_x {
                c > 0 && c + 1 < columns
            } else {
                r > 0 && r + 1 < rows
            };
            match (inside, along_x) {
                (false, _) => f64::NAN,
                (true, true) => 0.5 * (z[[r, c + 1]] - z[[r, c - 1]]),
                (true, false) => 0.5 * (z[[r + 1, c]] - z[[r - 1, c]]),
            }
        };
        Reference {
            z,
            gradient_x: Array2::from_shape_fn((rows, columns), |(r, c)| central(r, c, true)),
            gradient_y: Array2::from_shape_fn((rows, columns), |(r, c)| central(r, c, false)),
        }
    }

    /// The value and gradient at the sub-pixel point (`x` column, `y` row) by cubic
    /// convolution (Keys, a = −½): exact for quadratics, so that it biases a sub-pixel
    /// shift far less than a bilinear one would.
    fn sample(&self, x: f64, y: f64) -> [f64; 3] {
        let (c, r) = (x.floor(), y.floor());
        let (wx, wy) = (keys_weights(x - c), keys_weights(y - r));
        let (c, r) = (c as usize, r as usize);
        let mut out = [0.0; 3];
        for (image, value) in [self.z, &self.gradient_x, &self.gradient_y]
            .into_iter()
            .zip(&mut out)
        {
            for (i, wy) in wy.iter().enumerate() {
                let row = r + i - 1;
                let line: f64 = wx
                    .iter()
                    .enumerate()
                    .map(|(j, wx)| wx * image[[row, c + j - 1]])
                    .sum();
                *value += wy * line;
            }
        }
        out
    }
}

/// The four weights of cubic convolution for the samples at −1, 0, 1, 2 from a point `t`
/// (0 ≤ t < 1) past sample 0.
fn keys_weights(t: f64) -> [f64; 4] {
    let near = |d: f64| (1.5 * d - 2.5) * d * d + 1.0;
    let far = |d: f64| ((-0.5 * d + 2.5) * d - 4.0) * d + 2.0;
    [far(1.0 + t), near(t), near(1.0 - t), far(2.0 - t)]
}

/// One Gauss–Newton step of the shift from `d`, with the gain, offset and tilt solved
/// alongside (parameters: `d_x`, `d_y`, gain, offset, tilt along x, tilt along y).
fn gauss_newton_step(
    reference: &Reference<'_>,
    moving: &Array2<f64>,
    pixels: &[(usize, usize)],
    d: [f64; 2],
) -> Option<[f64; 2]> {
    let samples: Vec<[f64; 3]> = pixels
        .iter()
        .map(|&(r, c)| reference.sample(c as f64 + d[0], r as f64 + d[1]))
        .collect();
    let scale = 1.0 / reference.z.nrows().max(reference.z.ncols()) as f64;
    // The gain, offset and tilt at this shift, by linear least squares, first: the step's
    // residuals need them.
    let mut linear_n = SMatrix::<f64, 4, 4>::zeros();
    let mut linear_b = SVector::<f64, 4>::zeros();
    for (&(r, c), &[value, _, _]) in pixels.iter().zip(&samples) {
        let j = SVector::<f64, 4>::new(value, 1.0, c as f64 * scale, r as f64 * scale);
        linear_n += j * j.transpose();
        linear_b += j * moving[[r, c]];
    }
    let [gain, offset, tilt_x, tilt_y]: [f64; 4] = linear_n.cholesky()?.solve(&linear_b).into();
    let mut normal = SMatrix::<f64, 6, 6>::zeros();
    let mut rhs = SVector::<f64, 6>::zeros();
    for (&(r, c), &[value, gx, gy]) in pixels.iter().zip(&samples) {
        let (x, y) = (c as f64 * scale, r as f64 * scale);
        let residual = moving[[r, c]] - (gain * value + offset + tilt_x * x + tilt_y * y);
        let j = SVector::<f64, 6>::from_column_slice(&[gain * gx, gain * gy, value, 1.0, x, y]);
        normal += j * j.transpose();
        rhs += j * residual;
    }
    let step = normal.cholesky()?.solve(&rhs);
    Some([step[0], step[1]])
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A hexagonal lattice of Gaussian bumps (period `a` px) shifted by `s` px, with a
    /// tilt and an offset.
    fn lattice(rows: usize, columns: usize, a: f64, s: [f64; 2], tilt: f64) -> Array2<f64> {
        let k = 4.0 * std::f64::consts::PI / (3.0f64.sqrt() * a);
        let directions = [0.0f64, 60.0, 120.0].map(|deg| {
            let t = deg.to_radians();
            [k * t.cos(), k * t.sin()]
        });
        Array2::from_shape_fn((rows, columns), |(r, c)| {
            let (x, y) = (c as f64 - s[0], r as f64 - s[1]);
            let wave: f64 = directions.iter().map(|g| (g[0] * x + g[1] * y).cos()).sum();
            wave + tilt * c as f64 + 3.0
        })
    }

    #[test]
    fn a_known_sub_pixel_shift_is_found_despite_gain_offset_and_tilt() {
        let reference = lattice(96, 96, 9.0, [0.0, 0.0], 0.0);
        let mut moving = lattice(96, 96, 9.0, [0.3, -0.2], 0.01);
        moving.mapv_inplace(|v| 2.0 * v - 1.0);
        // Half of it without values, as a registered frame that covers part of the grid.
        for r in 0..96 {
            for c in 60..96 {
                moving[[r, c]] = f64::NAN;
            }
        }
        let found = image_shift(&reference, &moving).expect("a shift");
        // moving(p) = reference(p − s), so d = −s (read 2–4 % long on this 8 px period).
        assert!(
            (found[0] + 0.3).abs() < 0.05 * 0.3 && (found[1] - 0.2).abs() < 0.05 * 0.2,
            "{found:?}"
        );
        assert!(image_shift(&reference, &reference).expect("zero")[0].abs() < 1e-9);
    }

    /// A large overlap is thinned to a regular sub-grid, and the shift read on it is the
    /// one read on every pixel.
    #[test]
    fn a_large_overlap_is_thinned_without_moving_the_shift() {
        let reference = lattice(400, 400, 9.0, [0.0, 0.0], 0.0);
        let moving = lattice(400, 400, 9.0, [0.3, -0.2], 0.01);
        let every = overlap(&reference, &moving);
        let usable = Usable::of(&reference, &moving);
        assert_eq!(usable.count(), every.len());
        let stride = thinning_stride(usable.count());
        let thinned = usable.thinned(stride);
        assert!(every.len() > SHIFT_PIXELS && thinned.len() <= SHIFT_PIXELS);
        assert!(thinned.len() > SHIFT_PIXELS / 4, "{}", thinned.len());
        // The thinned pixels are those of the whole overlap on every stride-th row and column.
        let on_grid: Vec<(usize, usize)> = every
            .iter()
            .copied()
            .filter(|&(r, c)| r % stride == 0 && c % stride == 0)
            .collect();
        assert_eq!(thinned, on_grid);
        let small = overlap(
            &reference.slice(ndarray::s![..100, ..100]).to_owned(),
            &reference.slice(ndarray::s![..100, ..100]).to_owned(),
        );
        assert_eq!(thinning_stride(small.len()), 1);
        let full = image_shift_over(&reference, &moving, &every).expect("a shift");
        let fast = image_shift(&reference, &moving).expect("a shift");
        assert!(
            (full[0] - fast[0]).abs() < 1e-3 && (full[1] - fast[1]).abs() < 1e-3,
            "{full:?} {fast:?}"
        );
    }

    #[test]
    fn the_overlap_keeps_the_pixels_whose_whole_neighbourhood_holds_values() {
        let a = Array2::from_shape_fn((30, 40), |(r, c)| {
            if (r * 7 + c * 13) % 97 == 0 {
                f64::NAN
            } else {
                1.0
            }
        });
        let b = Array2::from_shape_fn(
            (30, 40),
            |(r, c)| if c > 33 && r < 9 { f64::NAN } else { 2.0 },
        );
        let usable = |r: usize, c: usize| {
            (r - MARGIN..=r + MARGIN).all(|i| {
                (c - MARGIN..=c + MARGIN).all(|j| a[[i, j]].is_finite() && b[[i, j]].is_finite())
            })
        };
        let direct: Vec<(usize, usize)> = (MARGIN..30 - MARGIN)
            .flat_map(|r| (MARGIN..40 - MARGIN).map(move |c| (r, c)))
            .filter(|&(r, c)| usable(r, c))
            .collect();
        let found = overlap(&a, &b);
        assert!(!found.is_empty() && found.len() < 20 * 30);
        assert_eq!(found, direct);
    }

    #[test]
    fn images_that_do_not_overlap_have_no_shift() {
        let reference = lattice(40, 40, 9.0, [0.0, 0.0], 0.0);
        let moving = Array2::from_elem((40, 40), f64::NAN);
        assert!(image_shift(&reference, &moving).is_none());
    }
}
