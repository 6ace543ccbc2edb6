//! Helpers shared by the simulator's integration tests: a small, fast base config and a
//! sub-pixel peak finder to read feature positions back from simulated images.

#![allow(dead_code)]

use dhct_scan::{ImageChannel, ScanDirection, ScanPass};
use dhct_simulate::{
    DefectConfig, EffectConfig, FeatureShape, FeatureTruth, LatticeConfig, NoiseConfig,
    OutputConfig, ScanConfig, Simulation, SimulationConfig, SimulationOutput, SurfaceConfig,
    TipConfig,
};

/// Pixel pitch of [`base_config`], metres.
pub const PITCH: f64 = 50e-12;
/// Square lattice constant of [`base_config`]: 10 px.
pub const A: f64 = 0.5e-9;
/// Fast speed of [`base_config`]: pixel period 1 ms, line 0.128 s.
pub const SPEED: f64 = 50e-9;

/// 128 × 128 px, 50 pm pitch, square lattice a = 0.5 nm (10 px), σ = 2 px, 50 nm/s,
/// trace Right, slow Down, no noise, no effects.
pub fn base_config() -> SimulationConfig {
    SimulationConfig {
        name: "test".into(),
        description: String::new(),
        seed: 11,
        scan: ScanConfig {
            columns: 128,
            rows: 128,
            width_m: 128.0 * PITCH,
            height_m: 128.0 * PITCH,
            fast_speed_m_per_s: SPEED,
            turnaround_s: 0.0,
            trace_fast: ScanDirection::Right,
            slow: ScanDirection::Down,
            memory_limit_gib: None,
        },
        surface: SurfaceConfig {
            lattice: LatticeConfig::Square { a_m: A },
            angle_rad: 0.0,
            origin_m: [0.25e-9, 0.25e-9],
            feature: FeatureShape {
                height_m: 50e-12,
                sigma_m: [100e-12, 100e-12],
                angle_rad: 0.0,
                lobes: Vec::new(),
            },
            defects: DefectConfig::default(),
            second_domain: None,
            steps: Vec::new(),
            plane_slope: [0.0, 0.0],
            strain: Vec::new(),
            modulations: Vec::new(),
        },
        tip: TipConfig::default(),
        noise: NoiseConfig::default(),
        output: OutputConfig::default(),
        effects: Vec::new(),
        sequence: None,
    }
}

/// [`base_config`] with `effects`.
pub fn with_effects(effects: Vec<EffectConfig>) -> SimulationConfig {
    let mut config = base_config();
    config.effects = effects;
    config
}

/// Builds and runs `config`.
pub fn run(config: &SimulationConfig) -> SimulationOutput {
    Simulation::from_config(config)
        .expect("valid config")
        .run()
        .expect("simulation runs")
}

/// The square-lattice cell indices `(n, m)` of a lattice feature.
pub fn cell(feature: &FeatureTruth) -> Option<(i64, i64)> {
    match feature.kind {
        dhct_simulate::surface::FeatureKind::LatticeSite { n, m, .. } => Some((n, m)),
        _ => None,
    }
}

/// Features imaged by `pass` at least `margin` px inside the image.
pub fn well_inside(output: &SimulationOutput, pass: ScanPass, margin: f64) -> Vec<&FeatureTruth> {
    let g = output.pair.geometry();
    output
        .truth
        .imaged_features(pass)
        .filter(|f| {
            let [x, y] = f.acquisition(pass).controller_position_px;
            x >= margin
                && y >= margin
                && x <= g.columns() as f64 - 1.0 - margin
                && y <= g.rows() as f64 - 1.0 - margin
        })
        .collect()
}

/// Sub-pixel positions `[x, y]` (px) of the local maxima above `threshold` in `image`:
/// the peak of a quadratic fitted to log z on the 3 × 3 neighbourhood (exact for an
/// isolated Gaussian of any shape).
pub fn peaks(image: &ImageChannel, threshold: f64) -> Vec<[f64; 2]> {
    let z = &image.z;
    let (rows, columns) = z.dim();
    let mut found = Vec::new();
    for r in 1..rows - 1 {
        for c in 1..columns - 1 {
            let centre = z[[r, c]];
            if centre < threshold {
                continue;
            }
            let mut is_max = true;
            for dr in -1i64..=1 {
                for dc in -1i64..=1 {
                    if (dr, dc) != (0, 0)
                        && z[[(r as i64 + dr) as usize, (c as i64 + dc) as usize]] >= centre
                    {
                        is_max = false;
                    }
                }
            }
            if !is_max {
                continue;
            }
            let l = |dx: i64, dy: i64| {
                z[[(r as i64 + dy) as usize, (c as i64 + dx) as usize]]
                    .max(1e-300)
                    .ln()
            };
            let gx = (-1..=1).map(|j| l(1, j) - l(-1, j)).sum::<f64>() / 6.0;
            let gy = (-1..=1).map(|i| l(i, 1) - l(i, -1)).sum::<f64>() / 6.0;
            let hxx = (-1..=1)
                .map(|j| l(1, j) - 2.0 * l(0, j) + l(-1, j))
                .sum::<f64>()
                / 3.0;
            let hyy = (-1..=1)
                .map(|i| l(i, 1) - 2.0 * l(i, 0) + l(i, -1))
                .sum::<f64>()
                / 3.0;
            let hxy = (l(1, 1) - l(1, -1) - l(-1, 1) + l(-1, -1)) / 4.0;
            let det = hxx * hyy - hxy * hxy;
            if det <= 0.0 {
                continue;
            }
            let ox = -(hyy * gx - hxy * gy) / det;
            let oy = -(-hxy * gx + hxx * gy) / det;
            found.push([c as f64 + ox, r as f64 + oy]);
        }
    }
    found
}

/// Distance (px) from `p` to the nearest of `peaks`.
pub fn nearest_distance(peaks: &[[f64; 2]], p: [f64; 2]) -> f64 {
    peaks
        .iter()
        .map(|q| ((q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2)).sqrt())
        .fold(f64::INFINITY, f64::min)
}
