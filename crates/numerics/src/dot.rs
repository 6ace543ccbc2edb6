//! The dot product of two slices, the hot loop of every normal-equation product: summed in
//! eight interleaved partial sums, so that the additions do not wait on one another and the
//! compiler may pack them into vector registers (a single running sum is bound by the
//! latency of one addition after another: several times slower on long columns).

/// `Σ a_k·b_k` over the shorter of the two slices. The partial sums reorder the additions:
/// the result agrees with the sequential sum to rounding, and is the same on every run.
pub fn dot(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let (chunks_a, chunks_b) = (a.chunks_exact(LANES), b.chunks_exact(LANES));
    let tail: f64 = chunks_a
        .remainder()
        .iter()
        .zip(chunks_b.remainder())
        .map(|(x, y)| x * y)
        .sum();
    let mut partial = [0.0f64; LANES];
    for (x, y) in chunks_a.zip(chunks_b) {
        for k in 0..LANES {
            partial[k] += x[k] * y[k];
        }
    }
    let [p0, p1, p2, p3, p4, p5, p6, p7] = partial;
    ((p0 + p4) + (p1 + p5)) + ((p2 + p6) + (p3 + p7)) + tail
}

/// Partial sums of [`dot`].
const LANES: usize = 8;

#[cfg(test)]
mod tests {
    use super::*;

    /// Every length, with and without a tail past the last full group, and slices of
    /// unequal length (the shorter one counts).
    #[test]
    fn the_dot_product_is_the_sum_of_the_products_to_rounding() {
        for n in 0..40 {
            let a: Vec<f64> = (0..n).map(|k| ((k * 7 + 3) % 11) as f64 - 4.5).collect();
            let b: Vec<f64> = (0..n + 3)
                .map(|k| 0.25 * ((k * 5) % 9) as f64 - 1.0)
                .collect();
            let sequential: f64 = a.iter().zip(&b).map(|(x, y)| x * y).sum();
            let scale: f64 = a.iter().zip(&b).map(|(x, y)| (x * y).abs()).sum();
            assert!(
                (dot(&a, &b) - sequential).abs() <= 1e-14 * scale.max(1.0),
                "n = {n}"
            );
            assert_eq!(dot(&a, &b), dot(&b, &a), "n = {n}");
        }
        assert_eq!(dot(&[], &[1.0]), 0.0);
    }
}
