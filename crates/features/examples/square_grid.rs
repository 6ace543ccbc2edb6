//! Finds the features of a small synthetic square lattice and prints them.
use dhct_features::{Background, FeatureOptions, find_features};
use dhct_scan::{ImageChannel, ScanDirection, ScanGeometry, ScanPass};
use ndarray::Array2;

fn main() {
    let z = Array2::from_shape_fn((66, 66), |(r, c)| {
        let (dx, dy) = ((c % 9) as f64 - 4.0, (r % 9) as f64 - 4.0);
        1e-11 * (-(dx * dx + dy * dy) / 4.0).exp()
    });
    let image = ImageChannel::new("Topography", "m", z);
    let geometry = ScanGeometry::new(
        64,
        64,
        1e-10,
        1e-10,
        1e-3,
        ScanDirection::Right,
        ScanDirection::Down,
    )
    .unwrap();
    let options = FeatureOptions {
        background: Background::None, // the image has no tilt to remove
        ..FeatureOptions::for_neighbour_distance(9e-10)
    };
    match find_features(&image, &geometry, ScanPass::Trace, &options, None) {
        Ok(set) => {
            println!(
                "{} features, rejected: {}",
                set.features.len(),
                set.rejection_counts()
            );
            for f in set.features.iter().take(10) {
                println!(
                    "{:8.4} {:8.4} {:?} t={:.4}",
                    f.x_px, f.y_px, f.status, f.time_s
                );
            }
        }
        Err(e) => println!("error: {e}"),
    }
}
