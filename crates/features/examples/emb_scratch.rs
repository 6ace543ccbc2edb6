//! scratch: embedded example, y of features by levelling, differences vs none by line.
use dhct_features::{FeatureOptions, LineCorrection, find_features};
use dhct_scan::ScanPass;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let file = dhct_sm4_io::read_path(std::env::args().nth(1).unwrap().as_str().as_ref())?;
    let pair = file.topography().ok_or("no topo")?;
    for pass in [ScanPass::Trace, ScanPass::Retrace] {
        let image = pair.image(pass).ok_or("no image")?;
        let run = |lc| {
            let o = FeatureOptions {
                line_correction: lc,
                ..FeatureOptions::for_neighbour_distance(2.46e-10)
            };
            find_features(image, pair.geometry(), pass, &o, None)
                .unwrap()
                .features
        };
        let none = run(LineCorrection::None);
        for (name, lc) in [
            ("median", LineCorrection::Median),
            ("lattice", LineCorrection::Lattice),
        ] {
            let other = run(lc);
            // match by nearest
            let mut bands = vec![(0.0, 0.0, 0usize); 16];
            let mut all = (0.0, 0.0, 0usize);
            for f in &other {
                let g = none
                    .iter()
                    .min_by(|a, b| {
                        ((a.x_px - f.x_px).hypot(a.y_px - f.y_px))
                            .total_cmp(&(b.x_px - f.x_px).hypot(b.y_px - f.y_px))
                    })
                    .unwrap();
                let (dx, dy) = (f.x_px - g.x_px, f.y_px - g.y_px);
                if dx.hypot(dy) > 1.0 {
                    continue;
                }
                let b = ((f.y_px / 16.0) as usize).min(15);
                bands[b].0 += dy;
                bands[b].1 += dy * dy;
                bands[b].2 += 1;
                all.0 += dy;
                all.1 += dy * dy;
                all.2 += 1;
            }
            println!(
                "{pass:?} {name}: mean dy {:.4} px rms {:.4} px (n {})",
                all.0 / all.2 as f64,
                (all.1 / all.2 as f64).sqrt(),
                all.2
            );
            println!(
                "  by 16-row band mean dy: {:?}",
                bands
                    .iter()
                    .map(|b| format!("{:.3}", b.0 / b.2.max(1) as f64))
                    .collect::<Vec<_>>()
            );
        }
    }
    Ok(())
}
