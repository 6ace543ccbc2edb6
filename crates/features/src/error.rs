use thiserror::Error;

/// Why features could not be found.
#[derive(Debug, Error)]
pub enum FeatureError {
    /// An option or input is out of range or unusable.
    #[error("invalid parameter: {0}")]
    BadParameter(String),
    /// The image is smaller than the correlation kernel.
    #[error(
        "the image is {columns} x {rows} px, smaller than the {kernel} px kernel: check the nearest-neighbour distance and the pixel size"
    )]
    ImageTooSmall {
        /// Image columns, pixels.
        columns: usize,
        /// Image rows, pixels.
        rows: usize,
        /// The kernel's larger side, pixels.
        kernel: usize,
    },
    /// Too many pixels are NaN or infinite (or masked out) to work with.
    #[error("the image has {finite} finite pixels out of {total}: too few to find features")]
    MissingData {
        /// Pixels usable.
        finite: usize,
        /// Pixels in the image.
        total: usize,
    },
    /// Every pixel has the same value.
    #[error("the image is flat (all values equal): there is nothing to find")]
    FlatImage,
    /// No candidate region became a feature.
    #[error(
        "no features found in the {pass} image ({candidates} candidate regions above NCC {threshold}; \
         rejected: {rejected}). Check the nearest-neighbour distance, the polarity (bright/dark) and the threshold"
    )]
    NoFeatures {
        /// The pass searched: "trace" or "retrace".
        pass: &'static str,
        /// Candidate regions above the correlation threshold.
        candidates: usize,
        /// The correlation (NCC) threshold used.
        threshold: f64,
        /// Rejected candidates counted by reason.
        rejected: String,
    },
    /// The features found correlate too weakly with the kernel to be a lattice.
    #[error(
        "the {count} candidate features of the {pass} image look like noise, not a lattice: their \
         median peak correlation is {median_ncc:.2} (atoms give ≳ 0.5; the limit is {limit}). \
         Check the nearest-neighbour distance, the polarity (bright/dark) and the image itself"
    )]
    NoiseLike {
        /// The pass searched: "trace" or "retrace".
        pass: &'static str,
        /// Features found.
        count: usize,
        /// Their median peak correlation (NCC).
        median_ncc: f64,
        /// The lowest median correlation accepted.
        limit: f64,
    },
}
