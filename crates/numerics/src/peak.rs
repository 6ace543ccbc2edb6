//! Sub-sample position of a sampled peak.

/// The vertex of the parabola through three equally spaced samples `before`, `centre`,
/// `after` of a peak at `centre`, in samples from it: in −½…½, and 0 unless the parabola
/// opens downwards (the centre is no strict maximum of a curved peak).
///
/// ```
/// use dhct_numerics::peak::vertex;
///
/// // Samples of −(x − 0.2)² at −1, 0 and 1.
/// assert!((vertex(-1.44, -0.04, -0.64) - 0.2).abs() < 1e-12);
/// assert_eq!(vertex(1.0, 1.0, 1.0), 0.0);
/// ```
pub fn vertex(before: f64, centre: f64, after: f64) -> f64 {
    let curvature = before - 2.0 * centre + after;
    if curvature < 0.0 {
        (0.5 * (before - after) / curvature).clamp(-0.5, 0.5)
    } else {
        0.0
    }
}
