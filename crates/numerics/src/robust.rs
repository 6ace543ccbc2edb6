//! Robust statistics with one convention everywhere: the median of an even count is the
//! mean of the two middle values, the MAD scale is 1.4826 × the median absolute deviation
//! (the standard deviation for Gaussian data), and an empty input has no median (`None`).

/// 1.4826: the MAD of a normal distribution is 0.6745 σ.
pub const MAD_TO_SIGMA: f64 = 1.482_602_218_505_602;

/// The Huber tuning constant (95 % efficiency for Gaussian data), in units of σ.
pub const HUBER_K: f64 = 1.345;

/// The median of `values` (reordered in place, O(n)); the mean of the two middle values for
/// an even count; `None` when empty. Values are ordered by [`f64::total_cmp`], so pass finite
/// values (see [`finite_median`]).
pub fn median(values: &mut [f64]) -> Option<f64> {
    let n = values.len();
    if n == 0 {
        return None;
    }
    let (below, upper, _) = values.select_nth_unstable_by(n / 2, f64::total_cmp);
    let upper = *upper;
    if n % 2 == 1 {
        Some(upper)
    } else {
        // The lower middle value is the largest of the lower half.
        let lower = below.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        Some(0.5 * (lower + upper))
    }
}

/// The median of the finite values of `values`, `None` when there are none.
pub fn finite_median(values: impl IntoIterator<Item = f64>) -> Option<f64> {
    let mut finite: Vec<f64> = values.into_iter().filter(|v| v.is_finite()).collect();
    median(&mut finite)
}

/// Robust standard deviation of the finite values: [`MAD_TO_SIGMA`] × the median absolute
/// deviation from their median; `None` when there are none.
pub fn mad_sigma(values: &[f64]) -> Option<f64> {
    let centre = finite_median(values.iter().copied())?;
    mad_sigma_about(values, centre)
}

/// [`MAD_TO_SIGMA`] × the median of `|v − centre|` over the finite values: the robust scale
/// of residuals whose centre is known (e.g. zero for fit residuals).
pub fn mad_sigma_about(values: &[f64], centre: f64) -> Option<f64> {
    finite_median(values.iter().map(|v| (v - centre).abs())).map(|m| MAD_TO_SIGMA * m)
}

/// Huber weights for residuals `r` with scale `sigma`: 1 within [`HUBER_K`]·σ, `k/|r|` beyond.
pub fn huber_weights(r: &[f64], sigma: f64) -> Vec<f64> {
    let k = HUBER_K * sigma;
    r.iter()
        .map(|r| if r.abs() <= k { 1.0 } else { k / r.abs() })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn median_of_odd_and_even_counts() {
        assert_eq!(median(&mut []), None);
        assert_eq!(median(&mut [3.0]), Some(3.0));
        assert_eq!(median(&mut [5.0, 1.0, 3.0]), Some(3.0));
        assert_eq!(median(&mut [4.0, 1.0, 3.0, 2.0]), Some(2.5));
        assert_eq!(
            finite_median([f64::NAN, 1.0, f64::INFINITY, 3.0]),
            Some(2.0)
        );
        assert_eq!(finite_median([f64::NAN]), None);
    }

    #[test]
    fn mad_sigma_is_the_standard_deviation_of_gaussian_quantiles() {
        // Evenly spaced quantiles of N(0, 2²): the MAD scale recovers σ = 2.
        let n = 20_001;
        let values: Vec<f64> = (1..=n)
            .map(|i| 2.0 * normal_quantile(i as f64 / (n + 1) as f64))
            .collect();
        let sigma = mad_sigma(&values).unwrap();
        assert!((sigma - 2.0).abs() < 2e-3, "{sigma}");
        // About a known centre: shifted data gives a larger scale.
        assert!(mad_sigma_about(&values, 1.0).unwrap() > 2.2);
    }

    #[test]
    fn huber_weights_downweight_outliers_only() {
        let w = huber_weights(&[0.5, -1.0, 10.0], 1.0);
        assert_eq!(&w[..2], &[1.0, 1.0]);
        assert!((w[2] - 0.1345).abs() < 1e-12);
    }

    /// Inverse of the standard normal CDF by bisection (test helper).
    fn normal_quantile(p: f64) -> f64 {
        let cdf = |x: f64| 1.0 - crate::special::normal_upper_tail(x);
        let (mut lo, mut hi) = (-10.0, 10.0);
        for _ in 0..100 {
            let mid = 0.5 * (lo + hi);
            if cdf(mid) < p { lo = mid } else { hi = mid }
        }
        0.5 * (lo + hi)
    }

    proptest! {
        #[test]
        fn median_splits_the_values_in_half(mut v in proptest::collection::vec(-1e6f64..1e6, 1..200)) {
            let m = median(&mut v.clone()).unwrap();
            let below = v.iter().filter(|x| **x < m).count();
            let above = v.iter().filter(|x| **x > m).count();
            prop_assert!(below <= v.len() / 2 && above <= v.len() / 2);
            v.sort_by(f64::total_cmp);
            prop_assert!(m >= v[0] && m <= v[v.len() - 1]);
        }
    }
}
