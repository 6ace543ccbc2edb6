//! Prints the lattice a scan file shows and its calibration against a hexagonal or square
//! lattice: `cargo run -p dhct-calibrate --example measure -- FILE [hexagonal|square] [a_m]`.

use dhct_calibrate::{CheckOptions, calibrate_pair};
use dhct_lattice::{Hexagonal, Lattice, PlaneGroup, Square};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let path = args
        .first()
        .ok_or("usage: measure FILE [hexagonal|square] [a_m]")?;
    let kind = args.get(1).map_or("hexagonal", String::as_str);
    let a: f64 = args.get(2).map_or(Ok(2.46e-10), |s| s.parse())?;
    let lattice: Box<dyn Lattice> = match kind {
        "square" => Box::new(Square::new(a)?),
        _ => Box::new(Hexagonal::new("hexagonal", a, PlaneGroup::P6mm)?),
    };
    let file = dhct_sm4_io::read_path(path.as_ref())?;
    let pair = file.topography().ok_or("no topography")?;
    let options = CheckOptions {
        pitch_tolerance: 100.0,
        check_lattice_type: false,
        ..CheckOptions::default()
    };
    let found = calibrate_pair(pair, lattice.as_ref(), None, &options)?;
    for pass in &found.passes {
        println!("{}: {}", pass.pass, pass.lattice.describe());
        println!(
            "  {} peaks, {:.1} % of their power indexed",
            pass.lattice.peaks,
            100.0 * pass.lattice.indexed_power_fraction
        );
        println!("  match: {:#?}", pass.matched.calibration);
        for shell in &pass.matched.shells {
            println!(
                "  shell {:?}: snr {:?}, spread {:.1}, significant {}",
                shell.indices,
                shell.snr.iter().map(|s| s.round()).collect::<Vec<_>>(),
                shell.spread,
                shell.significant
            );
        }
        println!(
            "  check: {:?}",
            dhct_calibrate::check_inputs(
                &dhct_calibrate::measure_lattice(
                    pair.image(pass.pass).unwrap().z.view(),
                    pair.geometry(),
                    None
                )?,
                &pass.matched,
                &CheckOptions::default()
            )
            .map_err(|e| e.to_string())
        );
    }
    Ok(())
}
