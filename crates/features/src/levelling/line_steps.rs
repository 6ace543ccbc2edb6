//! Height steps within a scan line, and the line's level as a function of the position
//! along it.
//!
//! A line's single level (the median of what the lattice model leaves along it,
//! [`crate::levelling::lattice_levels`]) is right while the line stays on one terrace. A line that
//! crosses a step edge holds two terraces, and its median is the level of whichever covers
//! more of it: where the step crosses the middle of the lines, neighbouring lines pick
//! different terraces, and the levelled image gets line offsets as large as the step
//! (hundreds of pm against atomic corrugations of tens). Every feature on those lines
//! moves across them (measured on the `rendered-dev` scans with one graphite step and no
//! lateral effect at all: the centres' y scatter about the truth 5–22 pm, against
//! 1–2.4 pm without the step).
//!
//! So each line is cut where its residual jumps: a step shows as a jump *along* a line,
//! which a line offset never does. The jump test compares the means of blocks of about
//! half a neighbour distance on either side of each block boundary with the scatter those
//! differences show along the line (and never less than pixel noise gives); a jump is kept
//! only where it is the largest nearby, and only if the two pieces it separates still
//! differ by that much over their whole length. Each piece gets its own level; within a
//! step's transition (a block either side of the jump, where the tip-blurred step lies)
//! the level changes where the pixels turn nearer the next piece's level than the last
//! one's. A tip change within a line is a step in time and is cut the same way.
//!
//! A background plane fitted across a step leaves a slope on every terrace (the plane
//! takes part of the step as a tilt); piecewise levels cannot follow it, and where a
//! line's cut falls decides how much of it a piece's median holds. So the slope along
//! the lines is measured first, from the median of the jumps within lines (which a step
//! does not move), and is part of every line's level. The lines are cut on what is left.

use dhct_numerics::robust::{finite_median, mad_sigma, median};

/// How far a jump must stand above the scatter of block differences along its line.
const JUMP_SIGMAS: f64 = 8.0;

/// Jumps farther than this many robust σ from the median are left out of a line's slope.
const SLOPE_CLIP_SIGMAS: f64 = 3.0;

/// Where a neighbouring line steps, a jump this fraction of the usual threshold is taken for
/// a step: a step edge crosses many lines, and a cut found on some but not on their
/// neighbours levels neighbouring lines to different terraces (measured on the HOPG file's
/// wide step band: cuts found on 53 of the ~300 lines it crosses put its terrace's rms
/// deviation from 40.2 to 42.8 pm).
const HINTED_FRACTION: f64 = 0.5;

/// Fewest finite pixels a piece needs for a level of its own.
const MIN_PIECE_BLOCKS: usize = 2;

/// One scan line's level as a function of the position along it (px): a slope shared by
/// every line plus a level that is constant between the steps found on the line.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct LineLevel {
    /// `(position along the line px, level z units)`, two per piece (its first and last
    /// pixel), positions increasing; the level is interpolated between them (so it steps
    /// from one pixel to the next between pieces) and constant beyond the ends.
    knots: Vec<(f64, f64)>,
    /// The background's slope along the lines, z units per px.
    slope: f64,
}

impl LineLevel {
    /// One level for the whole line.
    pub fn flat(level: f64) -> Self {
        LineLevel {
            knots: vec![(0.0, level)],
            slope: 0.0,
        }
    }

    /// The level at `along` px.
    pub fn at(&self, along: f64) -> f64 {
        self.slope * along + self.stepped_at(along)
    }

    /// The level at `along` px without the slope.
    fn stepped_at(&self, along: f64) -> f64 {
        let k = &self.knots;
        let next = k.partition_point(|&(p, _)| p <= along);
        match next {
            0 => k[0].1,
            n if n == k.len() => k[n - 1].1,
            n => {
                let ((p0, l0), (p1, l1)) = (k[n - 1], k[n]);
                l0 + (l1 - l0) * (along - p0) / (p1 - p0)
            }
        }
    }

    /// Steps found along the line.
    pub fn steps(&self) -> usize {
        (self.knots.len() / 2).saturating_sub(1)
    }

