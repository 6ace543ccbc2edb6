//! Scan-line offsets fitted jointly with the features, and the centre shifts they cause.
//!
//! Levelling lines before fitting (each line's median) removes line offsets, but a line's
//! median also depends on where it crosses the atom rows, so it imprints the row period on
//! every feature; without levelling the offsets stay. Either way each line carries an
//! additive level the Gaussians do not model, and a fitted centre moves to absorb it —
//! coherently for the features of one row, a pattern a diagnosis reads as a vibration. The
//! residual of a free fit cannot show what its centre absorbed, so the levels are fitted
//! jointly with every feature: the model of each fit window's pixel is its Gaussian plus
//! the level `o_l` of its line `l`. One Gauss–Newton step from the converged fits (where
//! `Jᵢᵀrᵢ = 0`), with each feature's parameters eliminated (Schur complement):
//!
//! `Σᵢ (Dᵢ − Bᵢᵀ Aᵢ⁻¹ Bᵢ) · o = Σᵢ Eᵢᵀ rᵢ`,  then `Δθᵢ = −Aᵢ⁻¹ Bᵢ o`,
//!
//! with `Aᵢ = JᵢᵀJᵢ`, `Bᵢ = JᵢᵀEᵢ` (`Eᵢ` the pixel → line indicator), `Dᵢ = EᵢᵀEᵢ`. The
//! reduced matrix is banded (a window spans a few lines), solved in `O(lines·w²)`. Levels
//! that vary more slowly than a window is tall are what each fit's own background takes,
//! and on a lattice row parallel to the lines they mimic the row's shift: both are nearly
//! undetermined, and a ridge holds them.

use dhct_numerics::banded::SymmetricBand;
use dhct_scan::Axis;
use nalgebra::DMatrix;
use ndarray::ArrayView2;
use rayon::prelude::*;

use crate::gaussian_fit::GaussianFit;

/// Ridge on the line levels, as a fraction of the reduced matrix's median diagonal (a
/// line's pixel count, less what the features' own parameters take).
const RIDGE_FRACTION: f64 = 0.1;

/// The pixels of one fit window: columns `xs`, rows `ys` (px) and values `zs`.
pub(crate) struct WindowPixels {
    pub xs: Vec<f64>,
    pub ys: Vec<f64>,
    pub zs: Vec<f64>,
}

/// The finite pixels of `z` at `offsets` `(row, column)` from `peak` (a flat index).
pub(crate) fn window_pixels(
    z: ArrayView2<f64>,
    peak: usize,
    offsets: &[(i64, i64)],
) -> WindowPixels {
    let (rows, columns) = z.dim();
    let (peak_row, peak_col) = ((peak / columns) as i64, (peak % columns) as i64);
    let mut out = WindowPixels {
        xs: Vec::with_capacity(offsets.len()),
        ys: Vec::with_capacity(offsets.len()),
        zs: Vec::with_capacity(offsets.len()),
    };
    for &(dr, dc) in offsets {
        let (r, c) = (peak_row + dr, peak_col + dc);
        if r < 0 || c < 0 || r >= rows as i64 || c >= columns as i64 {
            continue;
        }
        let v = z[[r as usize, c as usize]];
        if v.is_finite() {
            out.xs.push(c as f64);
            out.ys.push(r as f64);
            out.zs.push(v);
        }
    }
    out
}

/// The line index of pixel `(x, y)`: its row when lines run along x, else its column.
fn line_of(x: f64, y: f64, fast_axis: Axis) -> usize {
    match fast_axis {
        Axis::Horizontal => y as usize,
        Axis::Vertical => x as usize,
    }
}

/// One fit's part of the joint system: its first line, `Aᵢ⁻¹Bᵢ` (7 × lines spanned),
/// `Bᵢ`, the pixel count and residual sum per line spanned.
struct WindowSystem {
    first_line: usize,
    solved: DMatrix<f64>,
    b: DMatrix<f64>,
    counts: Vec<f64>,
    residuals: Vec<f64>,
}

/// [`WindowSystem`] of `fit` on its window's pixels; `None` for a window without pixels or
/// with singular normal equations.
fn window_system(fit: &GaussianFit, w: &WindowPixels, fast_axis: Axis) -> Option<WindowSystem> {
    let lines: Vec<usize> =
        w.xs.iter()
            .zip(&w.ys)
            .map(|(&x, &y)| line_of(x, y, fast_axis))
            .collect();
    let first_line = *lines.iter().min()?;
    let span = lines.iter().max()? - first_line + 1;
    let gradients = fit.gradients(&w.xs, &w.ys, &w.zs);
    let mut b = DMatrix::<f64>::zeros(7, span);
    let mut counts = vec![0.0; span];
    let mut residuals = vec![0.0; span];
    for ((g, r), line) in gradients.iter().zip(&lines) {
        let k = line - first_line;
        for i in 0..7 {
            b[(i, k)] += g[i];
        }
        counts[k] += 1.0;
        residuals[k] += r;
    }
    let cholesky = fit.gram(&gradients).cholesky()?;
    let mut solved = DMatrix::<f64>::zeros(7, span);
    for k in 0..span {
        let column = cholesky.solve(&nalgebra::SVector::<f64, 7>::from_fn(|i, _| b[(i, k)]));
        solved.set_column(k, &column);
    }
    Some(WindowSystem {
        first_line,
        solved,
        b,
        counts,
        residuals,
    })
}

