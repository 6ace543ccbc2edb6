//! Confidence ellipses and averaged unit cells against simulator ground truth.

use dhct_features::{FeatureOptions, FeatureSet, find_features};
use dhct_lattice::{Hexagonal, LatticeFit, LatticeFitOptions, fit_lattice};
use dhct_scan::ScanPass;
use dhct_simulate::{NoiseConfig, Simulation, SimulationConfig, SimulationOutput, presets};
use dhct_unitcell::{ConfidenceEllipse, average_unit_cell, local_cells, tile};
use nalgebra::Matrix2;

/// Graphite at the headline pixel size, 512², no distortion, white noise `noise` (m).
fn config(noise: f64) -> SimulationConfig {
    let mut config = presets::headline_2048();
    config.scan.columns = 512;
    config.scan.rows = 512;
    config.scan.width_m = 6.25e-9;
    config.scan.height_m = 6.25e-9;
    config.surface.angle_rad = 0.2;
    config.effects.clear();
    config.noise = NoiseConfig {
        white_sigma_m: noise,
        ..NoiseConfig::default()
    };
    config
}

fn analyse(config: &SimulationConfig) -> (SimulationOutput, FeatureSet, Vec<[f64; 2]>, LatticeFit) {
    let output = Simulation::from_config(config).unwrap().run().unwrap();
    let options = FeatureOptions::for_neighbour_distance(2.46e-10);
    let set = find_features(
        output.pair.trace().unwrap(),
        &output.truth.geometry,
        ScanPass::Trace,
        &options,
        None,
    )
    .unwrap();
    let points: Vec<[f64; 2]> = set.features.iter().map(|f| [f.x_m, f.y_m]).collect();
    let fit = fit_lattice(
        &Hexagonal::graphite(),
        &[&points],
        &LatticeFitOptions::default(),
    )
    .unwrap();
    (output, set, points, fit)
}

#[test]
fn ellipse_recovers_the_true_localisation_noise_within_10_percent() {
    let (output, set, _, fit) = analyse(&config(6e-12));
    let deviations: Vec<[f64; 2]> = fit.points[0].iter().map(|p| p.deviation_m).collect();
    let heights: Vec<f64> = set.features.iter().map(|f| f.height).collect();
    let ellipse = ConfidenceEllipse::from_deviations(&deviations, Some(&heights)).unwrap();

    // The truth: each feature's error against its true position, as a covariance.
    let pitch = output.truth.geometry.pitch_x();
    let mut covariance = Matrix2::zeros();
    for f in &set.features {
        let t = output
            .truth
            .features
            .iter()
            .map(|t| t.trace.controller_position_px)
            .min_by(|a, b| {
                (a[0] - f.x_px)
                    .hypot(a[1] - f.y_px)
                    .total_cmp(&(b[0] - f.x_px).hypot(b[1] - f.y_px))
            })
            .unwrap();
        let e = nalgebra::Vector2::new((f.x_px - t[0]) * pitch, (f.y_px - t[1]) * pitch);
        covariance += e * e.transpose() / set.features.len() as f64;
    }
    let eigen = covariance.symmetric_eigen();
    let (true_major, true_minor) = (
        eigen.eigenvalues.max().sqrt(),
        eigen.eigenvalues.min().sqrt(),
    );
    println!(
        "ellipse {:.2} x {:.2} pm (truth {:.2} x {:.2} pm), σ_z {:.2} pm, {} features",
        ellipse.sigma_major_m * 1e12,
        ellipse.sigma_minor_m * 1e12,
        true_major * 1e12,
        true_minor * 1e12,
        ellipse.sigma_z_m.unwrap() * 1e12,
        ellipse.count
    );
    assert!((ellipse.sigma_major_m / true_major - 1.0).abs() < 0.1);
    assert!((ellipse.sigma_minor_m / true_minor - 1.0).abs() < 0.1);

    // Local cells: one per complete cell; their corner deviations are smaller than the
    // whole-image ones only by the fitted degrees of freedom.
    let points: Vec<[f64; 2]> = set.features.iter().map(|f| [f.x_m, f.y_m]).collect();
    let cells = local_cells(&Hexagonal::graphite(), &fit, &points, 0);
    assert!(cells.len() > 500, "{} cells", cells.len());
    let local: Vec<[f64; 2]> = cells.iter().flat_map(|c| c.deviations_m).collect();
    let local_ellipse = ConfidenceEllipse::from_deviations(&local, None).unwrap();
    assert!(local_ellipse.sigma_major_m < ellipse.sigma_major_m);
    let outline = ellipse.outline([0.0, 0.0], 2.0, 36);
    let r = outline[0][0].hypot(outline[0][1]);
    assert!((r / (2.0 * ellipse.sigma_major_m) - 1.0).abs() < 1e-9);
}

