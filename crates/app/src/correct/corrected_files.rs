//! A corrected image written as `{stem}.tiff` (float, pixel size) and `{stem}.gsf` on the
//! grid the run asked for: the scan's frame, or every corrected pixel
//! ([`Extent::Full`]: the GSF carries the grid's origin in `XOffset`/`YOffset`).

use std::path::Path;

use anyhow::Result;
use dhct_distortion::{DistortionModel, correct_image, correct_image_full};
use dhct_scan::{ImageChannel, ScanGeometry, ScanPass};
use dhct_sm4_io::write_atomically;
use ndarray::Array2;

use crate::setup::Extent;

/// One image to correct and write.
pub(crate) struct CorrectedImage<'a> {
    /// File stem in the output folder.
    pub stem: String,
    /// The raw image (controller frame) and its name and unit.
    pub raw: &'a ImageChannel,
    /// Its pass.
    pub pass: ScanPass,
    /// The correction kept.
    pub model: &'a DistortionModel,
    /// The scan's geometry.
    pub geometry: &'a ScanGeometry,
}

/// Writes `image` corrected on `extent`'s grid; returns the two file names.
pub(crate) fn write_corrected_files(
    dir: &Path,
    image: &CorrectedImage,
    extent: Extent,
) -> Result<Vec<String>> {
    let CorrectedImage {
        stem,
        raw,
        pass,
        model,
        geometry,
    } = image;
    let (z, origin_px): (Array2<f64>, Option<[i64; 2]>) = match extent {
        Extent::Frame => (correct_image(model, geometry, *pass, &raw.z)?, None),
        Extent::Full => {
            let full = correct_image_full(model, geometry, *pass, &raw.z)?;
            (full.z, Some(full.origin_px))
        }
    };
    let channel = ImageChannel::new(format!("{} (corrected)", raw.name), raw.unit.clone(), z);
    let pitch = [geometry.pitch_x(), geometry.pitch_y()];
    write_atomically(&dir.join(format!("{stem}.tiff")), |w| {
        dhct_sm4_io::tiff_file::write_f32_with_pixel_size(&channel, pitch, w)
    })?;
    write_atomically(&dir.join(format!("{stem}.gsf")), |w| match origin_px {
        Some(origin) => dhct_sm4_io::gsf::write_extended(&channel, geometry, *pass, origin, w),
        None => dhct_sm4_io::gsf::write_pass(&channel, geometry, *pass, w),
    })?;
    Ok(vec![format!("{stem}.tiff"), format!("{stem}.gsf")])
}
