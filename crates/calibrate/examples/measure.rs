//! Prints the lattice a scan file shows and its calibration against a hexagonal or square
//! lattice: `cargo run -p dhct-calibrate --example measure -- FILE [hexagonal|square] [a_m]`.
//! Useful on a corrected image written by `dhct correct` (e.g. `corrected_trace.gsf`) to
//! check the corrected lattice independently of dhct's own lattice fit.

use dhct_calibrate::{CheckOptions, calibrate_pair, check_inputs, measure_lattice};
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
    let anything = CheckOptions {
        pitch_tolerance: 100.0,
        check_lattice_type: false,
        ..CheckOptions::default()
    };
    let found = calibrate_pair(pair, lattice.as_ref(), None, &anything)?;
    for pass in &found.passes {
        let c = &pass.matched.calibration;
        println!("{}: {}", pass.pass, pass.lattice.describe());
        println!(
            "  against a = {a:e} m: x scale {:.4} ± {:.4}, y scale {:.4} ± {:.4}, shear {:.2}°",
            c.scale[0], c.scale_sigma[0], c.scale[1], c.scale_sigma[1], c.shear_deg
        );
        let image = pair.image(pass.pass).ok_or("no image")?;
        let measurement = measure_lattice(image.z.view(), pair.geometry(), None)?;
        let fast = pair.geometry().fast_axis();
        let verdict = check_inputs(&measurement, &pass.matched, fast, &CheckOptions::default());
        println!(
            "  default check: {}",
            verdict.map_or_else(|e| e.to_string(), |()| "ok".into())
        );
    }
    Ok(())
}
