//! Feature indexing: find every atom or molecule in an STM image and fit it to sub-pixel
//! precision (DHCT steps 1–2).
//!
//! Pipeline ([`find_features`]): optional background and scan-line corrections →
//! normalised cross-correlation with a Gaussian kernel sized from the nearest-neighbour
//! distance (FFT) → threshold and rain-falling watershed → DHCT area filter → bounded
//! Levenberg–Marquardt fit of an elliptical 2-D Gaussian per region (analytic Jacobian,
//! fixed-size normal equations) → edge and duplicate checks → acquisition time of each
//! sub-pixel centre from the scan geometry. Every rejected candidate is kept with its reason.
//!
//! ```
//! use dhct_features::{find_features, Background, FeatureOptions};
//! use dhct_scan::{ImageChannel, ScanDirection, ScanGeometry, ScanPass};
//! use ndarray::Array2;
//!
//! // A 66 x 66 px square lattice of Gaussian bumps, 9 px apart, 0.1 nm pixels.
//! let z = Array2::from_shape_fn((66, 66), |(r, c)| {
//!     let (dx, dy) = ((c % 9) as f64 - 4.0, (r % 9) as f64 - 4.0);
//!     1e-11 * (-(dx * dx + dy * dy) / 4.0).exp()
//! });
//! let image = ImageChannel::new("Topography", "m", z);
//! let geometry = ScanGeometry::new(66, 66, 1e-10, 1e-10, 1e-3,
//!                                  ScanDirection::Right, ScanDirection::Down).unwrap();
//! let options = FeatureOptions {
//!     background: Background::None, // the image has no tilt to remove
//!     ..FeatureOptions::for_neighbour_distance(9e-10)
//! };
//! let set = find_features(&image, &geometry, ScanPass::Trace, &options, None).unwrap();
//! // 7 x 7 bumps; those at x = 4 or y = 4 are closer to the border than the kernel radius.
//! assert_eq!(set.features.len(), 36);
//! for f in &set.features {
//!     // The bumps are cut off at their cell edges, so the model is not exact: the fit stops
//!     // once the centre moves by < 1e-3 px.
//!     assert!((f.x_px - 4.0 - 9.0 * ((f.x_px - 4.0) / 9.0).round()).abs() < 1e-3);
//! }
//! ```

mod blur;
mod correlate;
mod error;
mod feature;
mod feature_row;
mod find;
mod gaussian_fit;
mod kernel;
/// Before the fits: the background and the scan lines' levels (median, tapered, against the
/// lattice's own picture, with steps), refitted with the features, and what was removed.
mod levelling {
    pub(crate) mod lattice_levels;
    pub(crate) mod line_level;
    pub(crate) mod line_levelling;
    pub(crate) mod line_relevel;
    pub(crate) mod line_steps;
    pub(crate) mod preprocess;
    pub(crate) mod removed_levels;
}
mod ncc;
mod noise_correlation;
mod options;
mod watershed;

pub use blur::{gaussian_blur, gaussian_blur_sampled};
pub use correlate::{Correlator, RealSpectrum, correlate_same};
pub use error::FeatureError;
pub use feature::{
    Feature, FeatureSet, RejectedCandidate, Rejection, RejectionCounts, StageTimings,
};
pub use feature_row::{Cell, FeatureIndex, FeaturePlacement, FeatureRow};
pub use find::{
    PARALLEL_PASSES_MAX_PIXELS, find_features, find_features_and_correlation,
    find_features_in_pair, find_features_in_pair_and_correlation,
};
pub use gaussian_fit::{FitLimits, FitShape, FitStatus, GaussianFit, fit_gaussian};
pub use kernel::Kernel;
pub use levelling::lattice_levels::lattice_model_image;
pub use levelling::line_level::{line_taper, tapered_line_level, tapered_line_level_with};
pub use levelling::line_levelling::LineLevelling;
pub use levelling::preprocess::{
    correct_lines, correct_lines_in_place, remove_background, remove_background_in_place,
    sign_flattened_in_place, signed_flattened, subtract_polynomial, subtract_polynomial_in_place,
};
pub use ncc::{NccPlan, normalised_cross_correlation};
pub use options::{Background, FeatureOptions, KernelChoice, LineCorrection, Polarity};
pub use watershed::{MAX_WATERSHED_PIXELS, NO_BASIN, Region, basin_labels, watershed_regions};
