//! Fewer items for a costly step: every `k`-th, so that the order (time) is kept.

/// Every `k`-th item so that at most `most` remain (all when fewer).
pub(crate) fn thin<T: Clone>(items: &[T], most: usize) -> Vec<T> {
    let stride = items.len().div_ceil(most.max(1)).max(1);
    items.iter().step_by(stride).cloned().collect()
}
