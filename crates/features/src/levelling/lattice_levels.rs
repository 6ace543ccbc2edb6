//! Scan-line levels measured against the lattice's own picture.
//!
//! A line's median (or any level of one line) holds part of the lattice: how much depends
//! on where the line crosses the rows, so subtracting it imprints the row period on the
//! image and every fitted centre moves with it, coherently along the rows — a pattern a
//! diagnosis reads as a vibration. Rows within a few degrees of the lines are the worst
//! case: their whole modulation looks like line offsets.
//!
//! So the lattice is taken out first. Every pixel belongs to its nearest fitted centre;
//! the *atom template* is the image's average over all those cells as a function of the
//! offset from the centre (on a half-pixel grid), so it holds the measured shape with its
//! neighbours' tails, whatever the atoms look like. The lattice model puts the template
//! at every centre; a line's level is the median of the image minus that model along it,
//! which holds the line offset and not the rows. The first centres are the correlation's
//! peaks; the features are fitted on the image minus those levels, the levels are taken
//! again around the fitted centres, and the features are refitted if the levels moved
//! (`find.rs`, `level_against_lattice`). When the first levels vary from line to line no
//! more than pixel noise allows ([`LineLevels::offsets_over_noise`]), the lines are left
//! as recorded: levelling would only add noise shared along each line.
//!
//! Line offsets average out of the template (each cell is crossed by many lines). The
//! template is one average shape: where distortion squeezes the lattice (the start of a
//! fast-scan line) or where features differ in kind, the model is less exact there, and
//! the median keeps such places from setting a line's level.

use dhct_numerics::robust::finite_median;

use crate::levelling::line_steps::{LineLevel, line_slope, stepped_line_level};
use crate::levelling::preprocess::scan_lines_mut;
use dhct_scan::Axis;
use ndarray::{Array2, ArrayView2};
use rayon::prelude::*;

/// How far (in blocks of half a neighbour distance) from where a neighbouring line steps a
/// line's own step is looked for with the lower threshold.
const HINT_REACH_BLOCKS: usize = 4;

/// Lines the background's slope along the lines is measured on (evenly spread).
const SLOPE_LINES: usize = 64;

/// Template grid spacing, px.
const TEMPLATE_STEP_PX: f64 = 0.5;

/// Bands of rows the template is summed over in parallel.
const TEMPLATE_BANDS: usize = 32;

/// Reach of a centre's cell, in neighbour distances: beyond a regular lattice's farthest
/// cell corner (0.58 hexagonal, 0.71 square); pixels farther from every centre (gaps,
/// lattice-free patches) are left out of the model.
const CELL_REACH_NN: f64 = 0.75;

/// Each pixel's nearest centre within reach (row-major; [`NO_CENTRE`] where none is).
struct NearestCentre<'a> {
    centres: &'a [[f64; 2]],
    columns: usize,
    owner: Vec<u32>,
}

/// A pixel with no centre within reach.
const NO_CENTRE: u32 = u32::MAX;

impl<'a> NearestCentre<'a> {
    /// Rasterises every centre's disc of radius `reach_px` over an image of
    /// `(rows, columns)` px, keeping the nearest centre of each pixel.
    fn assign(centres: &'a [[f64; 2]], (rows, columns): (usize, usize), reach_px: f64) -> Self {
        let mut owner = vec![NO_CENTRE; rows * columns];
        let mut nearest = vec![f32::INFINITY; rows * columns];
        let reach2 = reach_px * reach_px;
        for (index, c) in centres.iter().enumerate() {
            let (r0, r1) = ((c[1] - reach_px).ceil(), (c[1] + reach_px).floor());
            let (c0, c1) = ((c[0] - reach_px).ceil(), (c[0] + reach_px).floor());
            if r1 < 0.0 || c1 < 0.0 || r0 >= rows as f64 || c0 >= columns as f64 {
                continue;
            }
            let (r0, r1) = (r0.max(0.0) as usize, r1.min(rows as f64 - 1.0) as usize);
            let (c0, c1) = (c0.max(0.0) as usize, c1.min(columns as f64 - 1.0) as usize);
            for r in r0..=r1 {
                let dy = r as f64 - c[1];
                for col in c0..=c1 {
                    let dx = col as f64 - c[0];
                    let d2 = dx * dx + dy * dy;
                    let k = r * columns + col;
                    if d2 <= reach2 && (d2 as f32) < nearest[k] {
                        nearest[k] = d2 as f32;
                        owner[k] = index as u32;
                    }
                }
            }
        }
        NearestCentre {
            centres,
            columns,
            owner,
        }
    }

