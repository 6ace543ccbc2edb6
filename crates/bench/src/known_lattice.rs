//! The judge's reading of a known lattice from an image's Fourier transform: the lattice's
//! first-order reflections, placed by the rotation and scale under which most of them
//! stand out of the spectrum, each then located to a small fraction of a bin, and the
//! reciprocal lattice fitted to them weighted by their signal.
//!
//! This is what an outsider does with a numpy FFT when the constant and lattice type are
//! known: it does not need the image to show enough peaks to index a lattice blind, so it
//! reads frames of a few large cells (a 7×7 frame five cells across) as well as large
//! ones, and a reflection barely above the noise cannot pull the lattice. It shares
//! nothing with dhct's own calibration.
//!
//! First order only: higher orders smear with whatever non-affine distortion an image
//! keeps, and a dense set of them (a 7×7 cell's) also fits a lattice rotated 30° and
//! 2/√3 longer, which the first ring alone never does. A surface whose first ring is too
//! weak (some 7×7 images) cannot be read this way.
//!
//! Frames: `x` along columns and `y` along rows, both in metres of the file (`pitch`);
//! frequencies in cycles per metre, or in bins (`u` along columns, `v` along rows).

use nalgebra::{Matrix2, Vector2};
use ndarray::{Array2, ArrayView2};
use rustfft::FftPlanner;
use rustfft::num_complex::Complex;
use serde::Deserialize;

/// The translation lattice a corpus file is judged with.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum JudgeLattice {
    /// Hexagonal (one site per 60° rhombus).
    #[default]
    Hexagonal,
    /// Square.
    Square,
}

/// Two independent reflections must stand this many times above the ring's median power
/// (without the reflections) for a reading.
pub const MIN_SIGNAL: f64 = 20.0;
/// Reflections weaker than this over the ring's median power are not used.
const NOISE_SIGNAL: f64 = 10.0;
/// Reflections are read up to this many times the first-order ring's radius (see the
/// module's notes).
const MAX_ORDER: f64 = 1.0;

/// The lattice read from an image.
#[derive(Debug, Clone, PartialEq)]
pub struct LatticeReading {
    /// The cell in the file: vectors `[a1, a2]` (`[x, y]` each), metres.
    pub cell_in_file_m: [[f64; 2]; 2],
    /// `[kx, ky]`: apparent over true length along x and y.
    pub scale: [f64; 2],
    /// Shear of the slow axis against the fast one, `atan(kxy/ky)`, degrees.
    pub shear_deg: f64,
    /// The reflections fitted.
    pub reflections: Vec<Reflection>,
}

/// One reflection read.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reflection {
    /// Index `[h, k]` on the ideal reciprocal basis.
    pub index: [f64; 2],
    /// Where it is, cycles per metre `[x, y]`.
    pub frequency: [f64; 2],
    /// Its power over the ring's median power (without the reflections).
    pub signal: f64,
}

/// Reads `lattice` with constant `a_m` from `z` (pixel pitch `[x, y]`, metres), at a
/// scale (apparent over true length) between `scale_range[0]` and `scale_range[1]`.
pub fn read_known_lattice(
    z: ArrayView2<f64>,
    pitch: [f64; 2],
    lattice: JudgeLattice,
    a_m: f64,
    scale_range: [f64; 2],
) -> Result<LatticeReading, String> {
    let (rows, columns) = z.dim();
    if rows < 16 || columns < 16 {
        return Err(format!("a {columns} × {rows} image is too small to read"));
    }
    let image = windowed(z).ok_or("the image holds no finite values")?;
    let bins = BinFrame {
        per_metre: [columns as f64 * pitch[0], rows as f64 * pitch[1]],
        size: [columns, rows],
    };
    let power = power_spectrum(&image);
    let ideal = lattice.ideal_reciprocal(a_m);
    let indices = visible_indices(ideal, &bins, scale_range);
    if indices.is_empty() {
        return Err("the lattice's reflections lie beyond the image's resolution".into());
    }
    let radius = (ideal * Vector2::new(1.0, 0.0)).norm();
    // The ring's median with its reflections in it places the lattice; without them, it
    // is the background the reflections are measured against.
    let crude = ring_median(&power, &bins, radius, &[]);
    let basis = best_similarity(&power, &bins, ideal, &indices, crude, lattice, scale_range);
    let predicted: Vec<[f64; 2]> = indices
        .iter()
        .map(|m| column(basis * Vector2::new(m[0], m[1])))
        .collect();
    let background = ring_median(&power, &bins, radius, &predicted);
    let located = locate(&image, &power, &bins, &predicted, &indices, background);
    check_independent(&located)?;
    let reciprocal = fit_robustly(&located, &bins).ok_or("the reflections read are parallel")?;
    let read = reading(reciprocal, lattice, a_m, located)?;
    let mean = (read.scale[0] * read.scale[1]).sqrt();
    if !(scale_range[0]..=scale_range[1]).contains(&mean) {
        return Err(format!(
            "the lattice read is {mean:.3}× the constant, outside {:.2}–{:.2}",
            scale_range[0], scale_range[1]
        ));
    }
    Ok(read)
}