/// What a fit keeps of its [`WindowSystem`] for its shift: its first line and, per line
/// of its window, the `x0`, `y0` rows of `Aᵢ⁻¹Bᵢ` (px per unit level).
struct ShiftRows {
    first_line: usize,
    rows: Vec<[f64; 2]>,
}

/// One thread's share of [`reduced_system`]: the matrix, the right-hand side and the
/// shift rows of the fits it visited (with their indices).
type Partial = (SymmetricBand, Vec<f64>, Vec<(usize, ShiftRows)>);

/// The reduced system `Σᵢ (Dᵢ − BᵢᵀAᵢ⁻¹Bᵢ)` and `Σᵢ Eᵢᵀrᵢ` over every fit, for `lines`
/// lines and half-bandwidth `w`, and each fit's [`ShiftRows`] (`None` where its window
/// system is singular or empty), so that each window is visited once.
fn reduced_system(
    z: ArrayView2<f64>,
    fits: &[(GaussianFit, usize)],
    offsets: &[(i64, i64)],
    fast_axis: Axis,
    (lines, w): (usize, usize),
) -> (SymmetricBand, Vec<f64>, Vec<Option<ShiftRows>>) {
    let empty = || -> Partial { (SymmetricBand::zeros(lines, w), vec![0.0; lines], Vec::new()) };
    let (m, rhs, kept) = fits
        .par_iter()
        .enumerate()
        .fold(empty, |(mut m, mut rhs, mut kept), (i, (fit, peak))| {
            let pixels = window_pixels(z, *peak, offsets);
            if let Some(s) = window_system(fit, &pixels, fast_axis) {
                let c = s.b.transpose() * &s.solved;
                for a in 0..s.counts.len() {
                    let la = s.first_line + a;
                    rhs[la] += s.residuals[a];
                    m.add(la, la, s.counts[a]);
                    for bb in 0..=a {
                        m.add(la, s.first_line + bb, -c[(a, bb)]);
                    }
                }
                let rows = (0..s.counts.len())
                    .map(|k| [s.solved[(1, k)], s.solved[(2, k)]])
                    .collect();
                kept.push((
                    i,
                    ShiftRows {
                        first_line: s.first_line,
                        rows,
                    },
                ));
            }
            (m, rhs, kept)
        })
        .reduce(empty, |(mut m, mut r, mut kept), (m2, r2, kept2)| {
            m.add_matrix(&m2);
            for (a, b) in r.iter_mut().zip(r2) {
                *a += b;
            }
            kept.extend(kept2);
            (m, r, kept)
        });
    let mut shifts: Vec<Option<ShiftRows>> = (0..fits.len()).map(|_| None).collect();
    for (i, rows) in kept {
        shifts[i] = Some(rows);
    }
    (m, rhs, shifts)
}

/// The line levels solving `(M + ρ·I)·o = rhs`, `ρ` = [`RIDGE_FRACTION`] × the median
/// diagonal of `M`. Levels the data cannot tell from the features' own shifts (a lattice
/// row parallel to the lines: its features share their lines and their phase) are held
/// near zero by it; a weaker ridge lets noise into them (on the embedded 256² example,
/// rows along x, 0.01 made the drift model's parameters undetermined). `None` if the solve
/// fails.
fn regularised_levels(m: &SymmetricBand, rhs: &[f64]) -> Option<Vec<f64>> {
    let lines = m.size();
    let mut diagonal: Vec<f64> = (0..lines)
        .map(|l| m.get(l, l))
        .filter(|d| *d > 0.0)
        .collect();
    let typical = dhct_numerics::robust::median(&mut diagonal)?;
    let mut regularised = m.clone();
    for l in 0..lines {
        // Lines no window covers get the ridge alone (their level is 0).
        regularised.add(l, l, RIDGE_FRACTION * typical);
    }
    regularised.solve(rhs)
}

