//! Background and scan-line corrections applied before feature finding.
//!
//! These change only the copy of z that the correlation and the Gaussian fits see; the
//! image handed to the distortion correction is never altered.

use dhct_scan::Axis;
use nalgebra::{DMatrix, DVector};
use ndarray::{Array2, ArrayViewMut1};
use rayon::prelude::*;

use crate::levelling::line_level::{line_taper, tapered_line_level_with};
use crate::{Background, FeatureError, FeatureOptions, LineCorrection, Polarity};

/// Subtracts a least-squares polynomial surface of total order `order` (1 = plane), fitted
/// to the finite pixels where `mask` is true (all finite pixels without a mask).
pub fn subtract_polynomial(
    z: &Array2<f64>,
    order: u8,
    mask: Option<&Array2<bool>>,
) -> Result<Array2<f64>, FeatureError> {
    let mut out = z.clone();
    subtract_polynomial_in_place(&mut out, order, mask)?;
    Ok(out)
}

/// [`subtract_polynomial`] without a copy: `z` is replaced by its residual.
pub fn subtract_polynomial_in_place(
    z: &mut Array2<f64>,
    order: u8,
    mask: Option<&Array2<bool>>,
) -> Result<(), FeatureError> {
    if order > 6 {
        return Err(FeatureError::BadParameter(format!(
            "background polynomial order must be at most 6, got {order}"
        )));
    }
    let (h, w) = z.dim();
    let order = order as usize;
    // Coordinates scaled to [−1, 1] keep the normal equations well conditioned.
    let scale = |i: usize, n: usize| {
        if n > 1 {
            2.0 * i as f64 / (n - 1) as f64 - 1.0
        } else {
            0.0
        }
    };
    // Terms x^i·y^j with i + j ≤ order.
    let exponents: Vec<(usize, usize)> = (0..=order)
        .flat_map(|total| (0..=total).map(move |j| (total - j, j)))
        .collect();
    let terms = exponents.len();
    // x^k per column for k ≤ 2·order, stored power-major so each power is contiguous.
    let x_powers: Vec<Vec<f64>> = (0..=2 * order)
        .map(|k| (0..w).map(|c| scale(c, w).powi(k as i32)).collect())
        .collect();
    // The normal equations only need, per row, S_k = Σ x^k and T_k = Σ x^k·z over the row's
    // usable pixels; they are combined with powers of the row's y.
    let mut normal = DMatrix::<f64>::zeros(terms, terms);
    let mut rhs = DVector::<f64>::zeros(terms);
    let mut used = 0usize;
    let (mut s, mut t) = (vec![0.0; 2 * order + 1], vec![0.0; order + 1]);
    for (r, row) in z.rows().into_iter().enumerate() {
        s.iter_mut().for_each(|v| *v = 0.0);
        t.iter_mut().for_each(|v| *v = 0.0);
        for (c, &value) in row.iter().enumerate() {
            if !value.is_finite() || mask.is_some_and(|m| !m[[r, c]]) {
                continue;
            }
            for (k, sum) in s.iter_mut().enumerate() {
                *sum += x_powers[k][c];
            }
            for (k, sum) in t.iter_mut().enumerate() {
                *sum += x_powers[k][c] * value;
            }
            used += 1;
        }
        let y = scale(r, h);
        for (a, &(ia, ja)) in exponents.iter().enumerate() {
            rhs[a] += y.powi(ja as i32) * t[ia];
            for (b, &(ib, jb)) in exponents.iter().enumerate() {
                normal[(a, b)] += y.powi((ja + jb) as i32) * s[ia + ib];
            }
        }
    }
    if used < 2 * terms {
        return Err(FeatureError::MissingData {
            finite: used,
            total: h * w,
        });
    }
    let coefficients = normal.cholesky().map(|c| c.solve(&rhs)).ok_or_else(|| {
        FeatureError::BadParameter("background fit is singular (mask too small?)".into())
    })?;
    // Per row the surface is a polynomial in x: c_i(y) = Σ_j coef[i, j]·y^j.
    let mut row_coefficients = vec![0.0; order + 1];
    for (r, mut row) in z.rows_mut().into_iter().enumerate() {
        let y = scale(r, h);
        row_coefficients.iter_mut().for_each(|v| *v = 0.0);
        for (k, &(i, j)) in exponents.iter().enumerate() {
            row_coefficients[i] += coefficients[k] * y.powi(j as i32);
        }
        for (c, value) in row.iter_mut().enumerate() {
            let x = x_powers[1.min(2 * order)][c];
            // Horner in x.
            let surface = row_coefficients
                .iter()
                .rev()
                .fold(0.0, |acc, k| acc * x + k);
            *value -= surface;
        }
    }
    Ok(())
}

