//! The contract every catalogue lattice passes (a new entry gets this test for free): its
//! surface, simulated with drift, creep and hysteresis, is corrected so that the corrected
//! image's lattice (by FFT, not by dhct's own fit) is the lattice's to 0.5 % and 0.3°, nearly
//! every feature is indexed, every motif site is found as often as the others, the fitted
//! positions deviate from their sites by less than 5 % of the nearest-neighbour distance
//! (RMS), and the averaged unit cell has the entry's own plane group about its symmetry
//! origin (residual at the noise level, below 0.15; a wrong group or origin gives ≳ 0.3).
//! Kagome, the centred rectangle and the two-site oblique cell were the lattices the implicit
//! contract failed (site-dependent bond directions, a strongest second-order reflection,
//! unequally spaced bonds, shells closer than 35 %).

use dhct_calibrate::{CheckOptions, calibrate_pair};
use dhct_lattice::{CATALOGUE, Lattice};
use dhct_pipeline::{PipelineOptions, run};
use dhct_scan::{ScanPair, ScanPass};
use dhct_simulate::config::{FeatureShape, LatticeConfig};
use dhct_simulate::{Simulation, presets};

/// Nearest-neighbour distance of the entries without a known constant, metres.
const GIVEN_NN_M: f64 = 3.2e-10;

/// The entry's surface on 256² px with about 10 px per nearest-neighbour distance.
fn simulated(name: &str, lattice: &dyn Lattice, nn_m: Option<f64>) -> ScanPair {
    let nn = lattice.nearest_neighbour_distance();
    let appearance = lattice.feature_appearance();
    let mut config = presets::ci_small();
    let width = 25.6 * nn;
    config.scan.width_m = width;
    config.scan.height_m = width;
    config.surface.lattice = LatticeConfig::Catalogue {
        name: name.to_string(),
        nn_m,
    };
    config.surface.angle_rad = 0.17;
    let sigma = appearance.width_fraction.unwrap_or(0.22) * nn;
    config.surface.feature = FeatureShape {
        height_m: if appearance.dark { -40e-12 } else { 40e-12 },
        sigma_m: [sigma; 2],
        angle_rad: 0.0,
        lobes: Vec::new(),
    };
    // The preset's fast speed is kept, so the slow speed and the drift relative to it are
    // the same at every frame size; the creep amplitude grows with the frame.
    let scale = width / 4e-9;
    for effect in &mut config.effects {
        if let dhct_simulate::EffectConfig::Creep(creep) = effect {
            creep.coefficient_m = creep.coefficient_m.map(|c| c * scale);
        }
    }
    Simulation::from_config(&config)
        .expect("a valid config")
        .run()
        .expect("simulates")
        .pair
}

#[test]
fn every_catalogue_lattice_is_corrected_indexed_and_symmetry_averaged() {
    let mut failures = Vec::new();
    for entry in CATALOGUE {
        let nn_m = (!entry.known_constant).then_some(GIVEN_NN_M);
        let lattice = entry.build(nn_m).expect("builds");
        let pair = simulated(entry.name, lattice.as_ref(), nn_m);
        let mut options = PipelineOptions::for_lattice(lattice.as_ref());
        options.features.line_correction = dhct_features::LineCorrection::None;
        let analysis = match run(&pair, lattice.as_ref(), None, &options, &|_| {}) {
            Ok(analysis) => analysis,
            Err(e) => {
                failures.push(format!("{}: {e}", entry.name));
                continue;
            }
        };
        // The corrected image by FFT.
        let corrected = ScanPair::new(
            pair.geometry().clone(),
            dhct_scan::ImageChannel::new("Z", "m", analysis.passes[0].corrected_image.clone()),
            None,
        )
        .expect("same grid");
        let anything = CheckOptions {
            pitch_tolerance: 100.0,
            check_lattice_type: false,
            ..CheckOptions::default()
        };
        let measured = calibrate_pair(&corrected, lattice.as_ref(), None, &anything)
            .expect("a lattice in the corrected image");
        let c = &measured.passes[0].matched.calibration;
        let indexed = analysis.passes[0].indices.iter().flatten().count() as f64
            / analysis.passes[0].features.features.len() as f64;
        let fit = &analysis.regions[0].fit;
        let rms_fraction = fit.rms_deviation_m / lattice.nearest_neighbour_distance();
        let sites = lattice.motif().len();
        let mut per_site = vec![0usize; sites];
        for point in fit.points.iter().flatten() {
            per_site[point.site] += 1;
        }
        let total = per_site.iter().sum::<usize>().max(1) as f64;
        let balanced = per_site
            .iter()
            .all(|&n| (n as f64 / total - 1.0 / sites as f64).abs() < 0.1 / sites as f64);
        let own = analysis.unit_cell.as_ref().and_then(|cell| {
            cell.residuals
                .iter()
                .find(|r| r.group == lattice.plane_group())
                .map(|r| r.residual)
        });
        println!(
            "{:10} corrected x × y {:.4} × {:.4}, shear {:.2}°; {:.1} % indexed, per site \
             {per_site:?}, RMS deviation {:.3} NN; {} residual {:?} ({:?})",
            entry.name,
            c.scale[0],
            c.scale[1],
            c.shear_deg,
            100.0 * indexed,
            rms_fraction,
            lattice.plane_group(),
            own,
            analysis.correction
        );
        let right = c.scale.iter().all(|k| (k - 1.0).abs() < 0.005)
            && c.shear_deg.abs() < 0.3
            && indexed > 0.95
            && balanced
            && rms_fraction < 0.05
            && own.is_some_and(|r| r < 0.15);
        if !right {
            failures.push(format!(
                "{}: scales {:?}, shear {:.2}°, indexed {:.3}, per site {per_site:?}, RMS \
                 deviation {rms_fraction:.3} NN, own-group residual {own:?}",
                entry.name, c.scale, c.shear_deg, indexed
            ));
        }
        assert!(
            analysis
                .passes
                .iter()
                .all(|p| p.pass == ScanPass::Trace || p.pass == ScanPass::Retrace)
        );
    }
    assert!(failures.is_empty(), "{failures:#?}");
}
