//! Where the gap lies: residual statistics binned by frame time (slow axis), by time since
//! line start (fast phase), by position, by pass and by feature height; the residual
//! spectrum; jumps (change points) in the line-averaged residuals.

use dhct_scan::{ScanGeometry, ScanPass};
use serde::{Deserialize, Serialize};

use crate::evidence::spectrum::{Spectrum, spectrum};
use crate::model::data::Observation;

/// Residual statistics of one bin. Residuals are sample-frame metres (≈ controller-frame
/// `measured − predicted`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Bin {
    /// What the bin holds, e.g. `"t 12.0–18.0 s"`, `"trace"`, `"x 2/6, y 4/6"`.
    pub label: String,
    /// Bin centre in the binned quantity's unit (s, fraction of the line, quantile …);
    /// for the position map, the centre x in metres (y in `centre_y`).
    pub centre: f64,
    /// Second coordinate of a position-map bin, metres.
    pub centre_y: Option<f64>,
    /// Features in the bin.
    pub count: usize,
    /// Mean residual, metres `[x, y]`.
    pub mean_m: [f64; 2],
    /// RMS residual per axis, metres.
    pub rms_m: [f64; 2],
    /// `mean((r_x/σ_x)² + (r_y/σ_y)²)/2`: 1 at the noise floor.
    pub chi2_per_dof: f64,
    /// `(χ²/dof − 1)·√count`: how significant the excess is (≈ N(0, 1) at the floor).
    pub excess_z: f64,
}

/// Binned residual profiles.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GapLocation {
    /// By seconds since frame start.
    pub by_frame_time: Vec<Bin>,
    /// By fraction of the line scan time since the line start.
    pub by_fast_phase: Vec<Bin>,
    /// Coarse position map (row-major, `map_size × map_size`).
    pub by_position: Vec<Bin>,
    /// Side of the map.
    pub map_size: usize,
    /// Trace, retrace.
    pub by_pass: Vec<Bin>,
    /// Apparent-height quintiles.
    pub by_height: Vec<Bin>,
    /// Bins where the gap concentrates (`excess_z > 3`), largest excess χ² first.
    pub hot_spots: Vec<Bin>,
    /// Spectrum of the residuals vs time.
    pub spectrum: Spectrum,
    /// Jumps in the half-line-averaged residuals.
    pub change_points: Vec<ChangePoint>,
}

/// A jump in the residuals at one time.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ChangePoint {
    /// Seconds since frame start (start of the first half line after the jump).
    pub time_s: f64,
    /// Mean residual after − before, metres `[x, y]`.
    pub jump_m: [f64; 2],
    /// Weighted between-segment χ² (≈ χ²₂ under no jump; threshold 30).
    pub statistic: f64,
}

fn bin_of(label: String, centre: f64, members: &[usize], r: &[[f64; 2]], sigma: [f64; 2]) -> Bin {
    let n = members.len().max(1) as f64;
    let mut mean = [0.0; 2];
    let mut sq = [0.0; 2];
    let mut chi = 0.0;
    for &i in members {
        for a in 0..2 {
            mean[a] += r[i][a] / n;
            sq[a] += r[i][a] * r[i][a] / n;
        }
        chi += 0.5 * ((r[i][0] / sigma[0]).powi(2) + (r[i][1] / sigma[1]).powi(2)) / n;
    }
    Bin {
        label,
        centre,
        centre_y: None,
        count: members.len(),
        mean_m: mean,
        rms_m: [sq[0].sqrt(), sq[1].sqrt()],
        chi2_per_dof: chi,
        excess_z: (chi - 1.0) * (members.len() as f64).sqrt(),
    }
}

#[allow(clippy::too_many_arguments)]
fn binned<F: Fn(&Observation) -> f64>(
    observations: &[Observation],
    r: &[[f64; 2]],
    sigma: [f64; 2],
    value: F,
    lo: f64,
    hi: f64,
    count: usize,
    unit: &str,
) -> Vec<Bin> {
    let width = (hi - lo).max(1e-300) / count as f64;
    let mut members = vec![Vec::new(); count];
    for (i, o) in observations.iter().enumerate() {
        let k = ((value(o) - lo) / width).floor();
        if k.is_finite() {
            members[(k.max(0.0) as usize).min(count - 1)].push(i);
        }
    }
    members
        .iter()
        .enumerate()
        .filter(|(_, m)| !m.is_empty())
        .map(|(k, m)| {
            let a = lo + k as f64 * width;
            bin_of(
                format!("{unit} {:.3}–{:.3}", a, a + width),
                a + 0.5 * width,
                m,
                r,
                sigma,
            )
        })
        .collect()
}