    /// Where the level steps, px along the line (the first pixel after each step).
    pub fn step_positions(&self) -> impl Iterator<Item = f64> + '_ {
        self.knots.iter().step_by(2).skip(1).map(|k| k.0)
    }

    /// The level over the longest piece of the line (without the slope).
    pub fn typical(&self) -> f64 {
        if self.knots.len() == 1 {
            return self.knots[0].1;
        }
        self.knots
            .chunks(2)
            .max_by(|a, b| span(a).total_cmp(&span(b)))
            .map_or(self.knots[0].1, |piece| piece[0].1)
    }

    /// Subtracts the level from every pixel of `line`.
    pub fn subtract_from<'a>(&self, line: impl Iterator<Item = &'a mut f64>) {
        if let ([(_, level)], 0.0) = (&self.knots[..], self.slope) {
            line.for_each(|v| *v -= level);
        } else {
            line.enumerate().for_each(|(i, v)| *v -= self.at(i as f64));
        }
    }
}

/// Length of a piece given as its two knots, px.
fn span(piece: &[(f64, f64)]) -> f64 {
    piece.last().map_or(0.0, |l| l.0) - piece[0].0
}

/// The slope along one line of its residuals (z units per px): the median of its block
/// jumps over their spans, which steps do not move. `None` when too few jumps can be
/// measured.
pub(crate) fn line_slope(residuals: &[f64], block_px: usize) -> Option<f64> {
    let blocks = Blocks::of(residuals, block_px.max(2));
    let slopes: Vec<f64> = (2..blocks.means.len().saturating_sub(1))
        .map(|i| blocks.jumps[i] / (blocks.jump_span_blocks(i) * blocks.size as f64))
        .filter(|s| s.is_finite())
        .collect();
    if slopes.len() < 8 {
        return None;
    }
    // The jumps across a step all lean one way: leave them out before the median.
    let centre = finite_median(slopes.iter().copied())?;
    let spread = mad_sigma(&slopes)?;
    finite_median(
        slopes
            .into_iter()
            .filter(|s| (s - centre).abs() <= SLOPE_CLIP_SIGMAS * spread),
    )
}

/// The level of one line from its residuals (the image minus the lattice model, NaN where
/// nothing is modelled) with `slope` (z units per px, shared by all lines) taken out, cut
/// at the steps found with blocks of `block_px` pixels; `pixel_noise` is the line's pixel
/// noise (z units). Within `hint_reach_px` of a position in `hints` (px: where a
/// neighbouring line steps) a jump of half the usual size is taken for a step. `None` if
/// no residual is finite.
pub(crate) fn stepped_line_level(
    residuals: &[f64],
    slope: f64,
    (block_px, pixel_noise): (usize, f64),
    (hints, hint_reach_px): (&[f64], f64),
) -> Option<LineLevel> {
    let residuals: Vec<f64> = residuals
        .iter()
        .enumerate()
        .map(|(along, v)| v - slope * along as f64)
        .collect();
    let residuals = &residuals[..];
    let with_slope = |knots| LineLevel { knots, slope };
    let flat = || finite_median(residuals.iter().copied()).map(|l| with_slope(vec![(0.0, l)]));
    let blocks = Blocks::of(residuals, block_px.max(2));
    let Some(threshold) = blocks.jump_threshold(pixel_noise) else {
        return flat();
    };
    let hinted = |at: usize| hints.iter().any(|h| (h - at as f64).abs() <= hint_reach_px);
    let needed = |at: usize| {
        if hinted(at) {
            HINTED_FRACTION * threshold
        } else {
            threshold
        }
    };
    let mut cuts = blocks.steps(HINTED_FRACTION * threshold);
    cuts.retain(|c| c.jump.abs() > needed(c.at));
    if cuts.is_empty() {
        return flat();
    }
    // Cut until every remaining step separates pieces that differ by what it needs.
    loop {
        let spans: Vec<(usize, usize)> = cuts.iter().map(|c| c.span).collect();
        let pieces = pieces_between(residuals, &spans, blocks.size);
        let weak = pieces
            .windows(2)
            .find(|w| (w[1].level - w[0].level).abs() < needed(cuts[w[0].ending_cut].at));
        match weak {
            Some(w) => {
                cuts.remove(w[0].ending_cut);
            }
            None if pieces.len() > 1 => return Some(with_slope(knots_of(&pieces, residuals))),
            None => return flat(),
        }
    }
}

/// A jump taken for a step: its size (z units), its boundary `at` (px) and its
/// transition (first pixel, one past the last).
struct Cut {
    jump: f64,
    at: usize,
    span: (usize, usize),
}

/// The means of a line's blocks of `size` pixels that have at least half their pixels
/// finite, with each block's index (means: a spike or a defect that moves one is no
/// step, and the pieces' medians tell it apart).
struct Blocks {
    size: usize,
    means: Vec<(usize, f64)>,
    /// The jump across the boundary before each block (right two blocks' mean minus the
    /// left two's, skipping blocks without a mean; NaN near the ends).
    jumps: Vec<f64>,
}