#[test]
fn averaged_cell_reproduces_the_true_motif() {
    let graphite = Hexagonal::graphite();
    let average = |noise: f64| {
        let (output, _, points, fit) = analyse(&config(noise));
        let cells = local_cells(&graphite, &fit, &points, 0);
        let g = &output.truth.geometry;
        let image = output.pair.trace().unwrap();
        average_unit_cell(
            image.z.view(),
            (g.pitch_x(), g.pitch_y()),
            &graphite,
            &cells,
            48,
        )
        .unwrap()
    };
    let noisy = average(6e-12);
    let clean = average(0.0);
    let correlation = {
        let (a, b) = (&noisy.values, &clean.values);
        let (ma, mb) = (a.mean().unwrap(), b.mean().unwrap());
        let cov: f64 = a.iter().zip(b).map(|(x, y)| (x - ma) * (y - mb)).sum();
        let va: f64 = a.iter().map(|x| (x - ma).powi(2)).sum();
        let vb: f64 = b.iter().map(|y| (y - mb).powi(2)).sum();
        cov / (va * vb).sqrt()
    };
    println!(
        "{} cells averaged, correlation with the noise-free cell {correlation:.5}",
        noisy.cells
    );
    assert!(noisy.cells > 500);
    assert!(correlation >= 0.99, "{correlation}");
    // The atom sits at the cell corner: the corners are the brightest samples.
    let corner = clean.values[[0, 0]];
    let centre = clean.values[[24, 24]];
    assert!(corner > centre, "{corner} vs {centre}");
    let tiled = tile(&clean, 3, 2);
    assert_eq!(tiled.dim(), (96, 144));
    assert_eq!(tiled[[48, 96]], clean.values[[0, 0]]);
}

#[test]
fn p3m1_averaging_restores_the_symmetric_motif_of_a_tip_asymmetric_image() {
    use dhct_lattice::PlaneGroup;
    use dhct_unitcell::{operations, symmetrize, symmetry_residuals};
    let graphite = Hexagonal::graphite();
    let cell_for = |sigma: [f64; 2], angle: f64| {
        let mut c = config(2e-12);
        c.surface.feature.sigma_m = sigma;
        c.surface.feature.angle_rad = angle;
        let (output, _, points, fit) = analyse(&c);
        let cells = local_cells(&graphite, &fit, &points, 0);
        let g = &output.truth.geometry;
        average_unit_cell(
            output.pair.trace().unwrap().z.view(),
            (g.pitch_x(), g.pitch_y()),
            &graphite,
            &cells,
            48,
        )
        .unwrap()
    };
    // An asymmetric tip images each atom as an ellipse; the symmetric reference has the same
    // second moment (the 3-fold average of the ellipse's quadratic form is isotropic).
    let (s1, s2) = (0.75e-10, 0.5e-10);
    let asymmetric = cell_for([s1, s2], 0.4);
    let reference = cell_for([((s1 * s1 + s2 * s2) / 2.0).sqrt(); 2], 0.0);
    let correlation = |a: &ndarray::Array2<f64>, b: &ndarray::Array2<f64>| {
        let (ma, mb) = (a.mean().unwrap(), b.mean().unwrap());
        let cov: f64 = a.iter().zip(b).map(|(x, y)| (x - ma) * (y - mb)).sum();
        let va: f64 = a.iter().map(|x| (x - ma).powi(2)).sum();
        let vb: f64 = b.iter().map(|y| (y - mb).powi(2)).sum();
        cov / (va * vb).sqrt()
    };
    let residual = |cell: &dhct_unitcell::AveragedCell| {
        symmetry_residuals(cell, &graphite)
            .unwrap()
            .into_iter()
            .find(|r| r.group == PlaneGroup::P3m1)
            .unwrap()
            .residual
    };
    let symmetric = symmetrize(
        &asymmetric,
        &operations(PlaneGroup::P3m1, &graphite).unwrap(),
    )
    .unwrap();
    let before = correlation(&asymmetric.values, &reference.values);
    let after = correlation(&symmetric.values, &reference.values);
    println!(
        "p3m1 residual {:.3} -> {:.2e}; correlation with the symmetric motif {before:.4} -> {after:.4}",
        residual(&asymmetric),
        residual(&symmetric)
    );
    assert!(
        residual(&asymmetric) > 0.05,
        "the tip must break the symmetry"
    );
    assert!(residual(&symmetric) < 1e-12);
    assert!(after >= 0.99 && after > before, "{before} -> {after}");
}
