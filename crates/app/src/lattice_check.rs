//! `dhct lattice check NAME|FILE [--nn LENGTH]`: a catalogue lattice or a user lattice file
//! checked against the `Lattice` contract (`dhct_lattice::testing`), rule by rule, with what
//! the lattice is (sites, neighbour counts, shells, window, plane group) when it holds.

use anyhow::{Result, bail};
use dhct_lattice::Lattice;
use dhct_lattice::testing::violations;

use crate::setup::build_lattice;

/// Checks the lattice `name` (a catalogue name or a lattice file) of nearest-neighbour
/// distance `nn_m` (metres; the lattice's own when `None`). Returns the report; an error
/// naming every broken rule when the contract does not hold.
pub fn run(name: &str, nn_m: Option<f64>) -> Result<String> {
    let lattice = build_lattice(name, nn_m)?;
    let broken = violations(lattice.as_ref());
    if !broken.is_empty() {
        let list: Vec<String> = broken.iter().map(|v| format!("  - {v}")).collect();
        bail!(
            "{name}: the lattice breaks {} rule{} of the contract:\n{}",
            broken.len(),
            if broken.len() == 1 { "" } else { "s" },
            list.join("\n")
        );
    }
    Ok(describe(name, lattice.as_ref()))
}

/// What the lattice is, in the numbers the contract checked.
fn describe(name: &str, lattice: &dyn Lattice) -> String {
    let angstrom = |m: f64| format!("{:.4} Å", m * 1e10);
    let shells: Vec<String> = lattice
        .neighbour_shells(4)
        .into_iter()
        .map(angstrom)
        .collect();
    let origin = lattice.symmetry_origin();
    format!(
        "{name}: the lattice contract holds\n  \
         sites per cell: {}\n  \
         nearest-neighbour distance: {}\n  \
         neighbour counts per site: {:?}\n  \
         first shells: {}\n  \
         neighbour window: ±{:.1} %\n  \
         plane group: {} about ({:.4}, {:.4})\n  \
         local distortion: {:?}\n",
        lattice.motif().len(),
        angstrom(lattice.nearest_neighbour_distance()),
        lattice.neighbour_counts(),
        shells.join(", "),
        100.0 * lattice.neighbour_window(),
        lattice.plane_group().symbol(),
        origin[0],
        origin[1],
        lattice.local_distortion_method(),
    )
}
