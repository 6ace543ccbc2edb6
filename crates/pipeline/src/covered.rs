//! The part of an image that holds values: a corrected or registered image has NaN where
//! no raw pixel maps, and a Fourier transform over the whole grid would see the edge of
//! that coverage (and the window would weight the covered corner down). The check of a
//! corrected image measures its lattice on the covered rectangle instead.

use ndarray::{Array2, ArrayView2, s};

/// Rows `[top, bottom)` and columns `[left, right)` of an image.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Window {
    pub top: usize,
    pub bottom: usize,
    pub left: usize,
    pub right: usize,
}

impl Window {
    /// Rows inside.
    pub fn rows(&self) -> usize {
        self.bottom - self.top
    }

    /// Columns inside.
    pub fn columns(&self) -> usize {
        self.right - self.left
    }
}

/// The largest rectangle (by area) of `z` holding finite values only: for each row, the
/// run of finite pixels ending there in each column is a histogram whose largest
/// rectangle is found with a stack. `None` when no pixel is finite.
pub(crate) fn covered_window(z: ArrayView2<f64>) -> Option<Window> {
    let (rows, columns) = z.dim();
    let mut heights = vec![0usize; columns];
    let mut best: Option<(usize, Window)> = None;
    for r in 0..rows {
        for (c, h) in heights.iter_mut().enumerate() {
            *h = if z[[r, c]].is_finite() { *h + 1 } else { 0 };
        }
        if let Some((area, left, right, height)) = largest_rectangle(&heights)
            && best.is_none_or(|(a, _)| area > a)
        {
            let window = Window {
                top: r + 1 - height,
                bottom: r + 1,
                left,
                right,
            };
            best = Some((area, window));
        }
    }
    best.map(|(_, window)| window)
}

/// The largest rectangle under the histogram `heights`: its area, columns `[left, right)`
/// and height; `None` when every height is 0.
fn largest_rectangle(heights: &[usize]) -> Option<(usize, usize, usize, usize)> {
    let mut stack: Vec<usize> = Vec::new();
    let mut best: Option<(usize, usize, usize, usize)> = None;
    for i in 0..=heights.len() {
        let h = heights.get(i).copied().unwrap_or(0);
        while let Some(&top) = stack.last() {
            if heights[top] < h {
                break;
            }
            stack.pop();
            let left = stack.last().map_or(0, |&l| l + 1);
            let area = heights[top] * (i - left);
            if area > 0 && best.is_none_or(|b| area > b.0) {
                best = Some((area, left, i, heights[top]));
            }
        }
        stack.push(i);
    }
    best
}

/// `z` inside `window`, as an owned image.
pub(crate) fn crop(z: ArrayView2<f64>, window: Window) -> Array2<f64> {
    z.slice(s![window.top..window.bottom, window.left..window.right])
        .to_owned()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_shifted_frame_keeps_its_covered_rectangle() {
        let mut z = Array2::from_elem((40, 50), f64::NAN);
        z.slice_mut(s![10..40, 0..30]).fill(1.0);
        // A ragged edge: one row covers a few columns more, and a slanted one.
        z.slice_mut(s![10..11, 30..34]).fill(1.0);
        for r in 10..40 {
            z.slice_mut(s![r..r + 1, 0..(r - 10) / 6]).fill(f64::NAN);
        }
        let w = covered_window(z.view()).expect("covered");
        assert_eq!(
            w,
            Window {
                top: 10,
                bottom: 40,
                left: 4,
                right: 30
            }
        );
        assert!(crop(z.view(), w).iter().all(|v| v.is_finite()));
    }

    #[test]
    fn a_full_image_is_its_own_window_and_an_empty_one_has_none() {
        let z = Array2::<f64>::zeros((8, 6));
        let w = covered_window(z.view()).expect("covered");
        assert_eq!((w.rows(), w.columns()), (8, 6));
        assert!(covered_window(Array2::from_elem((4, 4), f64::NAN).view()).is_none());
    }
}