/// Fails unless two independent reflections stand at least [`MIN_SIGNAL`] times above the
/// ring's background.
fn check_independent(located: &[Reflection]) -> Result<(), String> {
    let strong: Vec<&Reflection> = located.iter().filter(|r| r.signal >= MIN_SIGNAL).collect();
    let independent = strong.iter().any(|a| {
        strong
            .iter()
            .any(|b| (a.index[0] * b.index[1] - a.index[1] * b.index[0]).abs() > 0.5)
    });
    if independent {
        return Ok(());
    }
    let best = located.iter().map(|r| r.signal).fold(0.0, f64::max);
    Err(format!(
        "no two independent reflections of the lattice stand {MIN_SIGNAL}× above the \
         spectrum's median at their radius (the strongest: {best:.1}×)"
    ))
}

impl JudgeLattice {
    /// The ideal reciprocal basis `[b1, b2]` (columns), cycles per metre, `b1` along x:
    /// 120° apart on a hexagonal lattice (`b1 + b2` is then 60° from `b1`).
    fn ideal_reciprocal(self, a_m: f64) -> Matrix2<f64> {
        match self {
            JudgeLattice::Hexagonal => {
                let g = 2.0 / (3f64.sqrt() * a_m);
                let (s, c) = (120f64.to_radians()).sin_cos();
                Matrix2::new(g, g * c, 0.0, g * s)
            }
            JudgeLattice::Square => Matrix2::new(1.0 / a_m, 0.0, 0.0, 1.0 / a_m),
        }
    }

    /// The angle after which the lattice's reflections repeat, degrees.
    fn symmetry_deg(self) -> f64 {
        match self {
            JudgeLattice::Hexagonal => 60.0,
            JudgeLattice::Square => 90.0,
        }
    }
}

/// The indices (one of each `±` pair) of the reflections up to [`MAX_ORDER`] times the
/// first ring that lie, at every scale of `scale_range`, at least 2 bins from the origin
/// and within 0.9 of the Nyquist frequency.
fn visible_indices(ideal: Matrix2<f64>, bins: &BinFrame, scale_range: [f64; 2]) -> Vec<[f64; 2]> {
    let first = (ideal * Vector2::new(1.0, 0.0)).norm();
    let reach = MAX_ORDER.ceil() as i32 * 2;
    let mut found = Vec::new();
    for h in -reach..=reach {
        for k in -reach..=reach {
            let g = ideal * Vector2::new(h as f64, k as f64);
            let half_plane = g.y > 1e-9 * first || (g.y.abs() <= 1e-9 * first && g.x > 0.0);
            if !half_plane || g.norm() > MAX_ORDER * first * (1.0 + 1e-9) {
                continue;
            }
            // An apparent length `s` puts the reflection at `|g| / s`, in any direction.
            let (far, near) = (g.norm() / scale_range[0], g.norm() / scale_range[1]);
            let inside =
                (0..2).all(|axis| far * bins.per_metre[axis] < 0.45 * bins.size[axis] as f64);
            let clear = (0..2).all(|axis| near * bins.per_metre[axis] >= 2.0);
            if inside && clear {
                found.push([h as f64, k as f64]);
            }
        }
    }
    found
}