    /// The offset `(dx, dy)` px of pixel `(row, column)` from its nearest centre, if one
    /// is in reach.
    fn offset(&self, row: usize, column: usize) -> Option<(f64, f64)> {
        let owner = self.owner[row * self.columns + column];
        (owner != NO_CENTRE).then(|| {
            let c = self.centres[owner as usize];
            (column as f64 - c[0], row as f64 - c[1])
        })
    }
}

/// The image's mean as a function of the offset from the nearest centre.
struct AtomTemplate {
    half: i64,
    side: usize,
    values: Vec<f64>,
}

impl AtomTemplate {
    /// Bins of the grid reaching `reach_px` from the centre.
    fn empty_bins(reach_px: f64) -> (i64, usize) {
        let half = (reach_px / TEMPLATE_STEP_PX).ceil() as i64;
        (half, (2 * half + 1) as usize)
    }

    /// The bin nearest `(dx, dy)` px, if inside the grid. (Rounded by truncating the
    /// offset from the grid's corner, which is then ≥ 0: `f64::round` is a library call on
    /// the baseline x86-64 target, and this runs for every pixel.)
    fn bin(half: i64, side: usize, (dx, dy): (f64, f64)) -> Option<usize> {
        let corner = half as f64 + 0.5;
        let (u, v) = (
            dx / TEMPLATE_STEP_PX + corner,
            dy / TEMPLATE_STEP_PX + corner,
        );
        if !(u >= 0.0 && v >= 0.0) {
            return None;
        }
        let (i, j) = (v as usize, u as usize);
        (i < side && j < side).then_some(i * side + j)
    }

    /// Averages the finite pixels of `z` by their offset from the nearest centre.
    fn measure(z: ArrayView2<f64>, nearest: &NearestCentre, reach_px: f64) -> AtomTemplate {
        let (half, side) = Self::empty_bins(reach_px);
        let (rows, columns) = z.dim();
        // Fixed bands of rows summed in a fixed order: the same result on any number of
        // threads.
        let band = rows.div_ceil(TEMPLATE_BANDS).max(1);
        let partial: Vec<(Vec<f64>, Vec<u32>)> = (0..rows.div_ceil(band))
            .into_par_iter()
            .map(|b| {
                let (mut sum, mut count) = (vec![0.0; side * side], vec![0u32; side * side]);
                for r in b * band..((b + 1) * band).min(rows) {
                    for c in 0..columns {
                        let v = z[[r, c]];
                        let bin = nearest.offset(r, c).and_then(|o| Self::bin(half, side, o));
                        if let (true, Some(k)) = (v.is_finite(), bin) {
                            sum[k] += v;
                            count[k] += 1;
                        }
                    }
                }
                (sum, count)
            })
            .collect();
        let (mut sum, mut count) = (vec![0.0; side * side], vec![0u32; side * side]);
        for (s, n) in partial {
            sum.iter_mut().zip(&s).for_each(|(a, b)| *a += b);
            count.iter_mut().zip(&n).for_each(|(a, b)| *a += b);
        }
        let values = sum
            .iter()
            .zip(&count)
            .map(|(s, &n)| if n > 0 { s / f64::from(n) } else { f64::NAN })
            .collect();
        AtomTemplate { half, side, values }
    }

