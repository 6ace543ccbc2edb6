//! Neighbour geometry of the built-in and user-defined lattices against hand-derived values.

use dhct_lattice::{
    Hexagonal, Honeycomb, Lattice, LatticeError, LocalDistortionMethod, PlaneGroup, Rectangular,
    Square, UserLattice, lattice_sites,
};
use nalgebra::Vector2;

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-9 * a.abs().max(b.abs())
}

#[test]
fn graphite_has_six_neighbours_at_a_and_shells_at_a_sqrt3a_2a() {
    let g = Hexagonal::graphite();
    let nn = g.nearest_neighbours(0);
    assert_eq!(nn.len(), 6);
    for (k, v) in nn.iter().enumerate() {
        assert!(close(v.norm(), 2.46e-10));
        // Sorted by angle, 60° apart.
        if k > 0 {
            let step = v.y.atan2(v.x) - nn[k - 1].y.atan2(nn[k - 1].x);
            assert!(close(step, std::f64::consts::FRAC_PI_3), "{step}");
        }
    }
    let shells = g.neighbour_shells(4);
    let expected = [1.0, 3f64.sqrt(), 2.0, 7f64.sqrt()].map(|f| f * 2.46e-10);
    for (s, e) in shells.iter().zip(expected) {
        assert!(close(*s, e), "{shells:?}");
    }
    assert_eq!(g.plane_group(), PlaneGroup::P3m1);
    assert_eq!(g.local_distortion_method(), LocalDistortionMethod::Ellipse);
    assert!(close(
        g.cell_area(),
        0.5 * 3f64.sqrt() * 2.46e-10 * 2.46e-10
    ));
}

#[test]
fn honeycomb_sublattices_have_three_opposite_neighbours_at_a_over_sqrt3() {
    let g = Honeycomb::graphene();
    let a_site = g.nearest_neighbours(0);
    let b_site = g.nearest_neighbours(1);
    assert_eq!((a_site.len(), b_site.len()), (3, 3));
    for v in a_site.iter().chain(&b_site) {
        assert!(close(v.norm(), 2.46e-10 / 3f64.sqrt()));
    }
    // B's neighbours are A's reversed.
    for v in &a_site {
        assert!(b_site.iter().any(|w| (v + w).norm() < 1e-20));
    }
    assert_eq!(g.local_distortion_method(), LocalDistortionMethod::Affine);
    assert!(close(
        g.nearest_neighbour_distance(),
        2.46e-10 / 3f64.sqrt()
    ));
}

#[test]
fn square_and_rectangular_neighbours_span_the_plane() {
    let s = Square::new(3e-10).unwrap();
    assert_eq!(s.nearest_neighbours(0).len(), 4);
    assert_eq!(s.local_distortion_method(), LocalDistortionMethod::Affine);
    assert!(close(s.neighbour_shells(2)[1], 3e-10 * 2f64.sqrt()));
    let r = Rectangular::new(3e-10, 5e-10).unwrap();
    let nn = r.nearest_neighbours(0);
    assert_eq!(nn.len(), 4, "±a along x and ±b along y: {nn:?}");
    assert!(close(r.nearest_neighbour_distance(), 3e-10));
    assert!(Rectangular::new(3e-10, -1.0).is_err());
    assert!(matches!(
        Square::new(f64::NAN),
        Err(LatticeError::BadLength { .. })
    ));
}

#[test]
fn sam_is_hexagonal_with_a_4_99_angstrom_constant() {
    let sam = Hexagonal::sam_sqrt3();
    assert_eq!(sam.nearest_neighbours(0).len(), 6);
    assert!(close(sam.nearest_neighbour_distance(), 4.99e-10));
}

#[test]
fn lattice_sites_fill_a_region_at_the_density_of_the_cell() {
    let g = Hexagonal::graphite();
    let (w, h) = (10e-9, 8e-9);
    for angle in [0.0, 0.3, 1.0] {
        let sites = lattice_sites(&g, Vector2::new(1e-10, 2e-10), angle, w, h);
        let expected = w * h / g.cell_area();
        let found = sites.len() as f64;
        // Boundary effects are of the order of the perimeter in cells.
        assert!(
            (found - expected).abs() < 2.0 * (w + h) / 2.46e-10,
            "{found} vs {expected}"
        );
        assert!(
            sites
                .iter()
                .all(|s| s.position.x >= 0.0 && s.position.x <= w)
        );
        // Indices reproduce positions.
        for s in sites.iter().take(50) {
            let [a1, a2] = g.primitive_vectors();
            let (sin, cos) = f64::sin_cos(angle);
            let rot = nalgebra::Matrix2::new(cos, -sin, sin, cos);
            let p = Vector2::new(1e-10, 2e-10) + rot * (a1 * s.n as f64 + a2 * s.m as f64);
            assert!((p - s.position).norm() < 1e-20);
        }
    }
    let honeycomb = lattice_sites(&Honeycomb::graphene(), Vector2::zeros(), 0.0, w, h);
    let per_cell = honeycomb.len() as f64 / (w * h / Honeycomb::graphene().cell_area());
    assert!((per_cell - 2.0).abs() < 0.15, "{per_cell}");
}

#[test]
fn user_lattices_load_from_toml_and_json_with_units() {
    let toml = r#"
        name = "graphite as user lattice"
        length_unit = "A"
        a1 = [2.46, 0.0]
        a2 = [1.23, 2.1304225867]
        plane_group = "p3m1"
        [[motif]]
        fractional = [0.0, 0.0]
    "#;
    let user = UserLattice::from_toml(toml).unwrap();
    let builtin = Hexagonal::graphite();
    assert_eq!(user.nearest_neighbours(0).len(), 6);
    assert!(
        (user.nearest_neighbour_distance() - builtin.nearest_neighbour_distance()).abs() < 1e-19
    );
    assert_eq!(
        user.local_distortion_method(),
        LocalDistortionMethod::Ellipse
    );
    let json = serde_json::to_string(&user).unwrap();
    let back = UserLattice::from_json(&json).unwrap();
    assert_eq!(back, user);
}

#[test]
fn bad_user_lattices_say_what_is_wrong() {
    let base = |a2: &str, motif: &str, extra: &str| {
        format!("name = 'x'\na1 = [1e-10, 0.0]\na2 = {a2}\n{extra}\n{motif}")
    };
    let one_site = "[[motif]]\nfractional = [0.0, 0.0]\n";
    let err = |text: String| UserLattice::from_toml(&text).unwrap_err().to_string();
    assert!(err(base("[2e-10, 0.0]", one_site, "")).contains("parallel"));
    assert!(err(base("[0.0, 1e-10]", "motif = []", "")).contains("motif is empty"));
    assert!(err(base("[0.0, 1e-10]", one_site, "length_unit = 'furlong'")).contains("furlong"));
    assert!(err(base("[0.0, 1e-10]", one_site, "plane_group = 'p5'")).contains("p5"));
    let twice = "[[motif]]\nfractional = [0.0, 0.0]\n[[motif]]\nfractional = [1.0, 0.0]\n";
    assert!(err(base("[0.0, 1e-10]", twice, "")).contains("coincide"));
    assert!(err(base("[0.0, 1e-10]", one_site, "colour = 'red'")).contains("colour"));
    assert!("P6MM".parse::<PlaneGroup>().is_ok());
}
