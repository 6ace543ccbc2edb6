//! The explicit contract items of `Lattice`, checked against geometry worked out by hand
//! (not by the code under test): neighbour counts and distances per site, the windows
//! between shells, bond directions and their period, the translation cell, and a lattice
//! file given with rounded numbers.

use std::f64::consts::PI;

use dhct_lattice::{
    CentredRectangular, Hexagonal, Kagome, Lattice, LocalDistortionMethod, Oblique, PlaneGroup,
    Rectangular, UserLattice,
};

fn close(a: f64, b: f64, tolerance: f64) -> bool {
    (a - b).abs() <= tolerance * b.abs().max(1e-300)
}

#[test]
fn rounded_graphite_keeps_six_neighbours_on_a_circle() {
    // √3/2 · 2.46 Å = 2.130422 Å, written with 4 decimals.
    let text = "name = 'g'\nlength_unit = 'A'\na1 = [2.46, 0.0]\na2 = [1.23, 2.1304]\n\
                plane_group = 'p3m1'\n[[motif]]\nfractional = [0.0, 0.0]\n";
    let rounded = UserLattice::from_toml(text).unwrap();
    assert!(rounded.shell_tolerance() > 1e-5 && rounded.shell_tolerance() <= 1e-3);
    assert_eq!(rounded.neighbour_count(0), 6);
    assert_eq!(
        rounded.local_distortion_method(),
        LocalDistortionMethod::Ellipse
    );
    // The cell is made exact for p3m1: |a2| = |a1| to rounding of f64.
    let [a1, a2] = rounded.primitive_vectors();
    assert!(close(a2.norm(), a1.norm(), 1e-12));
    let shells = rounded.neighbour_shells(3);
    assert!(close(shells[1] / shells[0], 3f64.sqrt(), 1e-9));
    // At 1e-6 (before the tolerance followed the file), a1 and a2 were two shells.
    let exact = Hexagonal::new("g", 2.46e-10, PlaneGroup::P3m1).unwrap();
    assert!(close(
        rounded.nearest_neighbour_distance(),
        exact.nearest_neighbour_distance(),
        1e-5
    ));
}

#[test]
fn an_oblique_two_site_lattice_has_sites_of_different_heights_and_two_nn_distances() {
    // a1 = (1, 0), a2 = 1.15 at 78°; sites at (0, 0) and (1/2, 1/2): the half-diagonals
    // |a2 − a1|/2 and |a1 + a2|/2 are the first two shells.
    let (b, gamma) = (1.15, 78f64.to_radians());
    let lattice = Oblique::new(1e-9, b * 1e-9, gamma, 0.6).unwrap();
    let short = (1.0 + b * b - 2.0 * b * gamma.cos()).sqrt() / 2.0 * 1e-9;
    let long = (1.0 + b * b + 2.0 * b * gamma.cos()).sqrt() / 2.0 * 1e-9;
    let distances = lattice.nearest_neighbour_distances();
    assert_eq!(distances.len(), 2);
    assert!(close(distances[0], short, 1e-9) && close(distances[1], long, 1e-9));
    assert_eq!(lattice.neighbour_counts(), vec![4]);
    // The next shell is a1 (1 nm): the window keeps it out, with a margin.
    let window = lattice.neighbour_window();
    assert!(close(window, 0.5 * (1e-9 - long) / long, 1e-9), "{window}");
    assert!(long * (1.0 + window) < 1e-9);
    // The first shell is one direction (a2 − a1): the rotation is known modulo π.
    assert_eq!(lattice.bond_directions().len(), 1);
    assert!(close(lattice.bond_direction_period(), PI, 1e-12));
    // Sites of different heights do not repeat inside the cell.
    assert_eq!(lattice.translation_cell(), lattice.primitive_vectors());
    assert!(close(lattice.motif()[1].relative_height, 0.6, 1e-12));
}

