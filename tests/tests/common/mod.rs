//! Helpers shared by the workspace-level tests.

// Each test file that includes this module uses part of it.
#![allow(dead_code)]

use dhct_calibrate::{CheckOptions, match_lattice, measure_lattice};
use dhct_lattice::{Hexagonal, Lattice, MotifSite, PlaneGroup, Square, UserLattice};
use dhct_scan::ScanPair;
use dhct_scan::ScanPass;
use dhct_simulate::config::{FeatureShape, LatticeConfig, NoiseConfig};
use dhct_simulate::{Simulation, SimulationConfig, presets};
use nalgebra::Vector2;

/// A corrected image's lattice against the lattice given, as an outside check would
/// measure it: the lattice fitted to the image's Fourier peaks (within 15 % of its
/// constant), `[x scale, y scale, shear°]` (1, 1, 0 when the image shows exactly the
/// lattice). `corrected` lies on `pair`'s grid, in sample units.
pub fn corrected_lattice(
    pair: &ScanPair,
    corrected: &ndarray::Array2<f64>,
    lattice: &dyn Lattice,
) -> [f64; 3] {
    let measured = measure_lattice(corrected.view(), pair.geometry(), None)
        .expect("a lattice in the corrected image");
    let bounds = CheckOptions::default().bounds(pair.geometry().fast_axis());
    let matched = match_lattice(&measured, lattice, &bounds).expect("the lattice fits");
    let c = matched.calibration;
    [c.scale[0], c.scale[1], c.shear_deg]
}

/// A 7×7-like surface: corner hole at the origin (depth 1), 12 adatoms (height 0.5) on a
/// ring around the centroid of each half cell, and a shallower minimum (depth 0.25) at each
/// centroid, which a dark kernel also finds: the preset must keep only the corner holes
/// (on Si(111)-7×7 they lie about twice as deep below the adatoms as the other minima:
/// here 1.5 against 0.75).
pub fn das_like() -> UserLattice {
    let a = 2.688e-9;
    let mut motif = vec![MotifSite {
        relative_height: -1.0,
        ..MotifSite::new(0.0, 0.0, "corner hole")
    }];
    for centroid in [[1.0 / 3.0, 1.0 / 3.0], [2.0 / 3.0, 2.0 / 3.0]] {
        motif.push(MotifSite {
            relative_height: -0.25,
            ..MotifSite::new(centroid[0], centroid[1], "half-cell minimum")
        });
        for k in 0..6 {
            let angle = std::f64::consts::PI / 3.0 * k as f64 + 0.3;
            // A ring of 0.2 a in Cartesian units, expressed in fractional coordinates.
            let (x, y) = (0.2 * angle.cos(), 0.2 * angle.sin());
            let f2 = y / (3f64.sqrt() / 2.0);
            let f1 = x - 0.5 * f2;
            motif.push(MotifSite {
                relative_height: 0.5,
                ..MotifSite::new(centroid[0] + f1, centroid[1] + f2, "adatom")
            });
        }
    }
    UserLattice::new(
        "das-like",
        Vector2::new(a, 0.0),
        Vector2::new(0.5 * a, 0.5 * 3f64.sqrt() * a),
        PlaneGroup::P31m,
        motif,
    )
    .expect("a valid lattice")
}

/// One simulated surface of the calibration tests: the simulator's lattice, the lattice
/// the user names for it, and a frame and feature that show it.
pub struct Surface {
    pub name: &'static str,
    pub config: LatticeConfig,
    pub lattice: Box<dyn Lattice>,
    /// Frame width for the ordinary classes, metres.
    pub width_m: f64,
    /// Cell constant (the translation cell's first vector), metres.
    pub cell_m: f64,
    pub feature_sigma_m: f64,
    pub height_m: f64,
}

/// Graphite, a square lattice (3.6 Å) and a Si(111)-7×7-like cell ([`das_like`], tracked by
/// its corner holes with the `si111-7x7` preset).
pub fn surfaces() -> Vec<Surface> {
    vec![
        Surface {
            name: "graphite",
            config: LatticeConfig::Graphite,
            lattice: Box::new(Hexagonal::graphite()),
            width_m: 5e-9,
            cell_m: 2.46e-10,
            feature_sigma_m: 0.6e-10,
            height_m: 40e-12,
        },
        Surface {
            name: "square",
            config: LatticeConfig::Square { a_m: 3.6e-10 },
            lattice: Box::new(Square::new(3.6e-10).expect("valid")),
            width_m: 7e-9,
            cell_m: 3.6e-10,
            feature_sigma_m: 0.8e-10,
            height_m: 40e-12,
        },
        Surface {
            name: "7x7-like",
            config: LatticeConfig::User(das_like()),
            lattice: Box::new(Hexagonal::si111_7x7()),
            width_m: 40e-9,
            cell_m: 2.688e-9,
            feature_sigma_m: 2.5e-10,
            height_m: 60e-12,
        },
    ]
}

impl Surface {
    /// The `ci-small` acquisition (drift, creep, hysteresis) of this surface over its frame,
    /// the lattice turned by `angle_rad`, round features, 2 pm of white noise.
    pub fn simulation(&self, angle_rad: f64) -> SimulationConfig {
        let mut config = presets::ci_small();
        config.scan.width_m = self.width_m;
        config.scan.height_m = self.width_m;
        config.surface.lattice = self.config.clone();
        config.surface.angle_rad = angle_rad;
        config.surface.feature = FeatureShape {
            height_m: self.height_m,
            sigma_m: [self.feature_sigma_m; 2],
            angle_rad: 0.0,
            lobes: Vec::new(),
        };
        config.noise = NoiseConfig {
            white_sigma_m: 2e-12,
            ..NoiseConfig::default()
        };
        config
    }
}

/// Runs `config` and writes its scan with the pixel size multiplied by `error` per axis
/// (a miscalibrated head).
pub fn simulate_miscalibrated(config: &SimulationConfig, error: [f64; 2]) -> ScanPair {
    let pair = Simulation::from_config(config)
        .expect("valid config")
        .run()
        .expect("runs")
        .pair;
    let geometry = pair.geometry();
    let file_geometry = geometry
        .clone()
        .with_pitch(geometry.pitch_x() * error[0], geometry.pitch_y() * error[1])
        .expect("positive");
    ScanPair::new(
        file_geometry,
        pair.trace().expect("trace").clone(),
        pair.image(ScanPass::Retrace).cloned(),
    )
    .expect("same shape")
}