/// The median power of the first-order ring (its radius ±15 % at scale 1), without the
/// bins within 2.5 of the reflections `excluded` (frequencies; their mirror images too):
/// the spectrum's background under the reflections.
fn ring_median(power: &Array2<f64>, bins: &BinFrame, radius: f64, excluded: &[[f64; 2]]) -> f64 {
    let (rows, columns) = power.dim();
    let excluded: Vec<[f64; 2]> = excluded.iter().map(|k| bins.bin(*k)).collect();
    let mut ring = Vec::new();
    for r in 0..rows {
        for c in 0..columns {
            let bin = [signed(c, columns), signed(r, rows)];
            let k = norm(bins.frequency(bin));
            let near_reflection = excluded.iter().any(|e| {
                norm([bin[0] - e[0], bin[1] - e[1]]).min(norm([bin[0] + e[0], bin[1] + e[1]]))
                    <= 2.5
            });
            if (k / radius - 1.0).abs() <= 0.15 && !near_reflection {
                ring.push(power[[r, c]]);
            }
        }
    }
    if ring.is_empty() {
        return f64::NAN;
    }
    let middle = ring.len() / 2;
    *ring.select_nth_unstable_by(middle, f64::total_cmp).1
}

/// `p` over the background `median`.
fn signal(p: f64, median: f64) -> f64 {
    p / median.max(f64::MIN_POSITIVE)
}

/// The reciprocal basis of the rotation and scale (within `scale_range`) under which most
/// of the lattice's reflections stand out: each reflection whose bin (or a neighbour)
/// holds [`NOISE_SIGNAL`] times the `background` counts 1, plus a tenth of the log of its
/// excess to break ties; on a grid fine enough that the farthest reflection moves by at
/// most 0.4 bin a step.
fn best_similarity(
    power: &Array2<f64>,
    bins: &BinFrame,
    ideal: Matrix2<f64>,
    indices: &[[f64; 2]],
    background: f64,
    lattice: JudgeLattice,
    scale_range: [f64; 2],
) -> Matrix2<f64> {
    let farthest = indices
        .iter()
        .map(|m| norm(bins.bin(column(ideal * Vector2::new(m[0], m[1])))) / scale_range[0])
        .fold(1.0, f64::max);
    let step = 0.4 / farthest;
    let angles = (lattice.symmetry_deg().to_radians() / step).ceil() as usize;
    let (low, high) = (1.0 / scale_range[1], 1.0 / scale_range[0]);
    let sizes = ((high / low).ln() / step).ceil() as usize + 1;
    let dilated = dilated(power);
    let score = |basis: Matrix2<f64>| -> f64 {
        indices
            .iter()
            .map(|m| {
                let g = column(basis * Vector2::new(m[0], m[1]));
                let signal = signal(nearest_power(&dilated, bins, g), background);
                if signal >= NOISE_SIGNAL {
                    1.0 + 0.1 * (signal / NOISE_SIGNAL).ln()
                } else {
                    0.0
                }
            })
            .sum()
    };
    let mut best = (f64::NEG_INFINITY, ideal);
    for a in 0..angles {
        let rotation = nalgebra::Rotation2::new(a as f64 * step).into_inner();
        for s in 0..sizes {
            let basis = rotation * ideal * (low * (s as f64 * step).exp());
            let value = score(basis);
            if value > best.0 {
                best = (value, basis);
            }
        }
    }
    best.1
}

/// The reflections found near where they are `predicted`: the strongest bin within 0.02
/// of the reflection's radius (at least 1.5 bins), those standing [`NOISE_SIGNAL`] above
/// the `background` located to a fraction of a bin.
fn locate(
    image: &Array2<f64>,
    power: &Array2<f64>,
    bins: &BinFrame,
    predicted: &[[f64; 2]],
    indices: &[[f64; 2]],
    background: f64,
) -> Vec<Reflection> {
    predicted
        .iter()
        .zip(indices)
        .map(|(g, index)| {
            let near = strongest_near(power, bins, *g, 0.02 * norm(*g));
            (
                index,
                near,
                signal(nearest_power(power, bins, near), background),
            )
        })
        .filter(|(_, _, signal)| *signal >= NOISE_SIGNAL)
        .map(|(index, near, _)| {
            let (frequency, p) = refine(image, bins, near);
            Reflection {
                index: *index,
                frequency,
                signal: signal(p, background),
            }
        })
        .collect()
}