#[test]
fn kagome_sites_have_four_neighbours_in_site_dependent_directions() {
    let lattice = Kagome::new(1e-9).unwrap();
    assert!(close(lattice.nearest_neighbour_distance(), 0.5e-9, 1e-12));
    assert_eq!(lattice.neighbour_counts(), vec![4]);
    // Site A bonds along a1 and a2 (0°, 60°); site B along a1 and a2 − a1 (0°, 120°).
    let direction = |v: &nalgebra::Vector2<f64>| v.y.atan2(v.x).rem_euclid(PI).to_degrees();
    let mut a: Vec<f64> = lattice
        .nearest_neighbours(0)
        .iter()
        .map(direction)
        .collect();
    let mut b: Vec<f64> = lattice
        .nearest_neighbours(1)
        .iter()
        .map(direction)
        .collect();
    a.sort_by(f64::total_cmp);
    b.sort_by(f64::total_cmp);
    assert!(
        a.iter()
            .zip([0.0, 0.0, 60.0, 60.0])
            .all(|(x, y)| (x - y).abs() < 1e-9),
        "{a:?}"
    );
    assert!(
        b.iter()
            .zip([0.0, 0.0, 120.0, 120.0])
            .all(|(x, y)| (x - y).abs() < 1e-9),
        "{b:?}"
    );
    assert!(close(lattice.bond_direction_period(), PI / 3.0, 1e-12));
    // The next shell is √3·a/2, 73 % farther: the window is the DHCT maximum, 35 %.
    assert!(close(lattice.neighbour_window(), 0.35, 1e-12));
}

#[test]
fn a_centred_rectangle_repeats_with_its_rhombic_cell_and_has_unequal_bond_angles() {
    let lattice = CentredRectangular::new(1e-9, 1.25e-9).unwrap();
    let [t1, t2] = lattice.translation_cell();
    let area = (t1.x * t2.y - t1.y * t2.x).abs();
    assert!(close(area, 0.5 * 1.25e-18, 1e-9));
    assert!(close(
        t1.norm(),
        (1.0f64 + 1.5625).sqrt() / 2.0 * 1e-9,
        1e-9
    ));
    // Bonds at ±atan(1.25) = ±51.34°: not equally spaced, period π.
    let directions = lattice.bond_directions();
    assert_eq!(directions.len(), 2);
    assert!((directions[0].to_degrees() - 1.25f64.atan().to_degrees()).abs() < 1e-9);
    assert!(close(lattice.bond_direction_period(), PI, 1e-12));
}

#[test]
fn a_rectangle_has_neighbours_at_a_and_b_and_a_window_from_the_diagonal() {
    let lattice = Rectangular::new(1e-9, 2f64.sqrt() * 1e-9).unwrap();
    let distances = lattice.nearest_neighbour_distances();
    assert!(close(distances[0], 1e-9, 1e-12) && close(distances[1], 2f64.sqrt() * 1e-9, 1e-12));
    // The diagonal √3 is the nearest other shell: window (√3 − √2)/√2 / 2.
    let expected = 0.5 * (3f64.sqrt() - 2f64.sqrt()) / 2f64.sqrt();
    assert!(close(lattice.neighbour_window(), expected, 1e-9));
    assert!(close(
        lattice.first_shell_window(),
        0.5 * (2f64.sqrt() - 1.0),
        1e-9
    ));
}

#[test]
fn a_lieb_lattice_has_sites_of_different_neighbour_counts() {
    // docs/lattices.md's worked example, as a lattice file: the corner has 4 neighbours at
    // a/2; an edge site 2 at a/2 (collinear), so its neighbours extend to the 4 edge sites
    // of the other orientation at √2·a/2.
    let text = "name = 'lieb'\nlength_unit = 'A'\na1 = [4.0, 0.0]\na2 = [0.0, 4.0]\n\
                plane_group = 'p4mm'\nmotif = [{ fractional = [0.0, 0.0] }, \
                { fractional = [0.5, 0.0] }, { fractional = [0.0, 0.5] }]\n";
    let lieb = UserLattice::from_toml(text).unwrap();
    assert_eq!(lieb.neighbour_count(0), 4);
    assert_eq!(lieb.neighbour_count(1), 6);
    assert_eq!(lieb.neighbour_counts(), vec![4, 6]);
    let distances = lieb.nearest_neighbour_distances();
    assert!(close(distances[0], 2e-10, 1e-9) && close(distances[1], 2f64.sqrt() * 2e-10, 1e-9));
    let expected = 0.5 * (1.0 - 0.5 * 2f64.sqrt()) / (0.5 * 2f64.sqrt());
    assert!(
        close(lieb.neighbour_window(), expected, 1e-6),
        "{}",
        lieb.neighbour_window()
    );
}
