//! Prints the Fourier peaks of a file's topography and how a named hexagonal lattice
//! explains them: `cargo run --release -p dhct-calibrate --example fourier_peaks -- FILE NN_M
//! [TOLERANCE]` (a hexagonal lattice of nearest-neighbour distance `NN_M` metres; the
//! pixel-size tolerance defaults to 0.15).

use dhct_calibrate::{CheckOptions, check_inputs, measure_lattice};
use dhct_lattice::{Hexagonal, PlaneGroup};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let (Some(path), Some(which)) = (args.get(1), args.get(2)) else {
        eprintln!("usage: fourier_peaks FILE NN_M|CATALOGUE_NAME [TOLERANCE]");
        std::process::exit(2);
    };
    let lattice: Box<dyn dhct_lattice::Lattice + Send + Sync> = match which.parse::<f64>() {
        Ok(nn) => Box::new(Hexagonal::new("hexagonal", nn, PlaneGroup::P6mm).unwrap()),
        Err(_) => dhct_lattice::catalogue::lookup(which)
            .expect("a catalogue lattice")
            .build(None)
            .unwrap(),
    };
    let lattice = lattice.as_ref();
    let tolerance = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(0.15);
    let file = dhct_sm4_io::read_path(std::path::Path::new(path)).expect("a readable file");
    let pair = file.topography().expect("a topography");
    let geometry = pair.geometry();
    let (_, image) = pair.images().next().expect("an image");
    let measured = measure_lattice(image.z.view(), geometry, None).expect("a lattice");
    println!("blind: {}", measured.lattice.describe());
    for noise in &measured.periodic_noise {
        println!(
            "  periodic noise: {:.1} Hz, period {:.3e} m, {} peaks, power {:.2e}",
            noise.frequency_hz, noise.period_m, noise.peaks, noise.relative_power
        );
    }
    for r in &measured.lattice.reflections {
        println!(
            "  blind index {:?} at {:?} snr {:.1}",
            r.index, r.frequency_per_m, r.snr
        );
    }
    for p in measured.peaks().iter().take(48) {
        println!(
            "  k = ({:7.2}, {:7.2}) bins  power {:9.3e}  snr {:8.1}",
            p.k[0], p.k[1], p.power, p.snr
        );
    }
    let options = CheckOptions {
        pitch_tolerance: tolerance,
        ..CheckOptions::default()
    };
    match check_inputs(&measured, lattice, geometry.fast_axis(), &options) {
        Ok(m) => println!(
            "fit: scale {:?} shear {:.2}° anisotropy {:.3} explained {:.2}; unexplained {:?}",
            m.calibration.scale,
            m.calibration.shear_deg,
            m.calibration.anisotropy,
            m.explained_fraction,
            m.unexplained
        ),
        Err(e) => println!("refused: {e}"),
    }
    for tolerance in [0.15, 0.75, f64::MAX] {
        let options = CheckOptions {
            pitch_tolerance: tolerance,
            ..CheckOptions::default()
        };
        let bounds = options.bounds(geometry.fast_axis());
        if let Some(m) = dhct_calibrate::match_lattice(&measured, lattice, &bounds) {
            println!(
                "tolerance {tolerance:.2}: scale {:?} rotation {:.1} explained {:.2} coverage {:.2} explains {}",
                m.calibration.scale,
                m.calibration.rotation_deg,
                m.explained_fraction,
                m.primary_coverage,
                m.explains_image
            );
            for shell in &m.shells {
                println!(
                    "  shell {:.3e}/m: {:?} relative power {:?}",
                    shell.frequency_per_m, shell.indices, shell.relative_power
                );
            }
            println!("  cell in file {:?}", m.cell_in_file_m);
        }
    }
}