/// The reciprocal basis fitted to the reflections weighted by signal, once more without
/// those more than 1 bin (and 3 weighted rms) from the first fit.
fn fit_robustly(located: &[Reflection], bins: &BinFrame) -> Option<Matrix2<f64>> {
    let first = weighted_basis(located)?;
    let misses: Vec<f64> = located
        .iter()
        .map(|r| {
            let predicted = column(first * Vector2::new(r.index[0], r.index[1]));
            let miss = bins.bin([r.frequency[0] - predicted[0], r.frequency[1] - predicted[1]]);
            norm(miss)
        })
        .collect();
    let total: f64 = located.iter().map(|r| r.signal).sum();
    let rms = (located
        .iter()
        .zip(&misses)
        .map(|(r, m)| r.signal * m * m)
        .sum::<f64>()
        / total)
        .sqrt();
    let kept: Vec<Reflection> = located
        .iter()
        .zip(&misses)
        .filter(|(_, m)| **m <= 1.0_f64.max(3.0 * rms))
        .map(|(r, _)| *r)
        .collect();
    weighted_basis(&kept).or(Some(first))
}

/// The reciprocal basis fitted to the reflections by least squares, each weighted by its
/// signal (a position's variance falls as its power over the noise).
fn weighted_basis(reflections: &[Reflection]) -> Option<Matrix2<f64>> {
    let mut normal = Matrix2::zeros();
    let mut right = [Vector2::zeros(), Vector2::zeros()];
    for r in reflections {
        let m = Vector2::new(r.index[0], r.index[1]);
        normal += r.signal * m * m.transpose();
        for (axis, side) in right.iter_mut().enumerate() {
            *side += r.signal * r.frequency[axis] * m;
        }
    }
    let inverse = normal.try_inverse()?;
    let (bx, by) = (inverse * right[0], inverse * right[1]);
    Some(Matrix2::new(bx[0], bx[1], by[0], by[1]))
}

/// The cell and its calibration from the fitted reciprocal basis: the map from the ideal
/// cell to the one read, `M = K·Q` with `K = [[kx, kxy], [0, ky]]` and `Q` a rotation.
fn reading(
    reciprocal: Matrix2<f64>,
    lattice: JudgeLattice,
    a_m: f64,
    reflections: Vec<Reflection>,
) -> Result<LatticeReading, String> {
    let cell = reciprocal
        .try_inverse()
        .ok_or("the reflections read are parallel")?
        .transpose();
    let ideal = lattice
        .ideal_reciprocal(a_m)
        .try_inverse()
        .expect("a positive constant")
        .transpose();
    let map = cell * ideal.try_inverse().expect("a positive constant");
    if map.determinant() <= 0.0 {
        return Err("the reflections read are mirrored against the lattice".into());
    }
    let ky = map[(1, 0)].hypot(map[(1, 1)]);
    let (s, c) = (map[(1, 0)] / ky, map[(1, 1)] / ky);
    let kx = map[(0, 0)] * c - map[(0, 1)] * s;
    let kxy = map[(0, 0)] * s + map[(0, 1)] * c;
    Ok(LatticeReading {
        cell_in_file_m: [[cell[(0, 0)], cell[(1, 0)]], [cell[(0, 1)], cell[(1, 1)]]],
        scale: [kx, ky],
        shear_deg: kxy.atan2(ky).to_degrees(),
        reflections,
    })
}

/// How bins map to frequencies: `per_metre[0]` bins along columns per cycle per metre
/// (the frame's width, metres), `per_metre[1]` along rows.
struct BinFrame {
    per_metre: [f64; 2],
    /// The spectrum's `[columns, rows]`.
    size: [usize; 2],
}

impl BinFrame {
    fn frequency(&self, bin: [f64; 2]) -> [f64; 2] {
        [bin[0] / self.per_metre[0], bin[1] / self.per_metre[1]]
    }

    fn bin(&self, k: [f64; 2]) -> [f64; 2] {
        [k[0] * self.per_metre[0], k[1] * self.per_metre[1]]
    }
}

/// `z` with its non-finite values set to the mean, its best plane removed, and a 2-D Hann
/// window applied.
fn windowed(z: ArrayView2<f64>) -> Option<Array2<f64>> {
    let (rows, columns) = z.dim();
    let finite: Vec<f64> = z.iter().copied().filter(|v| v.is_finite()).collect();
    if finite.is_empty() {
        return None;
    }
    let mean = finite.iter().sum::<f64>() / finite.len() as f64;
    let filled = z.mapv(|v| if v.is_finite() { v - mean } else { 0.0 });
    let plane = best_plane(&filled);
    let hann = |i: usize, n: usize| {
        let t = (i as f64 + 0.5) / n as f64;
        0.5 - 0.5 * (2.0 * std::f64::consts::PI * t).cos()
    };
    Some(Array2::from_shape_fn((rows, columns), |(r, c)| {
        let level = plane[0] + plane[1] * c as f64 + plane[2] * r as f64;
        (filled[[r, c]] - level) * hann(r, rows) * hann(c, columns)
    }))
}

