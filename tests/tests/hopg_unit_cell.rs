//! The real HOPG file end to end: features → DHCT correction of the clean terrace → lattice
//! fit with indices → confidence ellipses → averaged and symmetry-averaged unit cell.
//! (The file is vendored; its timing is assumed, which does not change the corrected image.)

use std::path::PathBuf;

use dhct_distortion::mask::polygon_mask;
use dhct_distortion::{DhctOptions, PassInput, analyse, correct_features, correct_image};
use dhct_features::{FeatureOptions, LineCorrection, find_features};
use dhct_lattice::{Hexagonal, LatticeFitOptions, PlaneGroup, fit_lattice};
use dhct_scan::ScanPass;
use dhct_unitcell::{ConfidenceEllipse, average_unit_cell, local_cells, symmetry_residuals};

/// The HOPG terrace outline (raw-image pixels) of the example config
/// `tests/data/hopg_terrace.toml`: the step edge and the superstructure next to it left out.
fn terrace() -> Vec<[f64; 2]> {
    let config: toml::Value =
        toml::from_str(include_str!("../data/hopg_terrace.toml")).expect("example config");
    config["mask_polygon"]
        .clone()
        .try_into()
        .expect("mask_polygon")
}

/// Runs the chain with the given local-distortion method; returns the fitted x/y scales.
fn run(method: Option<dhct_lattice::LocalDistortionMethod>) -> [f64; 2] {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("data/hopg_graphiteterrace.spm");
    let file = dhct_sm4_io::read_path(&path).unwrap();
    let pair = file.topography().unwrap();
    let geometry = pair.geometry();
    let image = pair.trace().unwrap();
    let graphite = Hexagonal::graphite();
    let options = FeatureOptions {
        line_correction: LineCorrection::Median,
        ..FeatureOptions::for_neighbour_distance(2.46e-10)
    };
    let set = find_features(image, geometry, ScanPass::Trace, &options, None).unwrap();
    let mask = polygon_mask(geometry.rows(), geometry.columns(), &terrace(), true);
    let inputs = [PassInput {
        features: &set.features,
        mask: Some(&mask),
    }];
    let options = DhctOptions {
        method,
        ..DhctOptions::default()
    };
    let result = analyse(&inputs, geometry, &graphite, &options).unwrap();

    // Corrected features on the terrace (well inside the polygon: ≥ 2 NN from its edge).
    let corrected = correct_features(&result.model, geometry, &set.features);
    let inside = |x: f64, y: f64| {
        let (c, r) = (x.round() as usize, y.round() as usize);
        r < geometry.rows() && c < geometry.columns() && mask[[r, c]]
    };
    let margin = 2.0 * 2.46e-10 / geometry.pitch_x();
    let keep: Vec<usize> = (0..set.features.len())
        .filter(|&i| {
            let f = &set.features[i];
            [(-1.0, 0.0), (1.0, 0.0), (0.0, -1.0), (0.0, 1.0)]
                .iter()
                .all(|(dx, dy)| inside(f.x_px + dx * margin, f.y_px + dy * margin))
        })
        .collect();
    let points: Vec<[f64; 2]> = keep
        .iter()
        .map(|&i| [corrected[i].x_m, corrected[i].y_m])
        .collect();
    let fit = fit_lattice(&graphite, &[&points], &LatticeFitOptions::default()).unwrap();
    let deviations: Vec<[f64; 2]> = fit.points[0].iter().map(|p| p.deviation_m).collect();
    let heights: Vec<f64> = keep.iter().map(|&i| set.features[i].height).collect();
    let whole = ConfidenceEllipse::from_deviations(&deviations, Some(&heights)).unwrap();
    let cells = local_cells(&graphite, &fit, &points, 0);
    let local: Vec<[f64; 2]> = cells.iter().flat_map(|c| c.deviations_m).collect();
    let local_ellipse = ConfidenceEllipse::from_deviations(&local, None).unwrap();
    let z = correct_image(&result.model, geometry, ScanPass::Trace, &image.z).unwrap();
    let averaged = average_unit_cell(
        z.view(),
        (geometry.pitch_x(), geometry.pitch_y()),
        &graphite,
        &cells,
        48,
    )
    .unwrap();
    let residuals = symmetry_residuals(&averaged, &graphite).unwrap();
    let of = |g: PlaneGroup| residuals.iter().find(|r| r.group == g).unwrap().residual;

    println!(
        "HOPG terrace ({method:?}): {} corrected features, lattice a = {:.4} Å x {:.4} Å, angle {:.2}°, rms deviation {:.1} pm",
        points.len(),
        2.46 * fit.scale[0],
        2.46 * fit.scale[1],
        fit.angle_rad.to_degrees(),
        fit.rms_deviation_m * 1e12
    );
    println!(
        "  whole-image 1σ ellipse {:.1} x {:.1} pm, σz {:.1} pm; local-cell ellipse {:.1} x {:.1} pm ({} cells)",
        whole.sigma_major_m * 1e12,
        whole.sigma_minor_m * 1e12,
        whole.sigma_z_m.unwrap() * 1e12,
        local_ellipse.sigma_major_m * 1e12,
        local_ellipse.sigma_minor_m * 1e12,
        cells.len()
    );
    println!(
        "  averaged cell of {} cells; symmetry residuals: {}",
        averaged.cells,
        residuals
            .iter()
            .map(|r| format!("{} {:.3}", r.group, r.residual))
            .collect::<Vec<_>>()
            .join(", ")
    );

    assert!(points.len() > 300, "{}", points.len());
    // Indexing is sound: nearly every feature lies within half a lattice constant of its site.
    let close = deviations
        .iter()
        .filter(|d| d[0].hypot(d[1]) < 0.5 * 2.46e-10)
        .count();
    assert!(
        close as f64 >= 0.95 * deviations.len() as f64,
        "{close} of {}",
        deviations.len()
    );
    assert!(local_ellipse.sigma_major_m < whole.sigma_major_m);
    assert!(cells.len() > 100 && averaged.cells > 100);
    // The averaged cell is brightest at the atom (its corner) and, of the three-fold groups,
    // closest to p3m1 about the atom.
    assert!(averaged.values[[0, 0]] > averaged.values[[24, 24]]);
    assert!(of(PlaneGroup::P3m1) < of(PlaneGroup::P31m), "{residuals:?}");
    fit.scale
}

#[test]
fn hopg_terrace_lattice_ellipses_and_unit_cell() {
    // The affine local map gives graphite's lattice constant within 1.5 %. The paper's ellipse
    // (algebraic conic) fit, the default for hexagonal lattices, is biased under this file's
    // noise and leaves the corrected lattice ~5 % short along y (known, left open).
    let affine = run(Some(dhct_lattice::LocalDistortionMethod::Affine));
    assert!(
        affine.iter().all(|s| (s - 1.0).abs() < 0.015),
        "affine scales {affine:?}"
    );
    let ellipse = run(None);
    assert!(
        ellipse.iter().all(|s| (s - 1.0).abs() < 0.06),
        "ellipse scales {ellipse:?}"
    );
}