/// Change points by binary segmentation of half-line means (weights `n/σ²`).
pub(crate) fn change_points(
    observations: &[Observation],
    r: &[[f64; 2]],
    sigma: [f64; 2],
    threshold: f64,
) -> Vec<ChangePoint> {
    // Half-line segments in time order: (start time, Σr/σ², Σ1/σ² per axis).
    let mut segs: Vec<(f64, [f64; 2], [f64; 2])> = Vec::new();
    let mut order: Vec<usize> = (0..observations.len()).collect();
    order.sort_by(|&a, &b| observations[a].time_s.total_cmp(&observations[b].time_s));
    for i in order {
        let o = &observations[i];
        let start = o.time_s - o.line_time_s;
        let w = [1.0 / sigma[0].powi(2), 1.0 / sigma[1].powi(2)];
        match segs.last_mut() {
            Some(s) if (s.0 - start).abs() < 1e-9 * start.abs().max(1.0) => {
                for a in 0..2 {
                    s.1[a] += r[i][a] * w[a];
                    s.2[a] += w[a];
                }
            }
            _ => segs.push((start, [r[i][0] * w[0], r[i][1] * w[1]], w)),
        }
    }
    let mut out = Vec::new();
    let mut stack = vec![(0usize, segs.len())];
    while let Some((a, b)) = stack.pop() {
        if b - a < 4 || out.len() >= 8 {
            continue;
        }
        let total_s = segs[a..b]
            .iter()
            .fold([0.0; 2], |acc, s| [acc[0] + s.1[0], acc[1] + s.1[1]]);
        let total_w = segs[a..b]
            .iter()
            .fold([0.0; 2], |acc, s| [acc[0] + s.2[0], acc[1] + s.2[1]]);
        let mut left_s = [0.0; 2];
        let mut left_w = [0.0; 2];
        let mut best = (0.0, a, [0.0; 2]);
        for (k, seg) in segs.iter().enumerate().take(b - 1).skip(a) {
            for ax in 0..2 {
                left_s[ax] += seg.1[ax];
                left_w[ax] += seg.2[ax];
            }
            let mut stat = 0.0;
            let mut jump = [0.0; 2];
            for ax in 0..2 {
                let (ls, lw) = (left_s[ax], left_w[ax]);
                let (rs, rw) = (total_s[ax] - ls, total_w[ax] - lw);
                if lw <= 0.0 || rw <= 0.0 {
                    continue;
                }
                stat += ls * ls / lw + rs * rs / rw - total_s[ax] * total_s[ax] / total_w[ax];
                jump[ax] = rs / rw - ls / lw;
            }
            if stat > best.0 {
                best = (stat, k + 1, jump);
            }
        }
        if best.0 > threshold {
            out.push(ChangePoint {
                time_s: segs[best.1].0,
                jump_m: best.2,
                statistic: best.0,
            });
            stack.push((a, best.1));
            stack.push((best.1, b));
        }
    }
    out.sort_by(|x, y| x.time_s.total_cmp(&y.time_s));
    out
}

/// All location statistics of residuals `r` (metres).
pub(crate) fn locate(
    observations: &[Observation],
    r: &[[f64; 2]],
    sigma: [f64; 2],
    geometry: &ScanGeometry,
) -> GapLocation {
    let t_max = observations.iter().map(|o| o.time_s).fold(0.0, f64::max);
    let by_frame_time = binned(
        observations,
        r,
        sigma,
        |o| o.time_s,
        0.0,
        t_max * 1.000001,
        16,
        "t/s",
    );
    let lst = geometry.line_scan_time();
    let by_fast_phase = binned(
        observations,
        r,
        sigma,
        |o| o.line_time_s / lst,
        0.0,
        1.0,
        12,
        "τ/T",
    );
    let map_size = 6;
    let (w, h) = (geometry.width(), geometry.height());
    let mut cells = vec![Vec::new(); map_size * map_size];
    for (i, o) in observations.iter().enumerate() {
        let cx =
            ((o.controller_m[0] / w * map_size as f64).floor().max(0.0) as usize).min(map_size - 1);
        let cy =
            ((o.controller_m[1] / h * map_size as f64).floor().max(0.0) as usize).min(map_size - 1);
        cells[cy * map_size + cx].push(i);
    }
    let by_position = cells
        .iter()
        .enumerate()
        .map(|(k, m)| {
            let (cx, cy) = (k % map_size, k / map_size);
            let mut b = bin_of(
                format!("x {}/{map_size}, y {}/{map_size}", cx + 1, cy + 1),
                (cx as f64 + 0.5) * w / map_size as f64,
                m,
                r,
                sigma,
            );
            b.centre_y = Some((cy as f64 + 0.5) * h / map_size as f64);
            b
        })
        .collect::<Vec<_>>();
    let by_pass = ScanPass::BOTH
        .iter()
        .enumerate()
        .filter_map(|(k, pass)| {
            let m: Vec<usize> = (0..observations.len())
                .filter(|&i| observations[i].pass == *pass)
                .collect();
            (!m.is_empty()).then(|| bin_of(pass.to_string(), k as f64, &m, r, sigma))
        })
        .collect();
    let mut order: Vec<usize> = (0..observations.len()).collect();
    order.sort_by(|&a, &b| {
        observations[a]
            .apparent_height
            .total_cmp(&observations[b].apparent_height)
    });
    let by_height = (0..5)
        .filter_map(|q| {
            let lo = q * order.len() / 5;
            let hi = (q + 1) * order.len() / 5;
            (hi > lo).then(|| {
                bin_of(
                    format!("height quintile {}", q + 1),
                    q as f64 + 0.5,
                    &order[lo..hi],
                    r,
                    sigma,
                )
            })
        })
        .collect::<Vec<_>>();
    let weighted: Vec<f64> = r
        .iter()
        .flat_map(|v| [v[0] / sigma[0], v[1] / sigma[1]])
        .collect();
    let mut hot_spots: Vec<Bin> = by_frame_time
        .iter()
        .chain(&by_fast_phase)
        .chain(&by_position)
        .chain(&by_pass)
        .chain(&by_height)
        .filter(|b| b.excess_z > 3.0 && b.count > 0)
        .cloned()
        .collect();
    hot_spots.sort_by(|a, b| {
        let ea = (a.chi2_per_dof - 1.0) * a.count as f64;
        let eb = (b.chi2_per_dof - 1.0) * b.count as f64;
        eb.total_cmp(&ea)
    });
    hot_spots.truncate(10);
    GapLocation {
        by_frame_time,
        by_fast_phase,
        by_position,
        map_size,
        by_pass,
        by_height,
        hot_spots,
        spectrum: spectrum(observations, &weighted),
        change_points: change_points(observations, r, sigma, 30.0),
    }
}
