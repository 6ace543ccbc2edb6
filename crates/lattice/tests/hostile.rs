//! Hostile lattice files and fit options: errors that name the problem, bounded work, no
//! panic and no hang.

use std::time::{Duration, Instant};

use dhct_lattice::{
    Hexagonal, Lattice, LatticeError, LatticeFitError, LatticeFitOptions, MotifSite, PlaneGroup,
    Rectangular, UserLattice, fit_lattice, lattice_sites,
};
use nalgebra::Vector2;

fn lattice_toml(a1: &str, a2: &str, motif: &str) -> String {
    format!("name = 'x'\nlength_unit = 'A'\na1 = {a1}\na2 = {a2}\n{motif}")
}

fn site(f1: f64, f2: f64) -> String {
    format!("[[motif]]\nfractional = [{f1:e}, {f2:e}]\n")
}

#[test]
fn ten_thousand_motif_sites_are_refused_quickly() {
    let motif: String = (0..10_000)
        .map(|k| site((k % 100) as f64 / 100.0, (k / 100) as f64 / 100.0))
        .collect();
    let start = Instant::now();
    let error = UserLattice::from_toml(&lattice_toml("[300.0, 0.0]", "[0.0, 300.0]", &motif))
        .expect_err("too many sites");
    assert!(start.elapsed() < Duration::from_secs(5));
    let message = error.to_string();
    assert!(
        message.contains("10000 sites") && message.contains("256"),
        "{message}"
    );
}

#[test]
fn huge_and_non_finite_coordinates_are_errors_and_large_ones_are_wrapped() {
    let error =
        UserLattice::from_toml(&lattice_toml("[3.0, 0.0]", "[0.0, 3.0]", &site(1e300, 0.0)))
            .expect_err("huge fractional coordinate");
    assert!(
        error.to_string().contains("motif site 0") && error.to_string().contains("1000 cells"),
        "{error}"
    );
    let error = UserLattice::new(
        "nan",
        Vector2::new(3e-10, 0.0),
        Vector2::new(0.0, 3e-10),
        PlaneGroup::P1,
        vec![MotifSite::new(f64::NAN, 0.0, "")],
    )
    .expect_err("NaN coordinate");
    assert!(matches!(error, LatticeError::BadSite { .. }), "{error}");
    let mut tall = MotifSite::new(0.0, 0.0, "");
    tall.relative_height = f64::INFINITY;
    let error = UserLattice::new(
        "inf",
        Vector2::new(3e-10, 0.0),
        Vector2::new(0.0, 3e-10),
        PlaneGroup::P1,
        vec![tall],
    )
    .expect_err("infinite height");
    assert!(matches!(error, LatticeError::BadHeight { .. }), "{error}");
    for (a1, a2) in [
        ("[nan, 0.0]", "[0.0, 3.0]"),
        ("[1e300, 0.0]", "[0.0, 3.0]"),
        ("[1e-30, 0.0]", "[0.0, 1e-30]"),
    ] {
        assert!(
            UserLattice::from_toml(&lattice_toml(a1, a2, &site(0.0, 0.0))).is_err(),
            "{a1} {a2}"
        );
    }
    // A site hundreds of cells away is the same feature set as one inside the cell: the
    // neighbours are found as quickly and are the same.
    let far = UserLattice::from_toml(&lattice_toml(
        "[3.0, 0.0]",
        "[0.0, 3.0]",
        &format!("{}{}", site(0.0, 0.0), site(900.5, -700.5)),
    ))
    .expect("a far but finite site is valid");
    let near = UserLattice::from_toml(&lattice_toml(
        "[3.0, 0.0]",
        "[0.0, 3.0]",
        &format!("{}{}", site(0.0, 0.0), site(0.5, 0.5)),
    ))
    .unwrap();
    let start = Instant::now();
    assert_eq!(
        far.nearest_neighbours(0).len(),
        near.nearest_neighbours(0).len()
    );
    assert!((far.nearest_neighbour_distance() - near.nearest_neighbour_distance()).abs() < 1e-18);
    assert!(start.elapsed() < Duration::from_secs(2));
}

