//! Periodic noise in time: peaks no lattice makes.
//!
//! Interference at a fixed frequency in time (mains hum and its harmonics, a pump, a
//! vibration) adds a wave along every scan line at the same spatial frequency along the
//! fast axis, `f · pixel period` cycles per pixel, with a phase that wanders from line to
//! line. Its power lands in one *column* of the spectrum (one frequency along the fast
//! axis) at scattered frequencies along the slow axis: 32 sharp peaks at 183 bins in the
//! Createc Cu(111) retrace. A lattice's reflections share a frequency along the fast axis
//! only where a row of its reciprocal lattice runs along the slow axis, and then the
//! lattice indexes them all. So a column of at least [`MIN_COLUMN_PEAKS`] peaks of which
//! the fitted lattice indexes fewer than half is periodic noise, and none of its peaks may
//! refine the lattice: at high orders a few of them land near reflections by chance (a
//! column of 32 holds 5–10 such) and pulled that retrace's lattice 2.4 % short.

use dhct_scan::Axis;
use serde::{Deserialize, Serialize};

use crate::spectrum::Peak;

/// Fewest peaks in one column that can be called periodic noise.
pub const MIN_COLUMN_PEAKS: usize = 4;

/// A peak the lattice indexes in a column of noise is kept as a reflection when its power
/// is at least this many times the strongest unindexed peak's there.
const STANDS_OUT: f64 = 2.0;

/// Peaks within this many bins of each other along the fast axis share a column.
const COLUMN_WIDTH_BINS: f64 = 0.5;

/// Periodic noise in time that an image's spectrum shows.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PeriodicNoise {
    /// Its frequency in time, hertz (from the pixel period the file gives).
    pub frequency_hz: f64,
    /// Its period along the fast axis, metres in file units.
    pub period_m: f64,
    /// How many peaks it put in the spectrum.
    pub peaks: usize,
    /// Its strongest peak's power over the spectrum's strongest peak.
    pub relative_power: f64,
}

/// One column of periodic noise in a spectrum (bins of that spectrum).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct NoiseColumn {
    /// Its frequency along the fast axis, bins (cycles across the padded spectrum).
    pub fast_bins: f64,
    /// How many peaks it put in the spectrum.
    pub peaks: usize,
    /// Its strongest peak's power over the spectrum's strongest peak.
    pub relative_power: f64,
}

/// A peak's frequency along the fast axis (≥ 0), bins.
fn fast_frequency(peak: &Peak, fast_axis: Axis) -> f64 {
    match fast_axis {
        Axis::Horizontal => peak.k[0],
        Axis::Vertical => peak.k[1],
    }
    .abs()
}

/// The columns of `peaks` (each the peaks' positions in `peaks`): at least
/// [`MIN_COLUMN_PEAKS`] peaks whose frequencies along the fast axis lie within
/// [`COLUMN_WIDTH_BINS`] of the column's lowest.
fn columns(peaks: &[Peak], fast_axis: Axis) -> Vec<Vec<usize>> {
    let mut order: Vec<usize> = (0..peaks.len()).collect();
    let fast = |i: usize| fast_frequency(&peaks[i], fast_axis);
    order.sort_by(|&a, &b| fast(a).total_cmp(&fast(b)));
    let mut found = Vec::new();
    let mut start = 0;
    while start < order.len() {
        let first = fast(order[start]);
        let end = start
            + order[start..]
                .iter()
                .take_while(|&&i| fast(i) - first <= COLUMN_WIDTH_BINS)
                .count();
        if end - start >= MIN_COLUMN_PEAKS {
            found.push(order[start..end].to_vec());
        }
        start = end;
    }
    found
}

/// Whether `index` is one of the lattice's fundamental reflections (`|h|, |k| ≤ 1`).
fn fundamental(index: [i64; 2]) -> bool {
    index[0].abs() <= 1 && index[1].abs() <= 1
}