    /// The template at `offset`, interpolated bilinearly between its bins (the nearest bin
    /// where a neighbour is empty; NaN outside it or where no pixel fell).
    fn at(&self, (dx, dy): (f64, f64)) -> f64 {
        let (u, v) = (
            dx / TEMPLATE_STEP_PX + self.half as f64,
            dy / TEMPLATE_STEP_PX + self.half as f64,
        );
        // Truncation is the floor here (u, v ≥ 0), without a library call.
        let last = self.side - 1;
        let inside = u >= 0.0 && v >= 0.0 && (u as usize) < last && (v as usize) < last;
        if !inside {
            return Self::bin(self.half, self.side, (dx, dy)).map_or(f64::NAN, |k| self.values[k]);
        }
        let (j, i) = (u as usize, v as usize);
        let (fu, fv) = (u - j as f64, v - i as f64);
        let k = i * self.side + j;
        let corners = [
            self.values[k],
            self.values[k + 1],
            self.values[k + self.side],
            self.values[k + self.side + 1],
        ];
        if corners.iter().any(|c| c.is_nan()) {
            return Self::bin(self.half, self.side, (dx, dy)).map_or(f64::NAN, |k| self.values[k]);
        }
        (1.0 - fv) * ((1.0 - fu) * corners[0] + fu * corners[1])
            + fv * ((1.0 - fu) * corners[2] + fu * corners[3])
    }
}

/// The measured atom placed at every centre.
struct LatticeModel<'a> {
    nearest: NearestCentre<'a>,
    template: AtomTemplate,
}

impl<'a> LatticeModel<'a> {
    /// The model of `z` built from `centres` (`(x, y)` px; `nn_px` the neighbour
    /// distance in px).
    fn measure(z: ArrayView2<f64>, centres: &'a [[f64; 2]], nn_px: f64) -> Self {
        let reach_px = CELL_REACH_NN * nn_px;
        let nearest = NearestCentre::assign(centres, z.dim(), reach_px);
        let template = AtomTemplate::measure(z, &nearest, reach_px);
        LatticeModel { nearest, template }
    }

    /// The model at pixel `(row, column)`; NaN where no centre is in reach.
    fn at(&self, row: usize, column: usize) -> f64 {
        self.nearest
            .offset(row, column)
            .map_or(f64::NAN, |o| self.template.at(o))
    }
}

/// The lattice's own picture of `z`: the atom as `z` shows it (its mean by offset from
/// the nearest of `centres`, on a half-pixel grid) placed at every centre (`(x, y)` px;
/// `nn_px` the neighbour distance in px). Put the centres where a model predicts them and
/// this is that model rendered with the measured atom shape. NaN where no centre is within
/// 0.75 neighbour distances.
pub fn lattice_model_image(z: ArrayView2<f64>, centres: &[[f64; 2]], nn_px: f64) -> Array2<f64> {
    let model = LatticeModel::measure(z, centres, nn_px);
    Array2::from_shape_fn(z.dim(), |(r, c)| model.at(r, c))
}

/// `z` minus the lattice model built from `centres` (`(x, y)` px; `nn_px` the neighbour
/// distance in px): what the lattice's own picture does not explain (pixel noise, line
/// offsets, defects). NaN where no centre is in reach or `z` is missing.
pub(crate) fn lattice_residual(
    z: ArrayView2<f64>,
    centres: &[[f64; 2]],
    nn_px: f64,
) -> Array2<f64> {
    let mut residual = lattice_model_image(z, centres, nn_px);
    residual.zip_mut_with(&z, |m, v| *m = v - *m);
    residual
}

/// The lines' levels and how far they vary beyond what pixel noise alone would give.
pub(crate) struct LineLevels {
    /// Each line's level along it (z units), cut at the steps the line crosses
    /// ([`crate::levelling::line_steps`]).
    pub levels: Vec<LineLevel>,
    /// Variance of the level from one line to the next over the variance pixel noise
    /// alone gives a median of the line's residuals (`(π/2)·σ²/n`): about 1 without line
    /// offsets, far above with them (NaN when it cannot be told).
    pub offsets_over_noise: f64,
}

impl LineLevels {
    /// Each line's level over the longest piece of it (z units).
    pub fn typical(&self) -> Vec<f64> {
        self.levels.iter().map(LineLevel::typical).collect()
    }
}

