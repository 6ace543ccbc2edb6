//! Every feature of a 1024² simulated graphite image gets exactly the right lattice indices
//! (up to the one global relabelling any fit is free to choose), end to end: simulator →
//! feature finding → whole-image lattice fit.

use dhct_features::{FeatureOptions, find_features};
use dhct_lattice::{Hexagonal, LatticeFitOptions, fit_lattice};
use dhct_scan::ScanPass;
use dhct_simulate::surface::FeatureKind;
use dhct_simulate::{Simulation, presets};
use nalgebra::{Matrix2, Vector2};

#[test]
fn indices_are_exact_for_every_feature_of_a_1024_image() {
    // The headline surface and noise on 1024² px (12.2 pm pixels), without distortion, so the
    // features sit on the ideal lattice (in the controller frame = sample frame).
    let mut config = presets::headline_2048();
    config.scan.columns = 1024;
    config.scan.rows = 1024;
    config.scan.width_m = 12.5e-9;
    config.scan.height_m = 12.5e-9;
    config.surface.angle_rad = 0.35;
    config.effects.clear();
    let output = Simulation::from_config(&config).unwrap().run().unwrap();
    let image = output.pair.trace().unwrap();
    let options = FeatureOptions::for_neighbour_distance(2.46e-10);
    let set = find_features(
        image,
        &output.truth.geometry,
        ScanPass::Trace,
        &options,
        None,
    )
    .unwrap();
    let points: Vec<[f64; 2]> = set.features.iter().map(|f| [f.x_m, f.y_m]).collect();
    let graphite = Hexagonal::graphite();
    let fit = fit_lattice(&graphite, &[&points], &LatticeFitOptions::default()).unwrap();
    println!(
        "{} features; fit angle {:.5} rad, scales {:?}, rms deviation {:.2} pm",
        points.len(),
        fit.angle_rad,
        fit.scale,
        fit.rms_deviation_m * 1e12
    );

    // Truth for each feature: the lattice site imaged nearest to it.
    let pitch = output.truth.geometry.pitch_x();
    let truth: Vec<(i64, i64)> = set
        .features
        .iter()
        .map(|f| {
            let nearest = output
                .truth
                .features
                .iter()
                .min_by(|a, b| {
                    let d = |t: &dhct_simulate::FeatureTruth| {
                        let p = t.trace.controller_position_px;
                        (p[0] - f.x_px).hypot(p[1] - f.y_px)
                    };
                    d(a).total_cmp(&d(b))
                })
                .unwrap();
            let p = nearest.trace.controller_position_px;
            assert!(
                (p[0] - f.x_px).hypot(p[1] - f.y_px) * pitch < 0.5e-10,
                "feature far from any atom"
            );
            match nearest.kind {
                FeatureKind::LatticeSite { n, m, .. } => (n, m),
                other => panic!("unexpected truth kind {other:?}"),
            }
        })
        .collect();
    let fitted: Vec<(i64, i64)> = fit.points[0].iter().map(|p| (p.n, p.m)).collect();

    // One global relabelling fitted = U·true + t must explain every feature.
    let count = fitted.len() as f64;
    let centre = |v: &[(i64, i64)]| {
        Vector2::new(
            v.iter().map(|p| p.0 as f64).sum::<f64>() / count,
            v.iter().map(|p| p.1 as f64).sum::<f64>() / count,
        )
    };
    let (ct, cf) = (centre(&truth), centre(&fitted));
    let (mut ata, mut bta) = (Matrix2::zeros(), Matrix2::zeros());
    for (t, f) in truth.iter().zip(&fitted) {
        let a = Vector2::new(t.0 as f64, t.1 as f64) - ct;
        let b = Vector2::new(f.0 as f64, f.1 as f64) - cf;
        ata += a * a.transpose();
        bta += b * a.transpose();
    }
    let u = (bta * ata.try_inverse().unwrap()).map(|v| v.round() as i64);
    assert_eq!(
        (u[(0, 0)] * u[(1, 1)] - u[(0, 1)] * u[(1, 0)]).abs(),
        1,
        "{u}"
    );
    let apply = |t: (i64, i64)| {
        (
            u[(0, 0)] * t.0 + u[(0, 1)] * t.1,
            u[(1, 0)] * t.0 + u[(1, 1)] * t.1,
        )
    };
    let first = apply(truth[0]);
    let offset = (fitted[0].0 - first.0, fitted[0].1 - first.1);
    let wrong = truth
        .iter()
        .zip(&fitted)
        .filter(|(t, f)| {
            let e = apply(**t);
            (e.0 + offset.0, e.1 + offset.1) != **f
        })
        .count();
    // 12.5 nm x 12.5 nm holds ~2980 atoms; the kernel-radius border is edge-cut.
    assert!(points.len() > 2_700, "{} features", points.len());
    assert_eq!(wrong, 0, "{wrong} of {} features mis-indexed", fitted.len());
}
