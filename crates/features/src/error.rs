use thiserror::Error;

/// Why features could not be found.
#[derive(Debug, Error)]
pub enum FeatureError {
    #[error("invalid parameter: {0}")]
    BadParameter(String),
    #[error(
        "the image is {columns} x {rows} px, smaller than the {kernel} px kernel: check the nearest-neighbour distance and the pixel size"
    )]
    ImageTooSmall {
        columns: usize,
        rows: usize,
        kernel: usize,
    },
    #[error("the image has {finite} finite pixels out of {total}: too few to find features")]
    MissingData { finite: usize, total: usize },
    #[error("the image is flat (all values equal): there is nothing to find")]
    FlatImage,
    #[error(
        "no features found in the {pass} image ({candidates} candidate regions above NCC {threshold}; \
         rejected: {rejected}). Check the nearest-neighbour distance, the polarity (bright/dark) and the threshold"
    )]
    NoFeatures {
        pass: &'static str,
        candidates: usize,
        threshold: f64,
        rejected: String,
    },
    #[error(
        "the {count} candidate features of the {pass} image look like noise, not a lattice: their \
         median peak correlation is {median_ncc:.2} (atoms give ≳ 0.5; the limit is {limit}). \
         Check the nearest-neighbour distance, the polarity (bright/dark) and the image itself"
    )]
    NoiseLike {
        pass: &'static str,
        count: usize,
        median_ncc: f64,
        limit: f64,
    },
}
