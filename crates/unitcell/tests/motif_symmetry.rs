//! The contract between a lattice and its plane group: every operation of the group, about
//! the lattice's symmetry origin, maps the motif onto itself (sites onto sites of the same
//! relative height). Graphene's honeycomb is p6mm only about the hexagon centre; about an
//! atom its six-fold rotation would send atoms into the hexagon holes.

use dhct_lattice::{Hexagonal, Honeycomb, Lattice, PlaneGroup, Rectangular, Square};
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
fn every_preset_is_invariant_under_its_own_plane_group() {
    let presets: Vec<Box<dyn Lattice>> = vec![
        Box::new(Hexagonal::graphite()),
        Box::new(Hexagonal::sam_sqrt3()),
        Box::new(Hexagonal::si111_7x7()),
        Box::new(Honeycomb::graphene()),
        Box::new(Square::new(3e-10).unwrap()),
        Box::new(Rectangular::new(3e-10, 4e-10).unwrap()),
    ];
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
