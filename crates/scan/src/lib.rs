//! The STM scan data model shared by every dhct crate.
//!
//! * [`ImageChannel`]: one 2-D image of z values (row-major, SI units such as metres).
//! * [`ScanGeometry`]: pixel pitch, pixel period, turnaround, fast and slow scan directions,
//!   scan angle and offset. It answers, for any pixel or sub-pixel position, *when* the tip
//!   was there ([`ScanGeometry::acquisition_time`]).
//! * [`ScanPair`]: the trace and retrace images of one channel, sharing one geometry.
//! * [`HysteresisLaw`]: the scanner's apparent local scale against time since line start.
//! * [`ScanFile`]: everything a reader found in one file.
//! * [`quantity`]: a value with its unit (and 1σ) written for people, the same in every
//!   crate's messages and in the report.
//!
//! # Conventions
//!
//! Every image is stored in **display orientation**, whatever its scan direction: row 0 is the
//! top row, column 0 the left column, `z[[row, col]]`. Pixel *centres* sit at integer
//! coordinates, so a sub-pixel position `(x, y)` means column `x`, row `y`
//! (x to the right, y downwards — the "4th-quadrant" convention of the DHCT paper).
//! Positions in metres are `x·pitch_x`, `y·pitch_y` in this frame.
//! Trace and retrace images of one pair are both in display orientation, so the same `(x, y)`
//! is the same controller position in both; only their acquisition times differ.
//!
//! Timing: the tip scans a *line pair* per slow step — the trace line, a turnaround, the
//! retrace line back along the same line, another turnaround — then steps one pixel along the
//! slow axis. Which corner is acquired first follows from the directions: the trace starts at
//! the corner where both the fast and the slow direction begin (e.g. fast [`ScanDirection::Right`],
//! slow [`ScanDirection::Down`]: top-left corner first). See [`ScanGeometry`] for the formulas.
//!
//! ```
//! use dhct_scan::{ScanDirection, ScanGeometry, ScanPass};
//!
//! // 512 x 512 px, 0.2 nm pixels, 1 ms per pixel, fast left-to-right, slow top-to-bottom.
//! let g = ScanGeometry::new(512, 512, 0.2e-9, 0.2e-9, 1e-3,
//!                           ScanDirection::Right, ScanDirection::Down).unwrap();
//! // The first pixel of the trace is acquired first, in the middle of its 1 ms dwell.
//! assert_eq!(g.acquisition_time(ScanPass::Trace, 0.0, 0.0).since_frame_start, 0.5e-3);
//! // The retrace runs right-to-left, after the whole trace line.
//! let t = g.acquisition_time(ScanPass::Retrace, 511.0, 0.0);
//! assert!((t.since_frame_start - 0.5125).abs() < 1e-12);
//! assert!((t.since_line_start - 0.5e-3).abs() < 1e-12);
//! ```

mod channel;
mod choice;
pub mod clock;
mod direction;
mod error;
mod file;
mod geometry;
mod hysteresis;
mod pair;
pub mod quantity;

pub use channel::ImageChannel;
pub use choice::NoSuchChannel;
pub use direction::{Axis, ScanDirection, ScanPass};
pub use error::GeometryError;
pub use file::{FileFormat, ScanFile};
pub use geometry::{AcquisitionTime, ScanGeometry, ValueSource};
pub use hysteresis::HysteresisLaw;
pub use pair::ScanPair;