/// The least-squares plane `[p0, p_column, p_row]` of `z`.
fn best_plane(z: &Array2<f64>) -> [f64; 3] {
    let (rows, columns) = z.dim();
    let (cr, cc) = ((rows as f64 - 1.0) / 2.0, (columns as f64 - 1.0) / 2.0);
    let (mut szc, mut szr, mut scc, mut srr, mut sz) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for ((r, c), v) in z.indexed_iter() {
        let (dr, dc) = (r as f64 - cr, c as f64 - cc);
        szc += v * dc;
        szr += v * dr;
        scc += dc * dc;
        srr += dr * dr;
        sz += v;
    }
    let n = (rows * columns) as f64;
    let (pc, pr) = (szc / scc.max(1.0), szr / srr.max(1.0));
    [sz / n - pc * cc - pr * cr, pc, pr]
}

/// `|F|²` of `image`, indexed `[row, column]` as the FFT leaves it.
fn power_spectrum(image: &Array2<f64>) -> Array2<f64> {
    let (rows, columns) = image.dim();
    let mut planner = FftPlanner::<f64>::new();
    let (row_fft, column_fft) = (
        planner.plan_fft_forward(columns),
        planner.plan_fft_forward(rows),
    );
    let mut data: Vec<Complex<f64>> = image.iter().map(|&v| Complex::new(v, 0.0)).collect();
    for line in data.chunks_exact_mut(columns) {
        row_fft.process(line);
    }
    let mut column = vec![Complex::new(0.0, 0.0); rows];
    for c in 0..columns {
        for r in 0..rows {
            column[r] = data[r * columns + c];
        }
        column_fft.process(&mut column);
        for r in 0..rows {
            data[r * columns + c] = column[r];
        }
    }
    Array2::from_shape_fn((rows, columns), |(r, c)| data[r * columns + c].norm_sqr())
}

/// The signed bin of FFT index `i` of `n`.
fn signed(i: usize, n: usize) -> f64 {
    if i <= n / 2 {
        i as f64
    } else {
        i as f64 - n as f64
    }
}

/// The FFT index of signed bin `b` of `n`, if it is inside the spectrum.
fn index(b: i64, n: usize) -> Option<usize> {
    let n = n as i64;
    (b.abs() < n / 2).then(|| b.rem_euclid(n) as usize)
}

/// The largest power of each bin and its eight neighbours.
fn dilated(power: &Array2<f64>) -> Array2<f64> {
    let (rows, columns) = power.dim();
    Array2::from_shape_fn((rows, columns), |(r, c)| {
        let mut most = f64::NEG_INFINITY;
        for dr in [rows - 1, 0, 1] {
            for dc in [columns - 1, 0, 1] {
                most = most.max(power[[(r + dr) % rows, (c + dc) % columns]]);
            }
        }
        most
    })
}

/// The power at the bin nearest frequency `k`.
fn nearest_power(power: &Array2<f64>, bins: &BinFrame, k: [f64; 2]) -> f64 {
    let (rows, columns) = power.dim();
    let bin = bins.bin(k);
    match (
        index(bin[1].round() as i64, rows),
        index(bin[0].round() as i64, columns),
    ) {
        (Some(r), Some(c)) => power[[r, c]],
        _ => 0.0,
    }
}

/// The strongest bin within `radius` cycles per metre (at least 1.5 bins) of frequency
/// `k`.
fn strongest_near(power: &Array2<f64>, bins: &BinFrame, k: [f64; 2], radius: f64) -> [f64; 2] {
    let (rows, columns) = power.dim();
    let centre = bins.bin(k);
    let reach = [
        (radius * bins.per_metre[0]).max(1.5),
        (radius * bins.per_metre[1]).max(1.5),
    ];
    let mut best = ([centre[0].round(), centre[1].round()], f64::NEG_INFINITY);
    for v in (centre[1] - reach[1]).ceil() as i64..=(centre[1] + reach[1]).floor() as i64 {
        for u in (centre[0] - reach[0]).ceil() as i64..=(centre[0] + reach[0]).floor() as i64 {
            let (du, dv) = (
                (u as f64 - centre[0]) / reach[0],
                (v as f64 - centre[1]) / reach[1],
            );
            if du * du + dv * dv > 1.0 || (u == 0 && v == 0) {
                continue;
            }
            let (Some(r), Some(c)) = (index(v, rows), index(u, columns)) else {
                continue;
            };
            if power[[r, c]] > best.1 {
                best = ([u as f64, v as f64], power[[r, c]]);
            }
        }
    }
    bins.frequency(best.0)
}