#[test]
fn nearly_parallel_and_elongated_vectors_are_errors_naming_the_angle() {
    let error =
        UserLattice::from_toml(&lattice_toml("[3.0, 0.0]", "[3.0, 0.001]", &site(0.0, 0.0)))
            .expect_err("nearly parallel");
    assert!(
        error.to_string().contains("0.0191° apart, nearly parallel"),
        "{error}"
    );
    let error = UserLattice::new(
        "skewed",
        Vector2::new(3e-10, 0.0),
        Vector2::new(3e-10, 1e-13),
        PlaneGroup::P1,
        vec![MotifSite::new(0.0, 0.0, "")],
    )
    .expect_err("nearly parallel");
    assert!(
        matches!(error, LatticeError::NearlyParallel { .. }),
        "{error}"
    );
    let error =
        UserLattice::from_toml(&lattice_toml("[3.0, 0.0]", "[0.0, 300.0]", &site(0.0, 0.0)))
            .expect_err("elongated");
    assert!(error.to_string().contains("factor 1.0000e2"), "{error}");
    // Exactly parallel stays "parallel or zero".
    let error = UserLattice::from_toml(&lattice_toml("[3.0, 0.0]", "[6.0, 0.0]", &site(0.0, 0.0)))
        .expect_err("parallel");
    assert!(error.to_string().contains("parallel or zero"), "{error}");
}

#[test]
fn neighbour_searches_of_extreme_presets_are_bounded() {
    // Presets are not validated like user lattices; their searches are capped instead.
    let thin = Rectangular::new(1e-10, 1e-5).expect("a valid if absurd rectangle");
    let start = Instant::now();
    let _ = thin.nearest_neighbours(0);
    let shells = thin.neighbour_shells(10_000);
    assert!(!shells.is_empty() && shells.len() <= 64);
    assert!(
        start.elapsed() < Duration::from_secs(10),
        "{:?}",
        start.elapsed()
    );
    // Regions far larger than any image give no sites instead of exhausting memory.
    let graphite = Hexagonal::graphite();
    assert!(lattice_sites(&graphite, Vector2::zeros(), 0.0, 1.0, 1.0).is_empty());
    assert!(lattice_sites(&graphite, Vector2::new(f64::NAN, 0.0), 0.0, 1e-9, 1e-9).is_empty());
}

fn graphite_points() -> Vec<[f64; 2]> {
    let graphite = Hexagonal::graphite();
    lattice_sites(&graphite, Vector2::new(1e-11, 2e-11), 0.2, 5e-9, 5e-9)
        .into_iter()
        .map(|s| [s.position.x, s.position.y])
        .collect()
}

#[test]
fn fit_options_are_validated_with_key_value_and_range() {
    let points = graphite_points();
    let graphite = Hexagonal::graphite();
    for (options, key) in [
        (
            LatticeFitOptions {
                initial_radius: f64::NAN,
                ..Default::default()
            },
            "initial_radius",
        ),
        (
            LatticeFitOptions {
                initial_radius: 1e9,
                ..Default::default()
            },
            "initial_radius",
        ),
        (
            LatticeFitOptions {
                nn_window: -0.1,
                ..Default::default()
            },
            "nn_window",
        ),
        (
            LatticeFitOptions {
                max_deviation_fraction: f64::INFINITY,
                ..Default::default()
            },
            "max_deviation_fraction",
        ),
        (
            LatticeFitOptions {
                min_fraction_ok: 2.0,
                ..Default::default()
            },
            "min_fraction_ok",
        ),
    ] {
        let start = Instant::now();
        let error = fit_lattice(&graphite, &[&points], &options).expect_err(key);
        assert!(start.elapsed() < Duration::from_secs(2));
        let message = error.to_string();
        assert!(
            matches!(error, LatticeFitError::BadOption { .. }) && message.contains(key),
            "{message}"
        );
    }
    let fit = fit_lattice(&graphite, &[&points], &LatticeFitOptions::default()).unwrap();
    assert!(fit.converged, "a clean lattice converges");
    // Unknown keys in a config are errors, not silently ignored.
    assert!(toml::from_str::<LatticeFitOptions>("initial_radiuss = 3.0").is_err());
}
