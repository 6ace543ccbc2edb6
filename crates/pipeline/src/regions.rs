//! Continuous regions of a mask (one lattice domain each).

use std::collections::VecDeque;

use ndarray::Array2;

/// Labels the 4-connected regions of `mask` (true = use): `labels[[row, column]]` is the
/// region number (0, 1, ...) or `None` outside the mask; regions are numbered by size,
/// largest first. Returns the labels and each region's pixel count.
pub fn label_regions(mask: &Array2<bool>) -> (Array2<Option<u32>>, Vec<usize>) {
    let (rows, columns) = mask.dim();
    let mut raw = Array2::<Option<u32>>::from_elem((rows, columns), None);
    let mut sizes = Vec::new();
    let mut queue = VecDeque::new();
    for r in 0..rows {
        for c in 0..columns {
            if !mask[[r, c]] || raw[[r, c]].is_some() {
                continue;
            }
            let label = sizes.len() as u32;
            let mut size = 0;
            raw[[r, c]] = Some(label);
            queue.push_back((r, c));
            while let Some((y, x)) = queue.pop_front() {
                size += 1;
                let neighbours = [
                    (y.wrapping_sub(1), x),
                    (y + 1, x),
                    (y, x.wrapping_sub(1)),
                    (y, x + 1),
                ];
                for (ny, nx) in neighbours {
                    if ny < rows && nx < columns && mask[[ny, nx]] && raw[[ny, nx]].is_none() {
                        raw[[ny, nx]] = Some(label);
                        queue.push_back((ny, nx));
                    }
                }
            }
            sizes.push(size);
        }
    }
    // Renumber by size, largest first (ties by first appearance).
    let mut order: Vec<usize> = (0..sizes.len()).collect();
    order.sort_by_key(|&i| std::cmp::Reverse(sizes[i]));
    let mut rank = vec![0u32; sizes.len()];
    for (new, &old) in order.iter().enumerate() {
        rank[old] = new as u32;
    }
    let labels = raw.mapv(|l| l.map(|l| rank[l as usize]));
    let sorted = order.iter().map(|&i| sizes[i]).collect();
    (labels, sorted)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn two_regions_numbered_by_size() {
        let mut mask = Array2::from_elem((6, 8), false);
        // A small region top-left, a larger one on the right.
        mask[[0, 0]] = true;
        mask[[1, 0]] = true;
        for r in 0..6 {
            for c in 5..8 {
                mask[[r, c]] = true;
            }
        }
        // Diagonal contact is not a connection.
        mask[[2, 1]] = true;
        let (labels, sizes) = label_regions(&mask);
        assert_eq!(sizes, vec![18, 2, 1]);
        assert_eq!(labels[[0, 7]], Some(0));
        assert_eq!(labels[[0, 0]], Some(1));
        assert_eq!(labels[[2, 1]], Some(2));
        assert_eq!(labels[[3, 3]], None);
    }
}
