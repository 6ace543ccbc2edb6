//! The numerical routines every dhct stage shares, each written once:
//!
//! - [`lm`]: one Levenberg–Marquardt driver for bounded, weighted least squares, with an
//!   adaptor for problems given as residuals ([`lm::ResidualProblem`]) and room for hot
//!   loops that form their normal equations in one fused pass (the 2-D Gaussian fit).
//! - [`robust`]: the median, the MAD scale and Huber weights, with one convention.
//! - [`linalg`]: covariance from normal equations when some parameters are not determined.
//! - [`crlb`]: the Cramér–Rao bound on a 2-D Gaussian's centre.
//! - [`moments`]: plain moments of point sets.
//! - [`special`]: the error function and the normal upper tail.
//! - [`sparse_rows`]: normal equations from a Jacobian given as its non-zeros per row.
//! - [`envelope`]: a positive-definite solve inside the matrix's envelope, its dense
//!   parameters last (the LM step of a fit with a spline over a long session).
//! - [`series`]: `ln(1 + u)` for small `u` in hot loops (the correction of every pixel).
//!
//! Why our own LM and not `argmin` or `levenberg-marquardt`: the feature fit needs bound
//! projection after every step and forms `JᵀJ`, `Jᵀr` and the cost in one pass over the
//! pixels for ~10⁵ small fits per image; neither crate offers bounds, and both require the
//! Jacobian as a matrix.
//!
//! ```
//! use dhct_numerics::lm::{LmOptions, ResidualProblem, minimise};
//! // Fit y = a·exp(b·x) to exact data.
//! let xs: Vec<f64> = (0..20).map(|i| i as f64 * 0.1).collect();
//! let ys: Vec<f64> = xs.iter().map(|x| 2.0 * (0.5 * x).exp()).collect();
//! let residuals = |p: &[f64], r: &mut [f64]| {
//!     for ((r, x), y) in r.iter_mut().zip(&xs).zip(&ys) {
//!         *r = p[0] * (p[1] * x).exp() - y;
//!     }
//! };
//! let mut problem = ResidualProblem::new(&residuals, xs.len(), vec![1.0; xs.len()]);
//! let fit = minimise(&mut problem, &[1.0, 0.0], &LmOptions::default()).unwrap();
//! assert!((fit.params[0] - 2.0).abs() < 1e-8 && (fit.params[1] - 0.5).abs() < 1e-8);
//! ```

pub mod banded;
pub mod crlb;
pub mod dot;
pub mod envelope;
pub mod linalg;
pub mod lm;
pub mod moments;
pub mod peak;
pub mod robust;
pub mod series;
pub mod sparse_rows;
pub mod special;
