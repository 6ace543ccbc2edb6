//! Finds features in the topography trace of any supported file and writes them as CSV.
//!
//! `cargo run --release -p dhct-features --example find_in_file -- FILE NN_METRES [dark] > features.csv`
use dhct_features::{FeatureOptions, LineCorrection, Polarity, find_features};
use dhct_scan::ScanPass;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        return Err("usage: find_in_file FILE NN_METRES [dark]".into());
    }
    let file = dhct_sm4_io::read_path(args[1].as_ref())?;
    let pair = file.topography().ok_or("no topography channel")?;
    let image = pair.trace().ok_or("no trace image")?;
    let options = FeatureOptions {
        line_correction: LineCorrection::Median,
        polarity: if args.get(3).is_some_and(|a| a == "dark") {
            Polarity::Dark
        } else {
            Polarity::Bright
        },
        ..FeatureOptions::for_neighbour_distance(args[2].parse()?)
    };
    let set = find_features(image, pair.geometry(), ScanPass::Trace, &options, None)?;
    eprintln!(
        "{} features; rejected: {}",
        set.features.len(),
        set.rejection_counts()
    );
    set.write_csv(&mut std::io::stdout().lock())?;
    Ok(())
}