impl Blocks {
    fn of(residuals: &[f64], size: usize) -> Blocks {
        let means: Vec<(usize, f64)> = residuals
            .chunks(size)
            .enumerate()
            .filter_map(|(index, chunk)| {
                let (sum, count) = chunk
                    .iter()
                    .filter(|v| v.is_finite())
                    .fold((0.0, 0), |(s, n), v| (s + v, n + 1));
                (2 * count >= size).then(|| (index, sum / count as f64))
            })
            .collect();
        let m = |i: usize| means[i].1;
        let jumps = (0..means.len())
            .map(|i| {
                if i < 2 || i + 2 > means.len() {
                    return f64::NAN;
                }
                0.5 * (m(i) + m(i + 1) - m(i - 2) - m(i - 1))
            })
            .collect();
        Blocks { size, means, jumps }
    }

    /// Blocks between the centres of the two pairs that jump `i` compares.
    fn jump_span_blocks(&self, i: usize) -> f64 {
        let index = |k: usize| self.means[k].0 as f64;
        0.5 * (index(i) + index(i + 1) - index(i - 2) - index(i - 1))
    }

    /// The smallest jump taken for a step: [`JUMP_SIGMAS`] times the robust scatter of
    /// the line's jumps, never below what pixel noise alone gives them. `None` when too
    /// few jumps can be measured.
    fn jump_threshold(&self, pixel_noise: f64) -> Option<f64> {
        if self.jumps.iter().filter(|d| d.is_finite()).count() < 8 {
            return None;
        }
        // About their median: a tilt along the line (a background plane fitted across a
        // step leaves one on both terraces) shifts every jump alike.
        let scatter = mad_sigma(&self.jumps)?;
        // A mean of `size` pixels scatters by σ/√size; a jump is a difference of two means
        // of two such means.
        let from_noise = if pixel_noise.is_finite() {
            pixel_noise / (self.size as f64).sqrt()
        } else {
            0.0
        };
        let threshold = JUMP_SIGMAS * scatter.max(from_noise);
        (threshold > 0.0).then_some(threshold)
    }

    /// The steps: jumps above `threshold` that are the largest within two blocks, each with
    /// its transition: the two blocks either side of the boundary and any gap between them.
    fn steps(&self, threshold: f64) -> Vec<Cut> {
        let size = |i: usize| {
            self.jumps
                .get(i)
                .map_or(0.0, |d| if d.is_finite() { d.abs() } else { 0.0 })
        };
        (0..self.jumps.len())
            .filter(|&i| {
                let here = size(i);
                here > threshold
                    && (i.saturating_sub(2)..=i + 2)
                        .all(|k| k == i || size(k) < here || (size(k) == here && k > i))
            })
            .map(|i| {
                let (before, after) = (self.means[i - 1].0, self.means[i].0);
                Cut {
                    jump: self.jumps[i],
                    at: after * self.size,
                    span: (before * self.size, (after + 1) * self.size),
                }
            })
            .collect()
    }
}

/// A stretch of a line between steps, with its level.
struct Piece {
    /// First and one-past-last pixel.
    start: usize,
    end: usize,
    level: f64,
    /// Index of the cut that ends it (the last piece: one past the last cut).
    ending_cut: usize,
}

/// The pieces between the steps `cuts` (their transitions, which belong to no piece); a
/// piece with fewer than [`MIN_PIECE_BLOCKS`] blocks of finite pixels is left out (its
/// pixels get the ramp between its neighbours).
fn pieces_between(residuals: &[f64], cuts: &[(usize, usize)], block: usize) -> Vec<Piece> {
    let mut pieces = Vec::new();
    let mut start = 0;
    let bounds = cuts
        .iter()
        .copied()
        .chain(std::iter::once((residuals.len(), residuals.len())));
    for (ending_cut, (end, next_start)) in bounds.enumerate() {
        let end = end.max(start);
        let mut finite: Vec<f64> = residuals[start..end.min(residuals.len())]
            .iter()
            .copied()
            .filter(|v| v.is_finite())
            .collect();
        let enough = finite.len() >= MIN_PIECE_BLOCKS * block;
        if let Some(level) = median(&mut finite).filter(|_| enough) {
            pieces.push(Piece {
                start,
                end,
                level,
                ending_cut,
            });
        }
        start = next_start.min(residuals.len());
    }
    pieces
}