/// Removes per-line offsets along the fast axis (each line's median, tapered mean or
/// straight-line fit), then restores the overall median level.
pub fn correct_lines(z: &Array2<f64>, fast_axis: Axis, method: LineCorrection) -> Array2<f64> {
    let mut out = z.clone();
    correct_lines_in_place(&mut out, fast_axis, method);
    out
}

/// The scan lines of `z`, in order: its rows when the fast axis is horizontal, else its
/// columns.
pub(crate) fn scan_lines_mut(z: &mut Array2<f64>, fast_axis: Axis) -> Vec<ArrayViewMut1<'_, f64>> {
    match fast_axis {
        Axis::Horizontal => z.rows_mut().into_iter().collect(),
        Axis::Vertical => z.columns_mut().into_iter().collect(),
    }
}

/// [`correct_lines`] without a copy (lines levelled in parallel).
pub fn correct_lines_in_place(out: &mut Array2<f64>, fast_axis: Axis, method: LineCorrection) {
    if method == LineCorrection::None {
        return;
    }
    let lines = scan_lines_mut(out, fast_axis);
    let taper = match lines.first() {
        Some(line) if method == LineCorrection::Tapered => line_taper(line.len()),
        _ => Vec::new(),
    };
    let mut levels: Vec<f64> = lines
        .into_par_iter()
        .filter_map(|line| level_line(line, method, &taper))
        .collect();
    let level = median(&mut levels);
    out.mapv_inplace(|v| v + level);
}

/// Subtracts one line's level (or straight line) as `method` says (`taper`: the tapered
/// level's weights); returns the level, or `None` when fewer than two pixels are finite.
fn level_line(mut line: ArrayViewMut1<f64>, method: LineCorrection, taper: &[f64]) -> Option<f64> {
    let finite: Vec<(f64, f64)> = line
        .iter()
        .enumerate()
        .filter(|(_, v)| v.is_finite())
        .map(|(i, v)| (i as f64, *v))
        .collect();
    if finite.len() < 2 {
        return None;
    }
    let level = match method {
        LineCorrection::None => return None,
        LineCorrection::Median | LineCorrection::Lattice => {
            let mut values: Vec<f64> = finite.iter().map(|p| p.1).collect();
            median(&mut values)
        }
        LineCorrection::Tapered => tapered_line_level_with(&line.to_vec(), taper)?,
        LineCorrection::Linear => {
            let (level, slope, centre) = straight_line(&finite);
            for (i, v) in line.iter_mut().enumerate() {
                *v -= slope * (i as f64 - centre);
            }
            level
        }
    };
    line.mapv_inplace(|v| v - level);
    Some(level)
}

/// Least-squares straight line through `(position, value)` points: its value at the mean
/// position, its slope, and that mean position.
fn straight_line(points: &[(f64, f64)]) -> (f64, f64, f64) {
    let n = points.len() as f64;
    let (sx, sy) = points
        .iter()
        .fold((0.0, 0.0), |(a, b), p| (a + p.0, b + p.1));
    let (mx, my) = (sx / n, sy / n);
    let (sxx, sxy) = points.iter().fold((0.0, 0.0), |(a, b), p| {
        (a + (p.0 - mx).powi(2), b + (p.0 - mx) * (p.1 - my))
    });
    let slope = if sxx > 0.0 { sxy / sxx } else { 0.0 };
    (my, slope, mx)
}