/// The reflection near frequency `k` located to a small fraction of a bin: the image's
/// Fourier power on a grid of tenth-bins around it, its maximum refined by a parabola.
/// Returns the frequency (cycles per metre) and its power.
fn refine(image: &Array2<f64>, bins: &BinFrame, k: [f64; 2]) -> ([f64; 2], f64) {
    const STEPS: i32 = 6;
    const STEP: f64 = 0.1;
    let mut centre = bins.bin(k);
    let mut grid = zoom_power(image, centre, STEPS, STEP);
    for _ in 0..3 {
        let (i, j) = argmax(&grid);
        let edge = |n: usize| n == 0 || n == 2 * STEPS as usize;
        if !edge(i) && !edge(j) {
            break;
        }
        centre = [
            centre[0] + (j as f64 - STEPS as f64) * STEP,
            centre[1] + (i as f64 - STEPS as f64) * STEP,
        ];
        grid = zoom_power(image, centre, STEPS, STEP);
    }
    let (i, j) = argmax(&grid);
    let n = 2 * STEPS as usize;
    let offset = dhct_numerics::peak::vertex;
    let log = |i: usize, j: usize| grid[[i, j]].max(f64::MIN_POSITIVE).ln();
    let dv = if i > 0 && i < n {
        offset(log(i - 1, j), log(i, j), log(i + 1, j))
    } else {
        0.0
    };
    let du = if j > 0 && j < n {
        offset(log(i, j - 1), log(i, j), log(i, j + 1))
    } else {
        0.0
    };
    let bin = [
        centre[0] + (j as f64 - STEPS as f64 + du) * STEP,
        centre[1] + (i as f64 - STEPS as f64 + dv) * STEP,
    ];
    (bins.frequency(bin), grid[[i, j]])
}

fn argmax(grid: &Array2<f64>) -> (usize, usize) {
    grid.indexed_iter()
        .max_by(|a, b| a.1.total_cmp(b.1))
        .map(|(index, _)| index)
        .expect("a non-empty grid")
}

/// `|F(u, v)|²` of `image` at bins `centre + (j − steps, i − steps)·step`, indexed
/// `[i, j]`: the transform along rows at each `u` first, then along columns.
fn zoom_power(image: &Array2<f64>, centre: [f64; 2], steps: i32, step: f64) -> Array2<f64> {
    let (rows, columns) = image.dim();
    let n = (2 * steps + 1) as usize;
    let offsets: Vec<f64> = (0..n).map(|k| (k as f64 - steps as f64) * step).collect();
    let row_transforms: Vec<Vec<Complex<f64>>> = offsets
        .iter()
        .map(|du| {
            let phasors = phasors(centre[0] + du, columns);
            image
                .rows()
                .into_iter()
                .map(|line| line.iter().zip(&phasors).map(|(z, p)| p * z).sum())
                .collect()
        })
        .collect();
    let column_phasors: Vec<Vec<Complex<f64>>> = offsets
        .iter()
        .map(|dv| phasors(centre[1] + dv, rows))
        .collect();
    Array2::from_shape_fn((n, n), |(i, j)| {
        row_transforms[j]
            .iter()
            .zip(&column_phasors[i])
            .map(|(t, p)| t * p)
            .sum::<Complex<f64>>()
            .norm_sqr()
    })
}

/// `exp(−2πi·bin·k/n)` for `k` in `0..n`.
fn phasors(bin: f64, n: usize) -> Vec<Complex<f64>> {
    (0..n)
        .map(|k| Complex::from_polar(1.0, -2.0 * std::f64::consts::PI * bin * k as f64 / n as f64))
        .collect()
}

fn column(v: Vector2<f64>) -> [f64; 2] {
    [v.x, v.y]
}

