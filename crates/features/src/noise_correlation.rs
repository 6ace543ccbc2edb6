//! How much more the fitted centres scatter than their fits' covariance says when the
//! pixel noise is correlated.
//!
//! A fit's centre uncertainty assumes independent pixel noise: `σ²·(JᵀJ)⁻¹`. A centre is
//! a linear function of the pixels near the optimum, `δx = gₓ·n` with `gₓ` the x row of
//! `(JᵀJ)⁻¹Jᵀ`, so its variance is `gₓᵀ C gₓ` for noise covariance `C`, which equals
//! `σ²·|gₓ|²` only for white noise. Noise shared along scan lines (slow drift of the
//! z signal, 1/f noise, line offsets left in the image) moves every line of a feature
//! together and shifts its centre across the lines far more than white noise of the same
//! variance would.
//!
//! The noise is what the lattice model leaves ([`crate::levelling::lattice_levels`]): the image
//! minus the measured atom placed at every fitted centre. That model is one average atom,
//! so where distortion changes the atoms' shape the residual also holds that change; the
//! residual at a place minus the residual at the same place of the neighbouring cell
//! farthest across the lines cancels it (neighbouring cells look alike) and keeps the
//! noise, whose variance it doubles. Each fit's `gₓ` and `g_y` are applied to that
//! difference at places spread over the image; the mean of `(g·d)²` over the mean of
//! `Σ g²d²` is the variance ratio, 1 for white noise.
//!
//! Near a fitted centre the residual lacks what the fit absorbed, so the kernels sit
//! between the centres; the fits still absorb part of noise shared along lines, so the
//! ratio is a lower bound there (measured below). What the ratio cannot tell from noise:
//! structure the lattice model lacks (a large cell's unmodelled atoms) and an effect that
//! distorts a feature within its own lines (a slow vibration, a step edge). The diagnosis
//! therefore never lets its floor exceed 1.5 × the trace/retrace spread of the same sites
//! (`dhct-diagnose`, `noise.rs`).

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use ndarray::{ArrayView2, s};

use crate::gaussian_fit::GaussianFit;
use crate::levelling::lattice_levels::lattice_residual;

/// The ratio is measured on the central block of the image at most this many px on a
/// side (it is one number per axis; a larger image only costs time).
const BLOCK_PX: usize = 640;

/// Fits whose kernels are used (spread evenly over the list).
const KERNELS: usize = 256;

/// Places each kernel is applied at.
const PLACES_PER_KERNEL: usize = 8;

/// Places tried per place used (a place needs its window and its partner's inside the
/// modelled image).
const TRIES_PER_PLACE: usize = 8;

/// Fewer usable (kernel, place) samples than this give no factor.
const MIN_SAMPLES: usize = 200;

/// Kernels are applied only this many neighbour distances or more from every centre:
/// nearer, the residual lacks what that centre's fit absorbed. Measured on rendered
/// graphite with 1/f pixel noise (384², 16 scans): the y factor came out 10–45 % below
/// the true scatter applied anywhere, 5–40 % below at 0.3 or 0.45; with white noise the
/// same within 3 % of the truth either way.
const BETWEEN_CENTRES_NN: f64 = 0.3;

/// Samples whose mean square noise exceeds this many times the median are left out.
const OUTLIER_VARIANCE: f64 = 5.0;

/// Neighbours are looked for within this many neighbour distances of a centre.
const NEIGHBOUR_REACH_NN: f64 = 1.3;

/// The x and y rows of `(JᵀJ)⁻¹Jᵀ` of `fit` over pixel offsets `offsets` (`(row, column)`
/// around the pixel nearest its centre).
fn centre_kernels(fit: &GaussianFit, offsets: &[(i64, i64)]) -> Option<[Vec<f64>; 2]> {
    let (cx, cy) = (fit.x0.round(), fit.y0.round());
    let xs: Vec<f64> = offsets.iter().map(|o| cx + o.1 as f64).collect();
    let ys: Vec<f64> = offsets.iter().map(|o| cy + o.0 as f64).collect();
    let zs = vec![0.0; offsets.len()];
    let gradients = fit.gradients(&xs, &ys, &zs);
    let inverse = fit.gram(&gradients).try_inverse()?;
    let row = |axis: usize| -> Vec<f64> {
        gradients
            .iter()
            .map(|(g, _)| (0..7).map(|k| inverse[(axis, k)] * g[k]).sum())
            .collect()
    };
    Some([row(1), row(2)])
}

