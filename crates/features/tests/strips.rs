//! The correlation computed in strips (bounded memory for huge scans) finds the same
//! features at the same positions as the correlation of the whole image in one piece:
//! every position within 0.1 pm, on a simulated 768² headline-like image with drift,
//! creep, hysteresis and noise.

use dhct_features::{FeatureOptions, LineCorrection, find_features_in_pair};
use dhct_simulate::{Simulation, presets};

#[test]
fn strips_and_one_piece_give_the_same_features() {
    let mut config = presets::headline_2048();
    let pitch = config.scan.width_m / config.scan.columns as f64;
    config.scan.columns = 768;
    config.scan.rows = 768;
    config.scan.width_m = 768.0 * pitch;
    config.scan.height_m = 768.0 * pitch;
    let pair = Simulation::from_config(&config)
        .unwrap()
        .run()
        .unwrap()
        .pair;
    let with_strips = |rows: usize| FeatureOptions {
        line_correction: LineCorrection::Median,
        correlation_strip_rows: rows,
        ..FeatureOptions::for_neighbour_distance(2.46e-10)
    };
    let one_piece = find_features_in_pair(&pair, &with_strips(768)).unwrap();
    for rows in [0, 100] {
        let strips = find_features_in_pair(&pair, &with_strips(rows)).unwrap();
        for (a, b) in one_piece.iter().zip(&strips) {
            assert!(a.features.len() > 1000);
            assert_eq!(a.features.len(), b.features.len(), "strips of {rows} rows");
            let worst_m = a
                .features
                .iter()
                .zip(&b.features)
                .map(|(p, q)| (p.x_px - q.x_px).hypot(p.y_px - q.y_px) * pitch)
                .fold(0.0, f64::max);
            assert!(worst_m < 0.1e-12, "strips of {rows} rows: {worst_m:e} m");
        }
    }
}