fn norm(k: [f64; 2]) -> f64 {
    k[0].hypot(k[1])
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A lattice of cosines at reflections `indices` of `lattice` mapped by `K·Q(rotation)`,
    /// with amplitudes `amplitude`.
    fn cosines(
        size: usize,
        pitch: f64,
        lattice: JudgeLattice,
        a: f64,
        map: (Matrix2<f64>, f64),
        reflections: &[([f64; 2], f64)],
    ) -> Array2<f64> {
        // The real-space map M = K·Q takes reciprocal vectors g to M^-T·g.
        let (s, c) = map.1.to_radians().sin_cos();
        let m = map.0 * Matrix2::new(c, -s, s, c);
        let basis = m.try_inverse().unwrap().transpose() * lattice.ideal_reciprocal(a);
        let g: Vec<(Vector2<f64>, f64)> = reflections
            .iter()
            .map(|(i, amplitude)| (basis * Vector2::new(i[0], i[1]), *amplitude))
            .collect();
        Array2::from_shape_fn((size, size), |(r, c)| {
            let x = Vector2::new(c as f64 * pitch, r as f64 * pitch);
            g.iter()
                .map(|(g, a)| a * (2.0 * std::f64::consts::PI * g.dot(&x)).cos())
                .sum()
        })
    }

    /// White noise in [0, 1).
    fn noise(size: usize, seed: u64) -> Array2<f64> {
        let mut state = seed;
        Array2::from_shape_fn((size, size), |_| {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        })
    }

    #[test]
    fn reads_a_stretched_sheared_hexagonal_lattice_of_few_cells() {
        let a = 2.7e-9;
        // 256 px over 15 nm: about 5.5 cells across; the first ring's third reflection
        // near the noise, a second-order one strong (not read).
        let (size, pitch) = (256, 15e-9 / 256.0);
        let k = Matrix2::new(1.04, 0.03, 0.0, 0.97);
        let lattice = JudgeLattice::Hexagonal;
        let z = cosines(
            size,
            pitch,
            lattice,
            a,
            (k, 17.0),
            &[
                ([1.0, 0.0], 1.0),
                ([1.0, 1.0], 0.8),
                ([0.0, 1.0], 0.05),
                ([2.0, 1.0], 0.5),
            ],
        ) + noise(size, 7) * 0.5;
        let read = read_known_lattice(z.view(), [pitch; 2], lattice, a, [0.85, 1.15]).unwrap();
        assert!((read.scale[0] - 1.04).abs() < 0.003, "{read:?}");
        assert!((read.scale[1] - 0.97).abs() < 0.003, "{read:?}");
        let shear = (0.03f64 / 0.97).atan().to_degrees();
        assert!((read.shear_deg - shear).abs() < 0.2, "{read:?}");
    }

    #[test]
    fn reads_a_square_lattice_whose_reflections_differ_in_power() {
        let a = 3.77e-10;
        let (size, pitch) = (200, 20e-9 / 200.0);
        let lattice = JudgeLattice::Square;
        let k = Matrix2::new(0.99, 0.0, 0.0, 1.01);
        let z = cosines(
            size,
            pitch,
            lattice,
            a,
            (k, 8.0),
            &[([1.0, 0.0], 1.0), ([0.0, 1.0], 0.2), ([1.0, 1.0], 0.5)],
        ) + noise(size, 3) * 0.5;
        let read = read_known_lattice(z.view(), [pitch; 2], lattice, a, [0.85, 1.15]).unwrap();
        assert!((read.scale[0] - 0.99).abs() < 0.002, "{read:?}");
        assert!((read.scale[1] - 1.01).abs() < 0.002, "{read:?}");
        assert!(read.shear_deg.abs() < 0.1, "{read:?}");
    }

    #[test]
    fn refuses_noise_and_a_lattice_off_the_scale_range() {
        let a = 3.77e-10;
        let (size, pitch) = (200, 20e-9 / 200.0);
        let lattice = JudgeLattice::Square;
        let found =
            read_known_lattice(noise(size, 11).view(), [pitch; 2], lattice, a, [0.85, 1.15]);
        assert!(found.is_err(), "{found:?}");
        // The image's lattice 30 % longer than the constant.
        let k = Matrix2::new(1.3, 0.0, 0.0, 1.3);
        let z = cosines(
            size,
            pitch,
            lattice,
            a,
            (k, 0.0),
            &[([1.0, 0.0], 1.0), ([0.0, 1.0], 1.0)],
        );
        let found = read_known_lattice(z.view(), [pitch; 2], lattice, a, [0.85, 1.15]);
        assert!(found.is_err(), "{found:?}");
    }
}
