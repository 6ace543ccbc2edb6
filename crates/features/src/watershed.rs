//! Watershed segmentation of the correlation map into one region per peak.
//!
//! This is the rain-falling (steepest-ascent) watershed: every pixel above the threshold
//! drains to its highest 8-neighbour, and the pixels that drain to the same local maximum
//! form one basin. Ties are broken by pixel index, so the order is strict, plateaus drain
//! to a single maximum and no cycles can form. It runs in O(pixels).

use ndarray::Array2;

/// One watershed basin: the pixels (row-major indices) draining to one maximum.
#[derive(Debug, Clone, PartialEq)]
pub struct Region {
    /// Row-major index of the basin's maximum.
    pub peak: usize,
    /// Row-major indices of the basin's pixels, ascending.
    pub pixels: Vec<usize>,
}

/// Splits the pixels of `map` with value `> threshold` into basins of its local maxima.
pub fn watershed_regions(map: &Array2<f64>, threshold: f64) -> Vec<Region> {
    let (h, w) = map.dim();
    let values = map
        .as_slice()
        .map(|s| s.to_vec())
        .unwrap_or_else(|| map.iter().copied().collect());
    let above = |i: usize| values[i] > threshold;
    let higher = |a: usize, b: usize| {
        // Strict total order: value first, then index.
        values[a] > values[b] || (values[a] == values[b] && a > b)
    };
    const NONE: usize = usize::MAX;
    // Each above-threshold pixel's steepest higher neighbour, or itself if it is a maximum.
    let mut parent = vec![NONE; h * w];
    for r in 0..h {
        for c in 0..w {
            let i = r * w + c;
            if !above(i) {
                continue;
            }
            let mut best = i;
            for dr in -1i64..=1 {
                for dc in -1i64..=1 {
                    let (rr, cc) = (r as i64 + dr, c as i64 + dc);
                    if (dr == 0 && dc == 0) || rr < 0 || cc < 0 || rr >= h as i64 || cc >= w as i64
                    {
                        continue;
                    }
                    let j = rr as usize * w + cc as usize;
                    if higher(j, best) {
                        best = j;
                    }
                }
            }
            parent[i] = best;
        }
    }
    // Resolve every pixel to its maximum, compressing paths as we go.
    let mut root = vec![NONE; h * w];
    let mut path = Vec::new();
    for start in 0..h * w {
        if parent[start] == NONE || root[start] != NONE {
            continue;
        }
        let mut i = start;
        while root[i] == NONE && parent[i] != i {
            path.push(i);
            i = parent[i];
        }
        let top = if root[i] != NONE { root[i] } else { i };
        root[i] = top;
        for p in path.drain(..) {
            root[p] = top;
        }
    }
    // Group pixels by maximum, in order of the maxima's first appearance.
    let mut region_of_peak = std::collections::HashMap::new();
    let mut regions: Vec<Region> = Vec::new();
    for (i, &top) in root.iter().enumerate() {
        if top == NONE {
            continue;
        }
        let index = *region_of_peak.entry(top).or_insert_with(|| {
            regions.push(Region {
                peak: top,
                pixels: Vec::new(),
            });
            regions.len() - 1
        });
        regions[index].pixels.push(i);
    }
    regions
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
        assert!(peaks.contains(&(4, 5)) && peaks.contains(&(4, 14)));
        for region in &regions {
            let cols: Vec<_> = region.pixels.iter().map(|p| p % 20).collect();
            let peak_col = region.peak % 20;
            // Every pixel is on the peak's side of the saddle near column 9-10.
            assert!(
                cols.iter().all(|&c| (c < 10) == (peak_col < 10)),
                "{cols:?}"
            );
        }
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
        assert_eq!(regions[0].pixels.len(), 9);
        assert!(watershed_regions(&Array2::zeros((4, 4)), 0.1).is_empty());
    }
}