/// Knots holding each piece's level over it and over the part of each transition nearer
/// its level, the step between one pixel and the next.
fn knots_of(pieces: &[Piece], residuals: &[f64]) -> Vec<(f64, f64)> {
    let splits: Vec<usize> = pieces
        .windows(2)
        .map(|w| split(&residuals[w[0].end..w[1].start], w[0].level, w[1].level) + w[0].end)
        .collect();
    let mut knots = Vec::with_capacity(2 * pieces.len());
    for (k, piece) in pieces.iter().enumerate() {
        let first = if k == 0 { 0 } else { splits[k - 1] };
        let last = splits.get(k).map_or(residuals.len(), |&s| s) - 1;
        knots.push((first as f64, piece.level));
        knots.push((last as f64, piece.level));
    }
    knots
}

/// Where in a step's transition `gap` the level changes from `before` to `after`: the
/// index that leaves the least absolute difference between each pixel and its level.
fn split(gap: &[f64], before: f64, after: f64) -> usize {
    let cost = |v: f64, level: f64| {
        if v.is_finite() {
            (v - level).abs()
        } else {
            0.0
        }
    };
    // Cost of the split at 0: every pixel on the `after` side.
    let mut total: f64 = gap.iter().map(|&v| cost(v, after)).sum();
    let (mut best, mut best_total) = (0, total);
    for (i, &v) in gap.iter().enumerate() {
        total += cost(v, before) - cost(v, after);
        if total < best_total {
            (best, best_total) = (i + 1, total);
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::levelling::lattice_levels::tests::noise;

    fn line(length: usize, shape: impl Fn(usize) -> f64) -> Vec<f64> {
        (0..length).map(|i| shape(i) + noise(i, 1.0)).collect()
    }

    #[test]
    fn a_line_without_steps_keeps_one_level() {
        let residuals = line(400, |_| 3.0);
        let level = stepped_line_level(&residuals, 0.0, (6, 1.0), (&[], 0.0)).unwrap();
        assert_eq!(level.steps(), 0);
        assert!((level.at(200.0) - 3.0).abs() < 0.2, "{}", level.at(200.0));
    }

    #[test]
    fn a_step_is_cut_where_it_is_and_each_side_keeps_its_level() {
        let residuals = line(400, |i| if i < 157 { 0.0 } else { 20.0 });
        let level = stepped_line_level(&residuals, 0.0, (6, 1.0), (&[], 0.0)).unwrap();
        assert_eq!(level.steps(), 1);
        let at: Vec<f64> = level.step_positions().collect();
        assert!((at[0] - 157.0).abs() <= 1.0, "step at {at:?}");
        assert!(level.at(50.0).abs() < 0.3 && (level.at(350.0) - 20.0).abs() < 0.3);
    }

    #[test]
    fn a_bump_narrower_than_two_blocks_is_no_step() {
        // An adsorbate or a defect: up and down again within 8 px.
        let residuals = line(400, |i| if (200..208).contains(&i) { 30.0 } else { 0.0 });
        let level = stepped_line_level(&residuals, 0.0, (6, 1.0), (&[], 0.0)).unwrap();
        assert_eq!(level.steps(), 0, "{level:?}");
    }

    #[test]
    fn the_slope_along_a_line_is_measured_across_a_step() {
        let residuals = line(400, |i| 0.05 * i as f64 + if i < 230 { 0.0 } else { -25.0 });
        let slope = line_slope(&residuals, 6).unwrap();
        // One line of 400 px with unit noise measures it to about ±0.005.
        assert!((slope - 0.05).abs() < 0.012, "slope {slope}");
        let level = stepped_line_level(&residuals, slope, (6, 1.0), (&[], 0.0)).unwrap();
        assert_eq!(level.steps(), 1);
        for along in [20.0, 150.0, 260.0, 390.0] {
            let expected = 0.05 * along + if along < 230.0 { 0.0 } else { -25.0 };
            assert!(
                (level.at(along) - expected).abs() < 0.5,
                "at {along}: {}",
                level.at(along)
            );
        }
    }

    #[test]
    fn a_weaker_step_is_cut_only_where_a_neighbouring_line_steps() {
        // Between half and all of the usual threshold (about 3.3 here).
        let residuals = line(400, |i| if i < 211 { 0.0 } else { 2.5 });
        let steps = |hints: &[f64]| {
            stepped_line_level(&residuals, 0.0, (6, 1.0), (hints, 24.0))
                .unwrap()
                .steps()
        };
        assert_eq!(steps(&[]), 0);
        assert_eq!(steps(&[205.0]), 1);
        assert_eq!(steps(&[100.0]), 0);
    }
}
