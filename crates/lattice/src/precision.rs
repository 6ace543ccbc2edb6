//! The precision of the numbers in a lattice file, and the relative tolerance it allows
//! when shells, lengths and angles are compared (a file with 4-decimal vectors is not
//! exact to 1e-6).

use crate::neighbours::DEFAULT_SHELL_TOLERANCE;

/// The largest tolerance a file's precision can give: numbers rounded more coarsely than
/// about 1 part in 1000 make shells ambiguous, and a plane group whose metric they miss by
/// more is reported as inconsistent.
pub const MAX_FILE_TOLERANCE: f64 = 1e-3;

/// How many times the rounding error the tolerance allows (rounded components add up in
/// lengths, angles and site positions).
const ROUNDING_MARGIN: f64 = 4.0;

/// The place value of the last significant digit of `value` as written in its shortest
/// decimal form (2.1304 → 1e-4, 2.46 → 1e-2, 3 → 1); `None` for zero or non-finite values.
fn last_digit_place(value: f64) -> Option<f64> {
    if value == 0.0 || !value.is_finite() {
        return None;
    }
    let text = format!("{:e}", value.abs());
    let (mantissa, exponent) = text.split_once('e')?;
    let exponent: i32 = exponent.parse().ok()?;
    let decimals = mantissa.split_once('.').map_or(0, |(_, d)| d.len()) as i32;
    Some(10f64.powi(exponent - decimals))
}

/// The finest digit place among `values` (what the writer rounded to).
fn finest_place(values: impl IntoIterator<Item = f64>) -> Option<f64> {
    values
        .into_iter()
        .filter_map(last_digit_place)
        .min_by(f64::total_cmp)
}

/// The relative tolerance of a lattice given by vector components `vectors` (any one unit)
/// and fractional site positions `fractions`: four times the relative rounding error of
/// its finest digits (half a unit in the last place), between 1e-6 and
/// [`MAX_FILE_TOLERANCE`].
pub(crate) fn file_tolerance(vectors: [[f64; 2]; 2], fractions: &[[f64; 2]]) -> f64 {
    let length = |v: [f64; 2]| v[0].hypot(v[1]);
    let (shortest, sum) = (
        length(vectors[0]).min(length(vectors[1])),
        length(vectors[0]) + length(vectors[1]),
    );
    let mut relative: f64 = 0.0;
    if let Some(place) = finest_place(vectors.iter().flatten().copied()) {
        relative = relative.max(0.5 * place / shortest);
    }
    if let Some(place) = finest_place(fractions.iter().flatten().copied()) {
        relative = relative.max(0.5 * place * sum / shortest);
    }
    (ROUNDING_MARGIN * relative).clamp(DEFAULT_SHELL_TOLERANCE, MAX_FILE_TOLERANCE)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_last_digit_is_read_from_the_shortest_form() {
        assert_eq!(last_digit_place(2.1304), Some(1e-4));
        assert_eq!(last_digit_place(2.46), Some(1e-2));
        assert_eq!(last_digit_place(-3.0), Some(1.0));
        assert!((last_digit_place(1.2304e-10).unwrap() - 1e-14).abs() < 1e-28);
        assert_eq!(last_digit_place(0.0), None);
    }

    #[test]
    fn four_decimal_vectors_get_a_tolerance_near_1e_4() {
        let t = file_tolerance([[2.46, 0.0], [1.23, 2.1304]], &[[0.0, 0.0]]);
        assert!((t - 4.0 * 0.5e-4 / 2.46).abs() < 1e-8, "{t}");
        let exact = file_tolerance([[2.46, 0.0], [1.23, 2.130_422_493_309_719]], &[[0.0, 0.0]]);
        assert!(exact < 1e-6 * 1.01, "{exact}");
        // Coarse numbers are capped.
        assert_eq!(
            file_tolerance([[3.0, 0.0], [0.0, 3.0]], &[]),
            MAX_FILE_TOLERANCE
        );
    }
}
