//! Bad input gives a typed error that says what is wrong — never a panic or a silent result.

use dhct_features::{FeatureError, FeatureOptions, Kernel, KernelChoice, find_features};
use dhct_scan::{ImageChannel, ScanDirection, ScanGeometry, ScanPass};
use ndarray::Array2;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

fn geometry(columns: usize, rows: usize) -> ScanGeometry {
    ScanGeometry::new(
        columns,
        rows,
        2e-11,
        2e-11,
        1e-4,
        ScanDirection::Right,
        ScanDirection::Down,
    )
    .unwrap()
}

fn lattice(size: usize) -> Array2<f64> {
    Array2::from_shape_fn((size, size), |(r, c)| {
        let (dx, dy) = ((c % 12) as f64 - 6.0, (r % 12) as f64 - 6.0);
        1e-9 + 3e-11 * (-(dx * dx + dy * dy) / 8.0).exp()
    })
}

fn run(z: Array2<f64>, options: &FeatureOptions) -> Result<usize, FeatureError> {
    let (rows, columns) = z.dim();
    let image = ImageChannel::new("Topography", "m", z);
    find_features(
        &image,
        &geometry(columns, rows),
        ScanPass::Trace,
        options,
        None,
    )
    .map(|set| set.features.len())
}

fn options() -> FeatureOptions {
    FeatureOptions::for_neighbour_distance(12.0 * 2e-11)
}

#[test]
fn flat_tiny_missing_and_lattice_free_images_are_clear_errors() {
    assert!(matches!(
        run(Array2::from_elem((64, 64), 1e-9), &options()),
        Err(FeatureError::FlatImage)
    ));
    let error = run(lattice(8), &options()).unwrap_err();
    assert!(
        matches!(error, FeatureError::ImageTooSmall { .. }),
        "{error}"
    );
    assert!(
        error.to_string().contains("nearest-neighbour distance"),
        "says what to check: {error}"
    );

    let mut holes = lattice(96);
    holes
        .iter_mut()
        .enumerate()
        .filter(|(i, _)| i % 3 != 0)
        .for_each(|(_, v)| *v = f64::NAN);
    assert!(matches!(
        run(holes, &options()),
        Err(FeatureError::MissingData { .. })
    ));
    assert!(matches!(
        run(Array2::from_elem((64, 64), f64::NAN), &options()),
        Err(FeatureError::MissingData { finite: 0, .. })
    ));

    // Pure noise has no lattice: its correlation blobs are rejected as noise-like, and the
    // error says what to check.
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let normal = Normal::new(0.0, 1e-12).unwrap();
    let noise = Array2::from_shape_fn((128, 128), |_| normal.sample(&mut rng));
    let error = run(noise, &options()).unwrap_err();
    assert!(matches!(error, FeatureError::NoiseLike { .. }), "{error}");
    assert!(error.to_string().contains("polarity"), "{error}");
}

#[test]
fn some_missing_pixels_are_tolerated() {
    let mut z = lattice(96);
    for k in 0..300 {
        z[[(k * 7) % 96, (k * 13) % 96]] = f64::NAN;
    }
    let found = run(z, &options()).unwrap();
    assert!(found >= 36, "{found}");
}

#[test]
fn wrong_parameters_name_the_parameter() {
    let bad = |options: FeatureOptions| run(lattice(96), &options).unwrap_err().to_string();
    assert!(bad(FeatureOptions::for_neighbour_distance(f64::NAN)).contains("nearest-neighbour"));
    assert!(bad(FeatureOptions::for_neighbour_distance(-1.0)).contains("nearest-neighbour"));
    assert!(
        bad(FeatureOptions {
            threshold: 1.5,
            ..options()
        })
        .contains("threshold")
    );
    assert!(
        bad(FeatureOptions {
            fit_radius_fraction: 0.0,
            ..options()
        })
        .contains("fit radius")
    );
    assert!(bad(FeatureOptions::for_neighbour_distance(1e-12)).contains("at least 2 px"));
    assert!(
        Kernel::custom(Array2::zeros((4, 5)))
            .unwrap_err()
            .to_string()
            .contains("odd")
    );
    assert!(
        bad(FeatureOptions {
            kernel: KernelChoice::GaussianSigma { sigma_px: 0.0 },
            ..options()
        })
        .contains("kernel width")
    );
}

#[test]
fn feature_sets_round_trip_through_json_and_csv_has_one_row_per_feature() {
    let image = ImageChannel::new("Topography", "m", lattice(96));
    let set = find_features(&image, &geometry(96, 96), ScanPass::Trace, &options(), None).unwrap();
    let mut json = Vec::new();
    set.write_json(&mut json).unwrap();
    let back: dhct_features::FeatureSet = serde_json::from_slice(&json).unwrap();
    assert_eq!(back, set);
    let mut csv = Vec::new();
    set.write_csv(&mut csv).unwrap();
    let text = String::from_utf8(csv).unwrap();
    assert_eq!(text.lines().count(), set.features.len() + 1);
    let header: Vec<&str> = text.lines().next().unwrap().split(',').collect();
    let names: Vec<&str> = dhct_features::FeatureRow::of(&set.features[0])
        .cells()
        .iter()
        .map(|(name, _)| *name)
        .collect();
    assert_eq!(header, names);
    assert!(text.lines().all(|l| l.split(',').count() == names.len()));
}
