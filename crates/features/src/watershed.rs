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
    let standard = map.as_standard_layout();
    let values = standard.as_slice().unwrap_or_default();
    let higher = |a: usize, b: usize| {
        // Strict total order: value first, then index.
        values[a] > values[b] || (values[a] == values[b] && a > b)
    };
    const NONE: usize = usize::MAX;
    // Each above-threshold pixel's steepest higher neighbour, or itself if it is a maximum.
    let mut parent = vec![NONE; h * w];
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
                // No bounds checks needed away from the border.
                for offset in offsets {
                    let j = (i as isize + offset) as usize;
                    if higher(j, best) {
                        best = j;
                    }
                }
            } else {
                for dr in -1i64..=1 {
                    for dc in -1i64..=1 {
                        let (rr, cc) = (r as i64 + dr, c as i64 + dc);
                        if (dr == 0 && dc == 0)
                            || rr < 0
                            || cc < 0
                            || rr >= h as i64
                            || cc >= w as i64
                        {
                            continue;
                        }
                        let j = rr as usize * w + cc as usize;
                        if higher(j, best) {
                            best = j;
                        }
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
    // Group pixels by maximum (regions in order of their maxima's first appearance): a
    // dense region index per maximum, then one pass to count and one to fill.
    let mut region_index = vec![u32::MAX; h * w];
    let mut peaks = Vec::new();
    for &top in &root {
        if top != NONE && region_index[top] == u32::MAX {
            region_index[top] = peaks.len() as u32;
            peaks.push(top);
        }
    }
    let mut sizes = vec![0usize; peaks.len()];
    for &top in root.iter().filter(|&&t| t != NONE) {
        sizes[region_index[top] as usize] += 1;
    }
    let mut regions: Vec<Region> = peaks
        .iter()
        .zip(&sizes)
        .map(|(&peak, &size)| Region {
            peak,
            pixels: Vec::with_capacity(size),
        })
        .collect();
    for (i, &top) in root.iter().enumerate() {
        if top != NONE {
            regions[region_index[top] as usize].pixels.push(i);
        }
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
