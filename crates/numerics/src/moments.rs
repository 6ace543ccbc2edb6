//! Plain (non-robust) moments of point sets.

/// Root-mean-square length of the 2-D vectors `d` after removing their mean (one common
/// translation), in their unit; 0 for no vectors.
pub fn rms_about_mean(d: &[[f64; 2]]) -> f64 {
    if d.is_empty() {
        return 0.0;
    }
    let n = d.len() as f64;
    let mx = d.iter().map(|v| v[0]).sum::<f64>() / n;
    let my = d.iter().map(|v| v[1]).sum::<f64>() / n;
    let sum: f64 = d
        .iter()
        .map(|v| (v[0] - mx).powi(2) + (v[1] - my).powi(2))
        .sum();
    (sum / n).sqrt()
}

/// Root mean square of `values` about their mean, in their unit; 0 for no values.
pub fn rms_about_mean_1d(values: &[f64]) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n).sqrt()
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_common_translation_is_removed() {
        let d = [[1.0, 5.0], [3.0, 5.0]];
        assert_eq!(super::rms_about_mean(&d), 1.0);
        assert_eq!(super::rms_about_mean(&[]), 0.0);
        assert_eq!(super::rms_about_mean_1d(&[1.0, 3.0]), 1.0);
        assert_eq!(super::rms_about_mean_1d(&[]), 0.0);
    }
}
