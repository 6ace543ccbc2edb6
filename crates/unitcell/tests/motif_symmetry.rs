//! The contract between a lattice and its plane group: every operation of the group, about
//! the lattice's symmetry origin, maps the motif onto itself (sites onto sites of the same
//! relative height). Every catalogue entry is checked (a new entry gets this test for
//! free). Graphene's honeycomb is p6mm only about the hexagon centre; about an atom its
//! six-fold rotation would send atoms into the hexagon holes.

use dhct_lattice::{CATALOGUE, Honeycomb, Kagome, Lattice, PlaneGroup, UserLattice};
use dhct_unitcell::operations;

fn maps_motif_onto_itself(lattice: &dyn Lattice, group: PlaneGroup) -> bool {
    let ops = operations(group, lattice).expect("a compatible group");
    let motif = lattice.motif();
    ops.iter().all(|op| {
        motif.iter().all(|site| {
            let [u, v] = site.fractional;
            let [[a, b], [c, d]] = op.matrix;
            let image = [
                a as f64 * u + b as f64 * v + op.translation[0],
                c as f64 * u + d as f64 * v + op.translation[1],
            ];
            motif.iter().any(|other| {
                let close = |x: f64, y: f64| {
                    let d = x - y;
                    (d - d.round()).abs() < 1e-9
                };
                close(image[0], other.fractional[0])
                    && close(image[1], other.fractional[1])
                    && other.relative_height == site.relative_height
            })
        })
    })
}

#[test]
fn every_catalogue_entry_is_invariant_under_its_own_plane_group() {
    let presets: Vec<Box<dyn Lattice + Send + Sync>> = CATALOGUE
        .iter()
        .map(|entry| entry.build(Some(3e-10)).expect("builds"))
        .collect();
    assert!(presets.len() >= 10);
    for lattice in &presets {
        assert!(
            maps_motif_onto_itself(lattice.as_ref(), lattice.plane_group()),
            "{}: {:?} about {:?}",
            lattice.name(),
            lattice.plane_group(),
            lattice.symmetry_origin()
        );
    }
}

#[test]
fn graphene_is_p6mm_about_the_hexagon_centre_only() {
    let graphene = Honeycomb::graphene();
    assert!(maps_motif_onto_itself(&graphene, PlaneGroup::P6mm));
    // About an atom (the origin an implementation might assume) p6mm fails: the check
    // can tell.
    #[derive(Debug)]
    struct AboutAnAtom(Honeycomb);
    impl Lattice for AboutAnAtom {
        fn name(&self) -> &str {
            "honeycomb about an atom"
        }
        fn primitive_vectors(&self) -> [nalgebra::Vector2<f64>; 2] {
            self.0.primitive_vectors()
        }
        fn motif(&self) -> &[dhct_lattice::MotifSite] {
            self.0.motif()
        }
        fn plane_group(&self) -> PlaneGroup {
            PlaneGroup::P6mm
        }
    }
    assert!(!maps_motif_onto_itself(
        &AboutAnAtom(Honeycomb::graphene()),
        PlaneGroup::P6mm
    ));
}

#[test]
fn kagome_is_p6mm_about_the_hexagon_centre_only() {
    let kagome = Kagome::new(5e-10).unwrap();
    assert!(maps_motif_onto_itself(&kagome, PlaneGroup::P6mm));
    // The same motif as a lattice file, about a site: refused, naming the rotation.
    let file = "name = 'kagome about a site'\nlength_unit = 'A'\na1 = [5.0, 0.0]\n\
                a2 = [2.5, 4.3301]\nplane_group = 'p6mm'\n\
                motif = [{ fractional = [0.0, 0.0] }, { fractional = [0.5, 0.0] }, \
                { fractional = [0.0, 0.5] }]\n";
    let error = UserLattice::from_toml(file).unwrap_err().to_string();
    assert!(error.contains("6-fold rotation"), "{error}");
    let about_centre = UserLattice::from_toml(&format!("{file}symmetry_origin = [0.5, 0.5]\n"))
        .expect("p6mm about the hexagon centre");
    // The rounded file (4 decimals) gives the exact cell: the unit cell's operations accept it.
    assert!(maps_motif_onto_itself(&about_centre, PlaneGroup::P6mm));
    assert_eq!(about_centre.nearest_neighbours(1).len(), 4);
}