/// Fits the scan-line levels jointly with the features (`fits[i]` fitted to the window
/// around flat index `fits[i].1` of `z`) and moves every centre by what they change
/// (first order). Nothing moves if the system cannot be solved.
pub(crate) fn relevel(
    z: ArrayView2<f64>,
    fits: &mut [(GaussianFit, usize)],
    offsets: &[(i64, i64)],
    fast_axis: Axis,
) {
    let lines = match fast_axis {
        Axis::Horizontal => z.dim().0,
        Axis::Vertical => z.dim().1,
    };
    let w = offsets
        .iter()
        .map(|&(dr, dc)| match fast_axis {
            Axis::Horizontal => dr,
            Axis::Vertical => dc,
        })
        .fold((0i64, 0i64), |(lo, hi), d| (lo.min(d), hi.max(d)));
    let half_bandwidth = (w.1 - w.0).max(0) as usize;
    if lines == 0 || fits.is_empty() {
        return;
    }
    let (m, rhs, shifts) = reduced_system(z, fits, offsets, fast_axis, (lines, half_bandwidth));
    let Some(levels) = regularised_levels(&m, &rhs) else {
        return;
    };
    for ((fit, _), shift) in fits.iter_mut().zip(shifts) {
        let Some(ShiftRows { first_line, rows }) = shift else {
            continue;
        };
        let window_levels = &levels[first_line..first_line + rows.len()];
        let (mut dx, mut dy) = (0.0, 0.0);
        for (row, o) in rows.iter().zip(window_levels) {
            dx -= row[0] * o;
            dy -= row[1] * o;
        }
        if dx.is_finite() && dy.is_finite() {
            fit.x0 += dx;
            fit.y0 += dy;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gaussian_fit::{FitLimits, FitShape, fit_gaussian};
    use ndarray::Array2;

    /// 6 × 6 Gaussians (σ 2 px) on a lattice rotated by 17°, spacing 9 px, in a 64² image
    /// whose lines (rows) carry offsets of ±8 % of the amplitude; their true centres.
    fn image() -> (Array2<f64>, Vec<(f64, f64)>) {
        let (s, c) = 17f64.to_radians().sin_cos();
        let mut centres = Vec::new();
        for i in 0..6 {
            for j in 0..6 {
                let (u, v) = (9.0 * i as f64, 9.0 * j as f64);
                centres.push((8.0 + c * u - s * v + 12.0, 8.0 + s * u + c * v));
            }
        }
        centres.retain(|&(x, y)| (6.0..58.0).contains(&x) && (6.0..58.0).contains(&y));
        let z = Array2::from_shape_fn((64, 64), |(r, col)| {
            let offset = 0.08 * ((r * 7919) % 13) as f64 / 6.0 - 0.08;
            offset
                + centres
                    .iter()
                    .map(|&(x, y)| {
                        let (dx, dy) = (col as f64 - x, r as f64 - y);
                        (-(dx * dx + dy * dy) / 8.0).exp()
                    })
                    .sum::<f64>()
        });
        (z, centres)
    }

    /// Fits every centre in `z` (windows of radius 3 px around the rounded true centre),
    /// optionally relevels, and returns the RMS error across the lines (`fast_axis`).
    fn error_across(
        z: &Array2<f64>,
        centres: &[(f64, f64)],
        fast_axis: Axis,
        relevel_on: bool,
    ) -> f64 {
        let offsets: Vec<(i64, i64)> = (-3i64..=3)
            .flat_map(|dr| (-3i64..=3).map(move |dc| (dr, dc)))
            .filter(|(dr, dc)| dr * dr + dc * dc <= 9)
            .collect();
        let columns = z.dim().1;
        let mut fits: Vec<(GaussianFit, usize)> = centres
            .iter()
            .map(|&(x, y)| {
                let peak = y.round() as usize * columns + x.round() as usize;
                let w = window_pixels(z.view(), peak, &offsets);
                let limits = FitLimits {
                    x_range: (x - 3.0, x + 3.0),
                    y_range: (y - 3.0, y + 3.0),
                    sigma_range: (0.5, 9.0),
                    max_iterations: 100,
                    shape: FitShape::Elliptical,
                };
                (
                    fit_gaussian(&w.xs, &w.ys, &w.zs, (x.round(), y.round()), 2.0, &limits),
                    peak,
                )
            })
            .collect();
        if relevel_on {
            relevel(z.view(), &mut fits, &offsets, fast_axis);
        }
        let across = |f: &GaussianFit, &(x, y): &(f64, f64)| match fast_axis {
            Axis::Horizontal => f.y0 - y,
            Axis::Vertical => f.x0 - x,
        };
        let sum: f64 = fits
            .iter()
            .zip(centres)
            .map(|((f, _), c)| across(f, c).powi(2))
            .sum();
        (sum / centres.len() as f64).sqrt()
    }

    #[test]
    fn fitted_line_levels_undo_the_offsets_shifts_along_either_fast_axis() {
        let (z, centres) = image();
        let before = error_across(&z, &centres, Axis::Horizontal, false);
        let after = error_across(&z, &centres, Axis::Horizontal, true);
        println!("across the lines: {before:.4} px, fitted levels {after:.4} px");
        assert!(before > 0.02, "the offsets move the centres ({before} px)");
        assert!(after < 0.5 * before, "{after} vs {before} px");
        // The same image transposed, its lines now columns: the same result.
        let transposed = z.t().to_owned();
        let swapped: Vec<(f64, f64)> = centres.iter().map(|&(x, y)| (y, x)).collect();
        let vertical = error_across(&transposed, &swapped, Axis::Vertical, true);
        assert!((vertical - after).abs() < 1e-9, "{vertical} vs {after}");
    }
}
