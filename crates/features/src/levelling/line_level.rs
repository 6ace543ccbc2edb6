//! The level of one scan line from a median weighted towards the line's middle.
//!
//! A line crosses the lattice's rows at some angle, and its median holds part of the
//! lattice that depends on where it crosses them; subtracting it imprints the row period on
//! the image, and every fitted centre moves with it (a lattice-locked pattern across the
//! lines that a diagnosis can read as a vibration). Part of that comes from the line's
//! ends, where fast-scan hysteresis compresses the lattice and a row is cut part-way. The
//! tapered level is the median of the line's values weighted by a window that falls
//! smoothly to zero at both ends (Hann, `sin²(π·u)` for `u` the position along the line in
//! (0, 1)). A line offset (one constant) is still removed exactly, and the estimate keeps
//! the median's robustness to spikes, adsorbates and steps.
//!
//! Measured (2026-11-27; `docs/diagnose.md`), so it is an option and not the default: on
//! rendered graphite with another simulator's base model (384², 5 pm line offsets, 16
//! effect-free seeds) the diagnosis finds no gap and names nothing on 12/16 with it against
//! 3/12 with the plain median, and the Pb/Pt(111) file's rms deviation is 104.4 pm against
//! 106.6; but on dhct's own simulator (rows at 23° to the lines) its levels carry as much of
//! the row period as the median's (0.23 against 0.17 pm), and rows within a few degrees of
//! the lines are levelled away with the offsets by any level of one line (4 of the 16
//! seeds fail either way).

/// The Hann weight of position `index` on a line of `length` pixels.
fn taper(index: usize, length: usize) -> f64 {
    let u = (index as f64 + 0.5) / length as f64;
    (std::f64::consts::PI * u).sin().powi(2)
}

/// The Hann weights of a line of `length` pixels (what [`tapered_line_level_with`] takes).
pub fn line_taper(length: usize) -> Vec<f64> {
    (0..length).map(|i| taper(i, length)).collect()
}

/// The tapered level of one line: `values[i]` is the pixel at position `i` of a line of
/// `values.len()` pixels (non-finite pixels are skipped but keep their place). `None` when
/// fewer than two pixels are finite.
pub fn tapered_line_level(values: &[f64]) -> Option<f64> {
    tapered_line_level_with(values, &line_taper(values.len()))
}

/// [`tapered_line_level`] with the line's weights `taper` ([`line_taper`]) computed once
/// for many lines of one length: the value at which the weights of the values below and
/// above it balance (the weighted median).
///
/// # Panics
/// If `taper` and `values` differ in length.
pub fn tapered_line_level_with(values: &[f64], taper: &[f64]) -> Option<f64> {
    assert_eq!(values.len(), taper.len(), "one weight per pixel");
    let mut pairs: Vec<(f64, f64)> = values
        .iter()
        .zip(taper)
        .filter(|(v, _)| v.is_finite())
        .map(|(&v, &w)| (v, w))
        .collect();
    if pairs.len() < 2 {
        return None;
    }
    pairs.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
    let half = 0.5 * pairs.iter().map(|p| p.1).sum::<f64>();
    let mut below = 0.0;
    for &(value, weight) in &pairs {
        below += weight;
        if below >= half {
            return Some(value);
        }
    }
    pairs.last().map(|p| p.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A line across a row set at `periods` periods per line, phase `phase`, the first
    /// part compressed as fast-scan hysteresis does (`S − 1 ∝ (1 − u)⁴`).
    fn lattice_line(n: usize, periods: f64, phase: f64) -> Vec<f64> {
        (0..n)
            .map(|i| {
                let u = i as f64 / n as f64;
                let position = u - 0.1 * (1.0 - u).powi(5);
                let x = std::f64::consts::TAU * periods * position + phase;
                // Sharp atoms: a cosine's exponential (many harmonics).
                (2.0 * x.cos()).exp()
            })
            .collect()
    }

    #[test]
    fn an_offset_is_removed_exactly_and_a_spike_does_not_set_the_level() {
        let line = lattice_line(256, 9.7, 0.3);
        let base = tapered_line_level(&line).unwrap();
        let shifted: Vec<f64> = line.iter().map(|v| v + 5.0).collect();
        assert!((tapered_line_level(&shifted).unwrap() - base - 5.0).abs() < 1e-9);
        let mut spiked = line.clone();
        spiked[128] = 1e4;
        spiked[129] = 1e4;
        spiked[40] = f64::NAN;
        let level = tapered_line_level(&spiked).unwrap();
        // Two pixels of the largest weight move the balance point by two ranks, not by the
        // spikes' height (the mean would move by 78).
        assert!((level - base).abs() < 0.2, "{level} vs {base}");
        assert_eq!(tapered_line_level(&[f64::NAN, 1.0]), None);
    }
}