/// Place `n` of a low-discrepancy sequence over the unit square.
fn place(n: usize) -> (f64, f64) {
    const A1: f64 = 0.754_877_666_246_692_8;
    const A2: f64 = 0.569_840_290_998_053_3;
    ((0.5 + n as f64 * A1).fract(), (0.5 + n as f64 * A2).fract())
}

/// The fitted centres, indexed for "the cell a pixel is in" and "its neighbour across
/// the lines".
struct Cells {
    centres: Vec<[f64; 2]>,
    tree: ImmutableKdTree<f64, 2>,
    nn_px: f64,
}

impl Cells {
    fn new(fits: &[GaussianFit], nn_px: f64) -> Option<Cells> {
        let centres: Vec<[f64; 2]> = fits.iter().map(|f| [f.x0, f.y0]).collect();
        let tree = ImmutableKdTree::new_from_slice(&centres).ok()?;
        Some(Cells {
            centres,
            tree,
            nn_px,
        })
    }

    /// The pixel at the same place as `(row, column)` in the neighbouring cell farthest
    /// across the scan lines (rows if `across_rows`, else columns), to the nearest pixel;
    /// `None` if `(row, column)` is nearer a centre than [`BETWEEN_CENTRES_NN`].
    fn partner(&self, (row, column): (usize, usize), across_rows: bool) -> Option<(usize, usize)> {
        let hit = self
            .tree
            .query(&[column as f64, row as f64])
            .nearest_one::<SquaredEuclidean<f64>>()
            .execute();
        if hit.distance < (BETWEEN_CENTRES_NN * self.nn_px).powi(2) {
            return None;
        }
        let own = hit.item as usize;
        let c = self.centres[own];
        let reach = NEIGHBOUR_REACH_NN * self.nn_px;
        let across = |j: usize| {
            let d = [self.centres[j][0] - c[0], self.centres[j][1] - c[1]];
            if across_rows { d[1].abs() } else { d[0].abs() }
        };
        let neighbour = self
            .tree
            .query(&c)
            .within::<SquaredEuclidean<f64>>(reach * reach)
            .unsorted()
            .execute()
            .into_iter()
            .map(|n| n.item as usize)
            .filter(|&j| j != own)
            .max_by(|&a, &b| across(a).total_cmp(&across(b)).then(b.cmp(&a)))?;
        let shift = [
            (self.centres[neighbour][1] - c[1]).round() as i64,
            (self.centres[neighbour][0] - c[0]).round() as i64,
        ];
        Some((
            usize::try_from(row as i64 + shift[0]).ok()?,
            usize::try_from(column as i64 + shift[1]).ok()?,
        ))
    }
}

/// `residual` at `(row, column)` minus at `partner`, over `offsets`; `None` if a pixel is
/// outside or missing.
fn differenced(
    residual: ArrayView2<f64>,
    (row, column): (usize, usize),
    partner: (usize, usize),
    offsets: &[(i64, i64)],
) -> Option<Vec<f64>> {
    let at = |(r, c): (usize, usize), o: &(i64, i64)| {
        let (r, c) = (r as i64 + o.0, c as i64 + o.1);
        let (r, c) = (usize::try_from(r).ok()?, usize::try_from(c).ok()?);
        residual.get([r, c]).copied().filter(|v| v.is_finite())
    };
    offsets
        .iter()
        .map(|o| Some(at((row, column), o)? - at(partner, o)?))
        .collect()
}

/// What one sample gives one axis.
struct Sample {
    /// The kernel's response to the noise, squared.
    response2: f64,
    /// What white noise of the same local variance would give it (`Σ g²d²`).
    white: f64,
    /// The sample's mean square noise.
    noise_variance: f64,
}

impl Sample {
    fn of(g: &[f64], d: &[f64]) -> Sample {
        let response: f64 = g.iter().zip(d).map(|(g, d)| g * d).sum();
        Sample {
            response2: response * response,
            white: g.iter().zip(d).map(|(g, d)| g * g * d * d).sum(),
            noise_variance: d.iter().map(|d| d * d).sum::<f64>() / d.len().max(1) as f64,
        }
    }
}

