//! Watershed segmentation of the correlation map into one region per peak.
//!
//! This is the rain-falling (steepest-ascent) watershed: every pixel above the threshold
//! drains to its highest 8-neighbour, and the pixels that drain to the same local maximum
//! form one basin. Ties are broken by pixel index, so the order is strict, plateaus drain
//! to a single maximum and no cycles can form. It runs in O(pixels) and holds one `u32` per
//! pixel (so an image must have fewer than [`MAX_WATERSHED_PIXELS`] pixels).

use ndarray::Array2;

/// One watershed basin: the pixels draining to one maximum.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Region {
    /// Row-major index of the basin's maximum.
    pub peak: usize,
    /// Number of pixels in the basin.
    pub area: usize,
}

/// The label of a pixel at or below the threshold in [`basin_labels`].
pub const NO_BASIN: u32 = u32::MAX;

/// Largest image (pixels) the segmentation takes: labels are `u32` with one bit spare.
pub const MAX_WATERSHED_PIXELS: usize = 1 << 31;

/// Splits the pixels of `map` with value `> threshold` into basins of its local maxima,
/// in the order of their peaks (row-major). Panics if `map` has more than
/// [`MAX_WATERSHED_PIXELS`] pixels.
pub fn watershed_regions(map: &Array2<f64>, threshold: f64) -> Vec<Region> {
    let (labels, peaks) = basin_labels(map, threshold);
    let mut regions: Vec<Region> = peaks
        .into_iter()
        .map(|peak| Region { peak, area: 0 })
        .collect();
    for &label in labels.iter().filter(|&&l| l != NO_BASIN) {
        regions[label as usize].area += 1;
    }
    regions
}

/// Each pixel's basin (an index into the returned peaks, row-major order; [`NO_BASIN`]
/// at or below `threshold`) and each basin's peak (row-major index).
pub fn basin_labels(map: &Array2<f64>, threshold: f64) -> (Vec<u32>, Vec<usize>) {
    let (h, w) = map.dim();
    assert!(
        h * w < MAX_WATERSHED_PIXELS,
        "watershed of {h} x {w} px: at most {MAX_WATERSHED_PIXELS} px"
    );
    let standard = map.as_standard_layout();
    let values = standard.as_slice().unwrap_or_default();
    let mut labels = steepest_neighbours(values, (h, w), threshold);
    let peaks = label_roots(&mut labels);
    (labels, peaks)
}

/// Each pixel's highest 8-neighbour (itself at a maximum; [`NO_BASIN`] at or below
/// `threshold`), as row-major indices.
fn steepest_neighbours(values: &[f64], (h, w): (usize, usize), threshold: f64) -> Vec<u32> {
    // Strict order: by value, ties by index.
    let higher = |a: usize, b: usize| values[a] > values[b] || (values[a] == values[b] && a > b);
    let mut parent = vec![NO_BASIN; h * w];
    let offsets: [isize; 8] = [
        -(w as isize) - 1,
        -(w as isize),
        -(w as isize) + 1,
        -1,
        1,
        w as isize - 1,
        w as isize,
        w as isize + 1,
    ];
    for r in 0..h {
        let interior_row = r > 0 && r + 1 < h;
        for c in 0..w {
            let i = r * w + c;
            if values[i] <= threshold {
                continue;
            }
            let mut best = i;
            if interior_row && c > 0 && c + 1 < w {
                for offset in offsets {
                    let j = (i as isize + offset) as usize;
                    if higher(j, best) {
                        best = j;
                    }
                }
            } else {
                for (rr, cc) in neighbours_at_border((r, c), (h, w)) {
                    let j = rr * w + cc;
                    if higher(j, best) {
                        best = j;
                    }
                }
            }
            parent[i] = best as u32;
        }
    }
    parent
}

/// The in-image 8-neighbours of `(r, c)`.
fn neighbours_at_border(
    (r, c): (usize, usize),
    (h, w): (usize, usize),
) -> impl Iterator<Item = (usize, usize)> {
    (-1i64..=1)
        .flat_map(|dr| (-1i64..=1).map(move |dc| (dr, dc)))
        .filter(|&d| d != (0, 0))
        .map(move |(dr, dc)| (r as i64 + dr, c as i64 + dc))
        .filter(move |&(rr, cc)| rr >= 0 && cc >= 0 && rr < h as i64 && cc < w as i64)
        .map(|(rr, cc)| (rr as usize, cc as usize))
}

/// Replaces, in place, each pixel's steepest neighbour by its basin's label and returns
/// each basin's peak. Roots are labelled first (row-major, with a flag bit), then every
/// pixel follows its path to its root, compressing the path as it goes.
fn label_roots(parent: &mut [u32]) -> Vec<usize> {
    const ROOT: u32 = 1 << 31;
    let mut peaks = Vec::new();
    for (i, p) in parent.iter_mut().enumerate() {
        if *p == i as u32 {
            *p = ROOT | peaks.len() as u32;
            peaks.push(i);
        }
    }
    let mut path = Vec::new();
    for start in 0..parent.len() {
        let mut i = start;
        while parent[i] != NO_BASIN && parent[i] & ROOT == 0 {
            path.push(i);
            i = parent[i] as usize;
        }
        let label = parent[i];
        for p in path.drain(..) {
            parent[p] = label;
        }
    }
    for label in parent.iter_mut().filter(|l| **l != NO_BASIN) {
        *label &= !ROOT;
    }
    peaks
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn two_bumps_give_two_basins_split_at_the_saddle() {
        let map = Array2::from_shape_fn((9, 20), |(r, c)| {
            let bump =
                |cx: f64| (-((c as f64 - cx).powi(2) + (r as f64 - 4.0).powi(2)) / 8.0).exp();
            bump(5.0) + 0.9 * bump(14.0)
        });
        let regions = watershed_regions(&map, 0.1);
        assert_eq!(regions.len(), 2);
        let peaks: Vec<_> = regions.iter().map(|r| (r.peak / 20, r.peak % 20)).collect();
        assert_eq!(peaks, vec![(4, 5), (4, 14)]);
        let (labels, _) = basin_labels(&map, 0.1);
        for (i, &label) in labels.iter().enumerate() {
            if label != NO_BASIN {
                // Every pixel is on its peak's side of the saddle near column 9-10.
                assert_eq!((i % 20) < 10, label == 0, "pixel {i} in basin {label}");
            }
        }
        let area: usize = regions.iter().map(|r| r.area).sum();
        assert_eq!(area, map.iter().filter(|&&v| v > 0.1).count());
    }

    #[test]
    fn plateaus_form_one_region_and_below_threshold_pixels_none() {
        let mut map = Array2::zeros((5, 5));
        for r in 1..4 {
            for c in 1..4 {
                map[[r, c]] = 0.5;
            }
        }
        let regions = watershed_regions(&map, 0.1);
        assert_eq!(regions.len(), 1);
        assert_eq!(regions[0].area, 9);
        assert!(watershed_regions(&Array2::zeros((4, 4)), 0.1).is_empty());
    }

    #[test]
    fn a_long_ascending_chain_is_one_basin() {
        // A ramp: every pixel drains towards the last; path compression must label all.
        let map = Array2::from_shape_fn((3, 50), |(r, c)| (r * 50 + c) as f64);
        let regions = watershed_regions(&map, -1.0);
        assert_eq!(
            regions,
            vec![Region {
                peak: 149,
                area: 150
            }]
        );
    }
}