/// The peaks of a noise `column` that are noise, and the strongest unindexed peak's power
/// there: a reflection inside the noise stands out of it (by [`STANDS_OUT`]) at a frequency
/// no higher than `reach`, where the lattice shows reflections elsewhere; a noise peak that
/// the lattice indexes by chance does neither, as a rule.
fn noise_members(
    column: Vec<usize>,
    peaks: &[Peak],
    indices: &[Option<[i64; 2]>],
    reach: f64,
) -> (Vec<usize>, f64) {
    let noise_power = column
        .iter()
        .filter(|&&i| indices[i].is_none())
        .map(|&i| peaks[i].power)
        .fold(0.0, f64::max);
    let reflection = |i: usize| {
        indices[i].is_some()
            && peaks[i].power >= STANDS_OUT * noise_power
            && peaks[i].k[0].hypot(peaks[i].k[1]) <= reach
    };
    let members = column.into_iter().filter(|&i| !reflection(i)).collect();
    (members, noise_power)
}

/// The periodic noise among `peaks` (strongest first) under a lattice that indexes them
/// as `indices`: the columns of which it indexes fewer than half and none as a fundamental
/// reflection (the peaks a strong reflection's smear puts beside it make a column too),
/// and for each peak whether it is noise (in such a column, and not a reflection:
/// [`noise_members`], with `reach` the highest frequency of a reflection the lattice
/// indexes outside every column).
pub(crate) fn periodic_noise(
    peaks: &[Peak],
    indices: &[Option<[i64; 2]>],
    fast_axis: Axis,
) -> (Vec<NoiseColumn>, Vec<bool>) {
    let strongest = peaks
        .first()
        .map_or(f64::MIN_POSITIVE, |p| p.power)
        .max(f64::MIN_POSITIVE);
    let columns = columns(peaks, fast_axis);
    let mut in_column = vec![false; peaks.len()];
    for &i in columns.iter().flatten() {
        in_column[i] = true;
    }
    let reach = peaks
        .iter()
        .zip(indices)
        .zip(&in_column)
        .filter(|((_, index), column)| index.is_some() && !**column)
        .map(|((p, _), _)| p.k[0].hypot(p.k[1]))
        .fold(0.0, f64::max);
    let is_noise = |column: &Vec<usize>| {
        let indexed = column.iter().filter(|&&i| indices[i].is_some()).count();
        2 * indexed < column.len() && !column.iter().any(|&i| indices[i].is_some_and(fundamental))
    };
    let mut in_noise = vec![false; peaks.len()];
    let mut noise: Vec<NoiseColumn> = Vec::new();
    for column in columns.into_iter().filter(is_noise) {
        let (members, noise_power) = noise_members(column, peaks, indices, reach);
        for &i in &members {
            in_noise[i] = true;
        }
        noise.push(NoiseColumn {
            fast_bins: members
                .iter()
                .map(|&i| fast_frequency(&peaks[i], fast_axis))
                .sum::<f64>()
                / members.len() as f64,
            peaks: members.len(),
            relative_power: noise_power / strongest,
        });
    }
    noise.sort_by(|a, b| b.relative_power.total_cmp(&a.relative_power));
    (noise, in_noise)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn peak(kx: f64, ky: f64, power: f64) -> Peak {
        Peak::at(kx, ky, power)
    }

    #[test]
    fn a_column_the_lattice_does_not_index_is_noise_and_one_it_indexes_is_not() {
        // A square lattice with rows along the slow axis: a column at kx = 16 with
        // reflections every 16 bins along ky, all indexed; and interference at
        // kx = 183.4, scattered, two of its eight peaks indexed by chance.
        let mut peaks = vec![peak(0.0, 16.0, 10.0)];
        let mut indices = vec![Some([0, 1])];
        for (j, ky) in [-32.0, -16.0, 0.0, 16.0, 32.0].into_iter().enumerate() {
            peaks.push(peak(16.0, ky, 1.0));
            indices.push(Some([1, j as i64 - 2]));
        }
        for (j, ky) in [-75.3, -44.9, -51.9, -124.0, -32.8, 3.0, -109.4, -18.0]
            .into_iter()
            .enumerate()
        {
            peaks.push(peak(183.4 + 0.01 * (j as f64), ky, 0.5));
            indices.push((j < 2).then_some([11, j as i64]));
        }
        let (noise, in_noise) = periodic_noise(&peaks, &indices, Axis::Horizontal);
        assert_eq!(noise.len(), 1, "{noise:?}");
        assert_eq!(noise[0].peaks, 8);
        assert!((noise[0].fast_bins - 183.435).abs() < 1e-9, "{noise:?}");
        assert!((noise[0].relative_power - 0.05).abs() < 1e-12);
        assert_eq!(in_noise.iter().filter(|&&n| n).count(), 8);
        assert!(in_noise[..6].iter().all(|&n| !n));
        // Read with y as the fast axis there is no column at all.
        assert!(
            periodic_noise(&peaks, &indices, Axis::Vertical)
                .0
                .is_empty()
        );
    }

    #[test]
    fn a_column_holding_a_fundamental_reflection_is_the_lattice_s() {
        // The smear beside a strong reflection: unindexed peaks at its fast frequency.
        let peaks = [
            peak(8.72, 16.02, 10.0),
            peak(18.2, 0.5, 9.0),
            peak(8.93, 20.05, 0.1),
            peak(9.15, -70.8, 0.1),
            peak(8.80, 33.0, 0.1),
        ];
        let indices = [Some([1, 1]), Some([1, 0]), None, None, None];
        let (noise, in_noise) = periodic_noise(&peaks, &indices, Axis::Horizontal);
        assert!(noise.is_empty(), "{noise:?}");
        assert!(in_noise.iter().all(|&n| !n));
    }

    #[test]
    fn a_reflection_standing_out_of_a_noise_column_is_kept() {
        // Line artefacts scattered at 4 bins, and the lattice's (-2, 3) among them, four
        // times stronger than any of them (the DCA3Cu2 MOF image).
        let mut peaks = vec![
            peak(26.6, 6.9, 10.0),
            peak(19.0, -20.8, 10.0),
            peak(22.8, -97.0, 1.0),
        ];
        let mut indices = vec![Some([1, 0]), Some([0, 1]), Some([-2, 4])];
        for (j, ky) in [60.8, -126.0, -65.7, -58.5, 56.0].into_iter().enumerate() {
            peaks.push(peak(3.9 + 0.05 * j as f64, ky, 0.8));
            indices.push(None);
        }
        peaks.push(peak(3.96, -76.2, 3.4));
        indices.push(Some([-2, 3]));
        let (noise, in_noise) = periodic_noise(&peaks, &indices, Axis::Horizontal);
        assert_eq!(noise.len(), 1, "{noise:?}");
        assert_eq!(noise[0].peaks, 5);
        assert!(!in_noise[8]);
        assert_eq!(in_noise.iter().filter(|&&n| n).count(), 5);
        // Beyond every reflection seen elsewhere it is taken for noise.
        let (_, in_noise) = periodic_noise(
            &peaks[..2]
                .iter()
                .chain(&peaks[3..])
                .copied()
                .collect::<Vec<_>>(),
            &[&indices[..2], &indices[3..]].concat(),
            Axis::Horizontal,
        );
        assert_eq!(in_noise.iter().filter(|&&n| n).count(), 6);
    }

    #[test]
    fn a_column_on_a_vertical_fast_axis_is_a_row_of_the_spectrum() {
        // The half plane stores some of its peaks with both signs flipped.
        let mut peaks = vec![peak(16.0, 0.0, 10.0), peak(8.0, 14.0, 10.0)];
        for (kx, sign) in [(5.3, 1.0), (41.0, 1.0), (77.7, -1.0), (12.9, -1.0)] {
            peaks.push(peak(kx, sign * 150.2, 0.5));
        }
        let indices = [vec![Some([1, 0]), Some([0, 1])], vec![None; 4]].concat();
        let (noise, in_noise) = periodic_noise(&peaks, &indices, Axis::Vertical);
        assert_eq!(noise.len(), 1, "{noise:?}");
        assert_eq!(in_noise, [false, false, true, true, true, true]);
    }
}