/// Pixel `(row, column)` at `along` px on `line`.
fn line_pixel(fast_axis: Axis, line: usize, along: usize) -> (usize, usize) {
    match fast_axis {
        Axis::Horizontal => (line, along),
        Axis::Vertical => (along, line),
    }
}

/// A line's pixel noise: the MAD scale of successive finite residual differences over √2
/// (NaN if there are none).
fn line_pixel_noise(residuals: &[f64]) -> f64 {
    let differences: Vec<f64> = residuals
        .windows(2)
        .map(|w| w[1] - w[0])
        .filter(|d| d.is_finite())
        .collect();
    dhct_numerics::robust::mad_sigma_about(&differences, 0.0)
        .map_or(f64::NAN, |s| s / std::f64::consts::SQRT_2)
}

/// Each scan line's level: the median along it of `z` minus the lattice model built from
/// `centres` (`(x, y)` px; `nn_px` the neighbour distance in px), taken piece by piece
/// between the height steps the line crosses ([`crate::levelling::line_steps`]). Lines along x when
/// the fast axis is horizontal, else along y. A line with no modelled pixel gets its plain
/// median (0 if it has no finite pixel).
pub(crate) fn lattice_line_levels(
    z: ArrayView2<f64>,
    centres: &[[f64; 2]],
    nn_px: f64,
    fast_axis: Axis,
) -> LineLevels {
    levels_as_recorded(z, &[], centres, nn_px, fast_axis)
}

/// [`lattice_line_levels`] of the lines as recorded, given them levelled: `levelled` is
/// the image with `removed` subtracted (indexed as [`lattice_line_levels`] returns them).
/// The atom template is measured on `levelled` (line offsets blur it less once they are
/// out); the levels are taken of `levelled` plus `removed`, so that each finds the whole
/// of every step, however the lines were levelled before.
pub(crate) fn levels_as_recorded(
    levelled: ArrayView2<f64>,
    removed: &[LineLevel],
    centres: &[[f64; 2]],
    nn_px: f64,
    fast_axis: Axis,
) -> LineLevels {
    let z = levelled;
    let model = LatticeModel::measure(z, centres, nn_px);
    let (rows, columns) = z.dim();
    let (lines, length) = match fast_axis {
        Axis::Horizontal => (rows, columns),
        Axis::Vertical => (columns, rows),
    };
    let block_px = (0.5 * nn_px).round().max(2.0) as usize;
    let recorded = |line: usize, along: usize| {
        let level = removed.get(line).map_or(0.0, |l| l.at(along as f64));
        z[line_pixel(fast_axis, line, along)] + level
    };
    let residuals_of = |line: usize| -> Vec<f64> {
        (0..length)
            .map(|along| {
                let (r, c) = line_pixel(fast_axis, line, along);
                recorded(line, along) - model.at(r, c)
            })
            .collect()
    };
    // The background plane was fitted across any steps, so it may leave a slope along the
    // lines on every terrace; the jumps within lines show it.
    // It is one number: a few dozen lines spread over the image measure it.
    let stride = (lines / SLOPE_LINES).max(1);
    let slope = finite_median(
        (0..lines)
            .into_par_iter()
            .step_by(stride)
            .map(|line| line_slope(&residuals_of(line), block_px).unwrap_or(f64::NAN))
            .collect::<Vec<f64>>(),
    )
    .unwrap_or(0.0);
    let level_of = |line: usize, hints: &[f64]| {
        let residuals = residuals_of(line);
        let count = residuals.iter().filter(|v| v.is_finite()).count();
        let noise = line_pixel_noise(&residuals);
        let reach = (HINT_REACH_BLOCKS * block_px) as f64;
        match stepped_line_level(&residuals, slope, (block_px, noise), (hints, reach)) {
            Some(level) => (level, Some((count, noise))),
            None => (
                LineLevel::flat(
                    finite_median((0..length).map(|along| recorded(line, along))).unwrap_or(0.0),
                ),
                None,
            ),
        }
    };
    let mut per_line: Vec<(LineLevel, Option<(usize, f64)>)> = (0..lines)
        .into_par_iter()
        .map(|line| level_of(line, &[]))
        .collect();
    follow_steps_across_lines(&mut per_line, |line, hints| level_of(line, hints));
    let offsets_over_noise = offsets_over_noise(&per_line, length, block_px);
    LineLevels {
        levels: per_line.into_iter().map(|p| p.0).collect(),
        offsets_over_noise,
    }
}