/// The samples' `Σ response² / Σ white`, leaving out samples whose noise variance exceeds
/// [`OUTLIER_VARIANCE`] times the median (a step edge or a defect is not noise).
fn pooled_ratio(samples: &[Sample]) -> f64 {
    let mut v: Vec<f64> = samples.iter().map(|s| s.noise_variance).collect();
    let limit = OUTLIER_VARIANCE * dhct_numerics::robust::median(&mut v).unwrap_or(f64::NAN);
    let (mut response, mut white) = (0.0, 0.0);
    for s in samples.iter().filter(|s| s.noise_variance <= limit) {
        response += s.response2;
        white += s.white;
    }
    response / white
}

/// The variance of fitted centres over what the fits' covariance gives, per axis `[x, y]`
/// (1 for white noise), from `residual` (image minus lattice model, NaN where unmodelled),
/// the usable `fits` with their window `offsets` (`(row, column)` px) and the neighbour
/// distance `nn_px`; scan lines along rows if `lines_along_rows`. `None` with too few
/// samples.
fn centre_variance_ratio(
    residual: ArrayView2<f64>,
    fits: &[GaussianFit],
    offsets: &[(i64, i64)],
    nn_px: f64,
    lines_along_rows: bool,
) -> Option<[f64; 2]> {
    let (rows, columns) = residual.dim();
    let cells = Cells::new(fits, nn_px)?;
    let step = fits.len().div_ceil(KERNELS).max(1);
    let mut samples: [Vec<Sample>; 2] = [Vec::new(), Vec::new()];
    let mut n = 0usize;
    for fit in fits.iter().step_by(step) {
        let Some(kernels) = centre_kernels(fit, offsets) else {
            continue;
        };
        let mut placed = 0;
        for _ in 0..TRIES_PER_PLACE * PLACES_PER_KERNEL {
            if placed == PLACES_PER_KERNEL {
                break;
            }
            n += 1;
            let (u, v) = place(n);
            let here = ((u * rows as f64) as usize, (v * columns as f64) as usize);
            let Some(d) = cells
                .partner(here, lines_along_rows)
                .and_then(|there| differenced(residual, here, there, offsets))
            else {
                continue;
            };
            placed += 1;
            for (axis, g) in kernels.iter().enumerate() {
                samples[axis].push(Sample::of(g, &d));
            }
        }
    }
    (samples[0].len() >= MIN_SAMPLES).then(|| samples.each_ref().map(|s| pooled_ratio(s)))
}

/// [`centre_variance_ratio`] of the image `z` the usable `fits` saw (centres in its px),
/// measured on its central block of at most [`BLOCK_PX`] px on a side against the lattice
/// model of that block.
pub(crate) fn measured_centre_variance_ratio(
    z: ArrayView2<f64>,
    fits: &[GaussianFit],
    offsets: &[(i64, i64)],
    nn_px: f64,
    lines_along_rows: bool,
) -> Option<[f64; 2]> {
    let (rows, columns) = z.dim();
    let (r0, c0) = (
        rows.saturating_sub(BLOCK_PX) / 2,
        columns.saturating_sub(BLOCK_PX) / 2,
    );
    let (r1, c1) = ((r0 + BLOCK_PX).min(rows), (c0 + BLOCK_PX).min(columns));
    let block = z.slice(s![r0..r1, c0..c1]);
    let inside: Vec<GaussianFit> = fits
        .iter()
        .map(|f| GaussianFit {
            x0: f.x0 - c0 as f64,
            y0: f.y0 - r0 as f64,
            ..*f
        })
        .filter(|f| {
            f.x0 >= 0.0 && f.y0 >= 0.0 && f.x0 < (c1 - c0) as f64 && f.y0 < (r1 - r0) as f64
        })
        .collect();
    let centres: Vec<[f64; 2]> = inside.iter().map(|f| [f.x0, f.y0]).collect();
    let residual = lattice_residual(block, &centres, nn_px);
    centre_variance_ratio(residual.view(), &inside, offsets, nn_px, lines_along_rows)
}