/// The median (0 for no values): the shared convention of [`dhct_numerics::robust::median`].
fn median(values: &mut [f64]) -> f64 {
    dhct_numerics::robust::median(values).unwrap_or(0.0)
}

/// Applies the chosen background removal.
pub fn remove_background(
    z: &Array2<f64>,
    background: Background,
    mask: Option<&Array2<bool>>,
) -> Result<Array2<f64>, FeatureError> {
    let mut out = z.clone();
    remove_background_in_place(&mut out, background, mask)?;
    Ok(out)
}

/// [`remove_background`] without a copy: `z` is replaced by its residual.
pub fn remove_background_in_place(
    z: &mut Array2<f64>,
    background: Background,
    mask: Option<&Array2<bool>>,
) -> Result<(), FeatureError> {
    match background {
        Background::None => Ok(()),
        Background::Plane => subtract_polynomial_in_place(z, 1, mask),
        Background::Polynomial(order) => subtract_polynomial_in_place(z, order, mask),
    }
}

/// `z` with the background removed (fitted where `mask` is true) and, for dark features,
/// negated, so every feature is a positive Gaussian on its local level. The feature finder
/// applies it after the line correction; the slices of `dhct-diagnose` apply it to the raw
/// image, keeping each line's level (levelling a line by its median mixes the features'
/// displacements into the level).
pub fn signed_flattened(
    z: &Array2<f64>,
    options: &FeatureOptions,
    mask: Option<&Array2<bool>>,
) -> Result<Array2<f64>, FeatureError> {
    let mut signed = z.clone();
    sign_flattened_in_place(&mut signed, options, mask)?;
    Ok(signed)
}

/// [`signed_flattened`] without a copy: `z` is replaced by the result.
pub fn sign_flattened_in_place(
    z: &mut Array2<f64>,
    options: &FeatureOptions,
    mask: Option<&Array2<bool>>,
) -> Result<(), FeatureError> {
    remove_background_in_place(z, options.background, mask)?;
    if options.polarity == Polarity::Dark {
        z.mapv_inplace(|v| -v);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_tilted_plane_is_removed_exactly_and_line_offsets_vanish() {
        let z = Array2::from_shape_fn((30, 40), |(r, c)| {
            1e-9 + 2e-11 * c as f64 - 3e-11 * r as f64
        });
        let flat = subtract_polynomial(&z, 1, None).unwrap();
        assert!(flat.iter().all(|v| v.abs() < 1e-20));
        let quadratic =
            z.mapv(|v| v * 1.0) + Array2::from_shape_fn((30, 40), |(r, _)| 1e-12 * (r * r) as f64);
        let flat = subtract_polynomial(&quadratic, 2, None).unwrap();
        assert!(flat.iter().all(|v| v.abs() < 1e-19));

        let striped = Array2::from_shape_fn((10, 8), |(r, c)| (r as f64) * 5.0 + (c % 2) as f64);
        let fixed = correct_lines(&striped, Axis::Horizontal, LineCorrection::Median);
        for row in fixed.rows() {
            assert!((row[0] - fixed[[0, 0]]).abs() < 1e-12);
        }
        assert!(subtract_polynomial(&z, 9, None).is_err());
        // Order 0 removes the mean; a mask keeps an outlier region out of the fit.
        let constant = subtract_polynomial(&Array2::from_elem((5, 7), 2.5), 0, None).unwrap();
        assert!(constant.iter().all(|v| v.abs() < 1e-15));
        let mut spoiled = z.clone();
        let mut mask = Array2::from_elem((30, 40), true);
        for r in 0..10 {
            for c in 0..10 {
                spoiled[[r, c]] += 1e-9;
                mask[[r, c]] = false;
            }
        }
        let flat = subtract_polynomial(&spoiled, 1, Some(&mask)).unwrap();
        assert!(
            flat.iter()
                .zip(mask.iter())
                .filter(|(_, m)| **m)
                .all(|(v, _)| v.abs() < 1e-20)
        );
    }
}