/// Looks again, down the lines and then up, for a step on each line next to one that has
/// steps and has none near them, with the neighbour's step positions as hints
/// (`level_of(line, hints)`): a step edge crosses many lines, and a line cut at it next to
/// one that is not puts the two on different terraces.
fn follow_steps_across_lines(
    per_line: &mut [(LineLevel, Option<(usize, f64)>)],
    level_of: impl Fn(usize, &[f64]) -> (LineLevel, Option<(usize, f64)>),
) {
    let lines = per_line.len();
    let order: Vec<(usize, usize)> = (1..lines)
        .map(|l| (l - 1, l))
        .chain((0..lines.saturating_sub(1)).rev().map(|l| (l + 1, l)))
        .collect();
    for (from, to) in order {
        let hints: Vec<f64> = per_line[from].0.step_positions().collect();
        let own: Vec<f64> = per_line[to].0.step_positions().collect();
        let unmatched = hints
            .iter()
            .any(|h| own.iter().all(|p| (p - h).abs() > 1.0));
        if hints.is_empty() || !unmatched {
            continue;
        }
        let again = level_of(to, &hints);
        if again.0.steps() > per_line[to].0.steps() {
            per_line[to] = again;
        }
    }
}

/// How far line `b`'s level lies above line `a`'s: the median over the line of their
/// difference (sampled every `block_px`), so that a step both lines cross cancels.
fn level_difference(a: &LineLevel, b: &LineLevel, length: usize, block_px: usize) -> f64 {
    if a.steps() == 0 && b.steps() == 0 {
        return b.at(0.0) - a.at(0.0);
    }
    finite_median(
        (0..length)
            .step_by(block_px)
            .map(|p| b.at(p as f64) - a.at(p as f64)),
    )
    .unwrap_or(f64::NAN)
}

/// [`LineLevels::offsets_over_noise`] from each line's level, residual count and pixel
/// noise.
fn offsets_over_noise(
    per_line: &[(LineLevel, Option<(usize, f64)>)],
    length: usize,
    block_px: usize,
) -> f64 {
    let steps: Vec<f64> = per_line
        .windows(2)
        .map(|w| level_difference(&w[0].0, &w[1].0, length, block_px))
        .collect();
    let observed = dhct_numerics::robust::mad_sigma_about(&steps, 0.0).map(|s| 0.5 * s * s);
    let count = finite_median(per_line.iter().filter_map(|p| p.1.map(|m| m.0 as f64)));
    let noise = finite_median(per_line.iter().filter_map(|p| p.1.map(|m| m.1)));
    match (observed, count, noise) {
        (Some(observed), Some(n), Some(noise)) if n > 0.0 && noise > 0.0 => {
            observed / (std::f64::consts::FRAC_PI_2 * noise * noise / n)
        }
        _ => f64::NAN,
    }
}

/// `z` with each line's level `old` replaced by `new` (both indexed as
/// [`lattice_line_levels`] returns them).
pub(crate) fn replace_line_levels(
    z: &mut Array2<f64>,
    old: &[LineLevel],
    new: &[LineLevel],
    fast_axis: Axis,
) {
    for ((mut line, old), new) in scan_lines_mut(z, fast_axis).into_iter().zip(old).zip(new) {
        for (along, v) in line.iter_mut().enumerate() {
            *v += old.at(along as f64) - new.at(along as f64);
        }
    }
}

