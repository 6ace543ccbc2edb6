//! Lines a scan never recorded.
//!
//! A scan stopped before its last line leaves the lines it never reached in the file.
//! Nanonis writes them as NaN; other instruments write one repeated value (Nanosurf's NID
//! files: zero), which reads as a flat band with a height step at its edge, and a lattice
//! measured over the whole frame then sees the band's edge and no atoms in it. Every reader's
//! images pass through [`mark_unrecorded_lines`]: the last lines in acquisition order that
//! hold one repeated value are read as missing (NaN), and the file's metadata says how many
//! (under [`UNRECORDED_LINES_KEY`]).

use dhct_scan::quantity::si;
use ndarray::ArrayView1;

use dhct_scan::{ImageChannel, ScanDirection, ScanFile, ScanGeometry, ScanPair};

use crate::placeholders::note;

/// Metadata key saying which lines of which images were read as not recorded.
pub const UNRECORDED_LINES_KEY: &str = "unrecorded lines";

/// Fewest pixels along a line for one repeated value to mark it unrecorded: a measured line
/// of this many pixels never repeats one value exactly.
const MIN_LINE_PIXELS: usize = 8;

/// Reads the trailing lines of every image of `file` that hold one repeated value as
/// missing (NaN), and notes it in the metadata. An image whose every line holds that value
/// is left as it is (the feature finder then says it is flat).
pub(crate) fn mark_unrecorded_lines(mut file: ScanFile) -> ScanFile {
    let mut notes = Vec::new();
    file.pairs = std::mem::take(&mut file.pairs)
        .into_iter()
        .map(|pair| {
            let (geometry, mut trace, mut retrace) = pair.into_parts();
            for (pass, image) in [("trace", &mut trace), ("retrace", &mut retrace)] {
                let Some(image) = image.as_mut() else {
                    continue;
                };
                if let Some((lines, value)) = blank_trailing_lines(image, &geometry) {
                    notes.push(format!(
                        "{} {pass}: the last {lines} of {} lines hold one value ({}) and were \
                         read as not recorded (the scan stopped early)",
                        image.name,
                        geometry.slow_len(),
                        si(value, &image.unit)
                    ));
                }
            }
            ScanPair::from_parts(geometry, trace, retrace)
                .expect("the images keep the shape the pair was made with")
        })
        .collect();
    for text in notes {
        note(&mut file.metadata, UNRECORDED_LINES_KEY, text);
    }
    file
}

/// Sets the trailing lines of `image` (in acquisition order) that hold one repeated finite
/// value, or none at all, to NaN; returns how many held the value and the value, if any did.
fn blank_trailing_lines(image: &mut ImageChannel, geometry: &ScanGeometry) -> Option<(usize, f64)> {
    let lines = geometry.slow_len();
    if geometry.fast_len() < MIN_LINE_PIXELS {
        return None;
    }
    let value = *line(image, geometry, lines - 1)
        .iter()
        .find(|v| v.is_finite())?;
    let blank = |k: usize| {
        let values = line(image, geometry, k);
        values.iter().all(|v| v.is_nan()) || values.iter().all(|&v| v == value)
    };
    let trailing = (0..lines).rev().take_while(|&k| blank(k)).count();
    let repeated = (lines - trailing..lines)
        .filter(|&k| line(image, geometry, k).iter().any(|v| v.is_finite()))
        .count();
    if trailing == lines || repeated == 0 {
        return None;
    }
    for k in lines - trailing..lines {
        image
            .line_mut(geometry.fast_axis(), line_index(geometry, k))
            .fill(f64::NAN);
    }
    Some((repeated, value))
}

/// Line `k` of `image` in acquisition order (0 = the first line acquired).
fn line<'a>(image: &'a ImageChannel, geometry: &ScanGeometry, k: usize) -> ArrayView1<'a, f64> {
    image.line(geometry.fast_axis(), line_index(geometry, k))
}

/// The display row or column of line `k` (0 = the first line acquired).
fn line_index(geometry: &ScanGeometry, k: usize) -> usize {
    match geometry.slow_direction() {
        ScanDirection::Down | ScanDirection::Right => k,
        ScanDirection::Up | ScanDirection::Left => geometry.slow_len() - 1 - k,
    }
}
