//! The chain on simulated graphite with drift, creep and hysteresis: every stage produces
//! its result, regions follow the mask, bad input gives a clear error.

use dhct_lattice::Hexagonal;
use dhct_pipeline::{CellSelection, PipelineError, PipelineOptions, run};
use dhct_scan::{ImageChannel, ScanPair};
use dhct_simulate::{Simulation, presets};
use ndarray::Array2;

fn simulated() -> ScanPair {
    Simulation::from_config(&presets::ci_small())
        .unwrap()
        .run()
        .unwrap()
        .pair
}

#[test]
fn chain_on_simulated_graphite() {
    let pair = simulated();
    let graphite = Hexagonal::graphite();
    let options = PipelineOptions::for_lattice(&graphite);
    let stages = std::sync::Mutex::new(Vec::new());
    let analysis = run(&pair, &graphite, None, &options, &|s| {
        stages.lock().unwrap().push(s)
    })
    .unwrap();
    assert_eq!(
        stages.into_inner().unwrap().len(),
        6,
        "calibration, features, model, correction, lattice fit, unit cells"
    );
    assert_eq!(analysis.passes.len(), 2);
    assert_eq!(analysis.regions.len(), 1);
    let fit = &analysis.regions[0].fit;
    // The corrected lattice has graphite's constant (the raw image is stretched by
    // hysteresis and drift by several per cent).
    assert!(
        fit.scale.iter().all(|s| (s - 1.0).abs() < 0.01),
        "{:?}",
        fit.scale
    );
    // Nearly every feature is indexed, within a small fraction of a lattice constant.
    for pass in &analysis.passes {
        let indexed: Vec<_> = pass.indices.iter().flatten().collect();
        assert!(indexed.len() as f64 > 0.95 * pass.features.features.len() as f64);
        let worst = indexed
            .iter()
            .map(|i| i.deviation_m[0].hypot(i.deviation_m[1]))
            .fold(0.0, f64::max);
        assert!(worst < 0.25 * 2.46e-10, "worst deviation {worst}");
        assert!(pass.rdf_corrected.is_some());
        assert!(pass.correlation.is_some());
        assert!(pass.corrected_image.iter().any(|z| z.is_finite()));
    }
    let region = &analysis.regions[0];
    assert!(region.whole_ellipse.sigma_major_m < 20e-12);
    assert!(region.local_ellipse.is_some());
    let cell = analysis.unit_cell.as_ref().expect("unit cell");
    assert!(cell.cells_selected > 100);
    assert_eq!(cell.group, dhct_lattice::PlaneGroup::P3m1);
    assert_eq!(cell.asymmetric_unit.len(), 3);
    // The atom (cell corner) is the brightest point of the symmetrised cell.
    let corner = cell.symmetrized.values[[0, 0]];
    assert!(cell.symmetrized.values.iter().all(|&v| v <= corner + 1e-15));
    assert!(analysis.timings.total_s > 0.0);
}

#[test]
fn each_mask_region_is_its_own_domain() {
    let pair = simulated();
    let graphite = Hexagonal::graphite();
    let (rows, columns) = (pair.geometry().rows(), pair.geometry().columns());
    // Left and right halves, separated by a 20-px gap.
    let mask = Array2::from_shape_fn((rows, columns), |(_, c)| !(110..130).contains(&c));
    let analysis = run(
        &pair,
        &graphite,
        Some(&mask),
        &PipelineOptions::for_lattice(&graphite),
        &|_| {},
    )
    .unwrap();
    assert_eq!(analysis.regions.len(), 2, "{:?}", analysis.skipped_regions);
    // Features in the gap (and within one NN of it) are not indexed.
    let trace = &analysis.passes[0];
    for (f, index) in trace.features.features.iter().zip(&trace.indices) {
        if (110.0..130.0).contains(&f.x_px) {
            assert!(index.is_none());
        }
    }
    // Both halves find the same lattice.
    let [a, b] = [&analysis.regions[0].fit, &analysis.regions[1].fit];
    assert!((a.scale[0] - b.scale[0]).abs() < 0.01 && (a.scale[1] - b.scale[1]).abs() < 0.01);
}

#[test]
fn cell_selection_by_feature_height() {
    let pair = simulated();
    let graphite = Hexagonal::graphite();
    let mut options = PipelineOptions::for_lattice(&graphite);
    options.unit_cell.selection = CellSelection {
        height_m: Some([1.0, 2.0]), // metres: no feature is this tall
        ..CellSelection::default()
    };
    let analysis = run(&pair, &graphite, None, &options, &|_| {}).unwrap();
    assert!(analysis.unit_cell.is_none());
    let note = analysis.unit_cell_note.unwrap();
    assert!(note.contains("loosen the cell selection"), "{note}");

    options.unit_cell.selection = CellSelection {
        exclude_outliers_sigma: Some(1.0),
        ..CellSelection::default()
    };
    let strict = run(&pair, &graphite, None, &options, &|_| {}).unwrap();
    let cell = strict.unit_cell.unwrap();
    assert!(cell.cells_selected > 0 && cell.cells_selected < cell.cells_available);
}

#[test]
fn bad_input_is_named() {
    let pair = simulated();
    let graphite = Hexagonal::graphite();
    let options = PipelineOptions::for_lattice(&graphite);
    let small = Array2::from_elem((10, 10), true);
    let e = run(&pair, &graphite, Some(&small), &options, &|_| {}).unwrap_err();
    assert!(matches!(e, PipelineError::MaskShape { .. }), "{e}");
    let empty = Array2::from_elem((256, 256), false);
    let e = run(&pair, &graphite, Some(&empty), &options, &|_| {}).unwrap_err();
    assert!(matches!(e, PipelineError::EmptyMask), "{e}");

    // A flat image has no lattice.
    let flat = ScanPair::new(
        pair.geometry().clone(),
        ImageChannel::new("Z", "m", Array2::zeros((256, 256))),
        None,
    )
    .unwrap();
    let e = run(&flat, &graphite, None, &options, &|_| {}).unwrap_err();
    println!("flat image: {e}");
    assert!(
        matches!(
            e,
            PipelineError::Features(_) | PipelineError::TooFewFeatures { .. }
        ),
        "{e}"
    );

    let mut bad = options.clone();
    bad.unit_cell.resolution = 7;
    let e = run(&pair, &graphite, None, &bad, &|_| {}).unwrap_err();
    assert!(e.to_string().contains("resolution"), "{e}");
}