/// `z` minus each line's level (`levels` indexed as [`lattice_line_levels`] returns them).
pub(crate) fn subtract_line_levels(z: &mut Array2<f64>, levels: &[LineLevel], fast_axis: Axis) {
    for (mut line, level) in scan_lines_mut(z, fast_axis).into_iter().zip(levels) {
        level.subtract_from(line.iter_mut());
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A hexagonal lattice of sharp atoms (spacing `a` px, rows at `angle` to x) plus a
    /// random offset per row.
    fn lattice_image(
        size: usize,
        a: f64,
        angle: f64,
        offsets: &[f64],
    ) -> (Array2<f64>, Vec<[f64; 2]>) {
        let (c, s) = (angle.cos(), angle.sin());
        let b1 = [a * c, a * s];
        let b2 = [
            a * (angle + std::f64::consts::FRAC_PI_3).cos(),
            a * (angle + std::f64::consts::FRAC_PI_3).sin(),
        ];
        let mut centres = Vec::new();
        let n = (2.0 * size as f64 / a) as i64;
        for i in -n..=n {
            for j in -n..=n {
                let x = i as f64 * b1[0] + j as f64 * b2[0] + 0.3;
                let y = i as f64 * b1[1] + j as f64 * b2[1] + 0.7;
                if (-a..size as f64 + a).contains(&x) && (-a..size as f64 + a).contains(&y) {
                    centres.push([x, y]);
                }
            }
        }
        let sigma = 0.22 * a;
        let z = Array2::from_shape_fn((size, size), |(r, col)| {
            let atoms: f64 = centres
                .iter()
                .map(|p| {
                    let d2 = (col as f64 - p[0]).powi(2) + (r as f64 - p[1]).powi(2);
                    (-0.5 * d2 / (sigma * sigma)).exp()
                })
                .sum();
            atoms + offsets[r]
        });
        (z, centres)
    }

    #[test]
    fn the_levels_are_the_line_offsets_and_not_the_rows() {
        let size = 160;
        let offsets: Vec<f64> = (0..size)
            .map(|r| 0.3 * ((r as f64 * 12.9898).sin() * 43_758.545).fract())
            .collect();
        // Rows 3° from the lines: any one line's median holds their modulation.
        let (z, centres) = lattice_image(size, 12.0, 0.05, &offsets);
        let levels = lattice_line_levels(z.view(), &centres, 12.0, Axis::Horizontal).typical();
        let error = |levels: &[f64]| {
            let d: Vec<f64> = levels.iter().zip(&offsets).map(|(l, o)| l - o).collect();
            let mean = d.iter().sum::<f64>() / d.len() as f64;
            (d.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / d.len() as f64).sqrt()
        };
        let medians: Vec<f64> = z
            .rows()
            .into_iter()
            .map(|r| dhct_numerics::robust::median(&mut r.to_vec()).unwrap())
            .collect();
        let (ours, median) = (error(&levels), error(&medians));
        assert!(median > 0.02, "median levels' error {median}");
        // What is left is mostly the offsets' own noise in the template (each of its bins
        // averages ~50 pixels here): 0.005 against the median's 0.043.
        assert!(
            ours < 0.2 * median,
            "lattice levels' error {ours} vs median {median}"
        );
    }

    #[test]
    fn either_fast_axis_gives_the_same_levels() {
        let size = 96;
        let offsets: Vec<f64> = (0..size).map(|r| 0.1 * (r % 7) as f64).collect();
        let (z, centres) = lattice_image(size, 10.0, 0.4, &offsets);
        let along_x = lattice_line_levels(z.view(), &centres, 10.0, Axis::Horizontal).typical();
        let transposed: Vec<[f64; 2]> = centres.iter().map(|c| [c[1], c[0]]).collect();
        let along_y = lattice_line_levels(z.t(), &transposed, 10.0, Axis::Vertical).typical();
        for (a, b) in along_x.iter().zip(&along_y) {
            assert!((a - b).abs() < 1e-12, "{a} vs {b}");
        }
    }

    #[test]
    fn the_levels_are_the_same_on_any_number_of_threads() {
        let size = 128;
        let offsets: Vec<f64> = (0..size).map(|r| 0.01 * ((r * 7) % 13) as f64).collect();
        let (z, centres) = lattice_image(size, 9.0, 0.3, &offsets);
        let on = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| {
                    lattice_line_levels(z.view(), &centres, 9.0, Axis::Horizontal).typical()
                })
        };
        let one = on(1);
        for threads in [2, 3] {
            let other = on(threads);
            assert!(
                one.iter()
                    .zip(&other)
                    .all(|(a, b)| a.to_bits() == b.to_bits()),
                "{threads} threads"
            );
        }
    }

    /// A reproducible stand-in for Gaussian noise of RMS `sigma` (sum of uniforms).
    pub(crate) fn noise(i: usize, sigma: f64) -> f64 {
        let u = |k: usize| {
            ((((i * 7 + k) as f64) * 12.9898).sin() * 43_758.545)
                .fract()
                .abs()
        };
        sigma * (u(0) + u(1) + u(2) + u(3) - 2.0) * 3f64.sqrt()
    }

    #[test]
    fn line_offsets_are_told_from_pixel_noise() {
        let size = 192;
        let ratio = |offset_sigma: f64| {
            let offsets: Vec<f64> = (0..size)
                .map(|r| noise(100_000 + r, offset_sigma))
                .collect();
            let (mut z, centres) = lattice_image(size, 11.0, 0.5, &offsets);
            for (i, v) in z.iter_mut().enumerate() {
                *v += noise(i, 0.05);
            }
            lattice_line_levels(z.view(), &centres, 11.0, Axis::Horizontal).offsets_over_noise
        };
        let (clean, offset) = (ratio(0.0), ratio(0.05));
        // Pixel noise alone: about 1; offsets as large as the pixel noise: far above 4.
        assert!((0.5..2.0).contains(&clean), "without offsets {clean}");
        assert!(offset > 20.0, "with offsets {offset}");
    }

    #[test]
    fn a_step_across_the_lines_is_levelled_on_both_terraces() {
        let size = 192;
        let offsets: Vec<f64> = (0..size).map(|r| noise(200_000 + r, 0.05)).collect();
        let (mut z, centres) = lattice_image(size, 11.0, 0.3, &offsets);
        // A step 8 times the atoms' height, crossing the lines near their middle at 80°,
        // spread over 4 px, and a slope along the lines.
        let step = |r: usize, c: usize| {
            let across = (c as f64 - 96.0) * 0.98 + (r as f64 - 96.0) * 0.17;
            8.0 * (0.5 + across / 4.0).clamp(0.0, 1.0)
        };
        for ((r, c), v) in z.indexed_iter_mut() {
            *v += step(r, c) + noise(r * size + c, 0.02) + 0.01 * c as f64;
        }
        let found = lattice_line_levels(z.view(), &centres, 11.0, Axis::Horizontal);
        let stepped = found.levels.iter().filter(|l| l.steps() == 1).count();
        assert!(
            stepped > size * 9 / 10,
            "{stepped} of {size} lines cut once"
        );
        // What is left on each line away from the step: its atoms and pixel noise only.
        let mut levelled = z.clone();
        subtract_line_levels(&mut levelled, &found.levels, Axis::Horizontal);
        let (atoms, _) = lattice_image(size, 11.0, 0.3, &vec![0.0; size]);
        let (mut worst, mut tilt): (f64, f64) = (0.0, 0.0);
        for r in 0..size {
            let left: Vec<f64> = (10..70).map(|c| levelled[[r, c]] - atoms[[r, c]]).collect();
            let right: Vec<f64> = (120..180)
                .map(|c| levelled[[r, c]] - atoms[[r, c]])
                .collect();
            let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
            worst = worst.max((mean(&left) - mean(&right)).abs());
            tilt += (mean(&left[40..]) - mean(&left[..20])) / 40.0 / size as f64;
        }
        // Without the cut, lines keep the step's 8 on one side or the other.
        assert!(worst < 0.1, "terraces left apart by up to {worst}");
        // The background plane's slope along the lines (0.01 per px) is taken out too.
        assert!(tilt.abs() < 1e-3, "slope left along the lines {tilt}");
    }
}
