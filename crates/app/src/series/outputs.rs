//! What `dhct series` writes: the features of every frame in the session frame
//! (`features.csv`), the drift over the session (`trajectory.csv`), every frame's images
//! registered onto one grid (`registered/frame_NN_{trace,retrace}.gsf`, the stack as one
//! multi-page TIFF, and their mean), and `series.json`.

use std::io::Write as _;
use std::path::Path;

use anyhow::{Context, Result};
use dhct_distortion::series::{
    SeriesFeature, SessionDrift, SessionPlacement, TrajectoryPoint, register_image,
};
use dhct_pipeline::{CorrectedImageCheck, check_corrected_images};
use dhct_scan::{ImageChannel, ScanPass};
use dhct_sm4_io::{WriteError, gsf, tiff_file, write_atomically};
use ndarray::Array2;

use super::placement;
use super::{PassShift, SeriesSummary, Timed};
use crate::analysis::FrameModel;
use crate::setup::CorrectConfig;

/// What [`write_all`] wrote and what the registered images showed.
pub struct Written {
    /// The files written, relative to the output directory.
    pub files: Vec<String>,
    /// The registered images' lattices, measured by FFT.
    pub checks: RegisteredChecks,
    /// The mean registered image (on the first frame's grid).
    pub mean: ImageChannel,
}

/// The registered images' lattices, measured by their Fourier transform as an outside
/// check would (empty when the first frame's raw lattice could not be measured).
#[derive(Default)]
pub struct RegisteredChecks {
    /// Per frame in time order: the passes whose registered lattice was measured.
    pub frames: Vec<Vec<CorrectedImageCheck>>,
    /// Per frame in time order: the passes whose registered lattice could not be measured.
    pub unmeasured: Vec<Vec<ScanPass>>,
    /// The mean image's, if measured.
    pub mean: Option<CorrectedImageCheck>,
    /// Per frame in time order: its registered images' shifts against the first frame's
    /// trace (or the frame before's), measured from the pixels (made whether or not the
    /// lattice was measured).
    pub shifts: Vec<Vec<PassShift>>,
    /// Whether the checks were made.
    pub made: bool,
}

/// Writes every output but `series.json`; returns the names written and the checks.
pub fn write_all(
    dir: &Path,
    summary: &SeriesSummary,
    corrected: &[FrameModel],
    timed: &[Timed],
    config: &CorrectConfig,
) -> Result<Written> {
    let mut files = vec![write_features(dir, summary, corrected, timed)?];
    files.push(write_trajectory(dir, &summary.fit.trajectory)?);
    let first = &corrected[timed[0].input];
    let session = Session {
        placement: &summary.fit,
        drift: &summary.fit.drift,
        grid: first.geometry.clone(),
        // A registered image is checked only where the raw image's lattice was measured.
        lattice: first.run.lattice_measured.then_some(first.lattice.as_ref()),
    };
    let registered = write_registered(dir, &session, timed, config)?;
    files.extend(registered.files);
    files.push(SERIES_JSON.to_string());
    Ok(Written {
        files,
        checks: registered.checks,
        mean: registered.mean,
    })
}

/// File name of the summary.
pub const SERIES_JSON: &str = "series.json";

/// Writes `series.json` (either route's summary).
pub fn write_summary(dir: &Path, summary: &impl serde::Serialize) -> Result<()> {
    write_atomically(&dir.join(SERIES_JSON), |w| {
        serde_json::to_writer_pretty(&mut *w, summary)
            .map_err(|e| WriteError::Stream(std::io::Error::other(e)))?;
        w.write_all(b"\n")?;
        Ok(())
    })?;
    Ok(())
}

fn csv_error(e: csv::Error) -> WriteError {
    WriteError::Stream(std::io::Error::other(e))
}

/// `features.csv`: every feature of every frame with its session position.
fn write_features(
    dir: &Path,
    summary: &SeriesSummary,
    corrected: &[FrameModel],
    timed: &[Timed],
) -> Result<String> {
    const NAME: &str = "features.csv";
    write_atomically(&dir.join(NAME), |w| {
        let mut out = csv::Writer::from_writer(w);
        out.write_record([
            "frame",
            "pass",
            "x_px",
            "y_px",
            "session_time_s",
            "height",
            "corrected_x_m",
            "corrected_y_m",
        ])
        .map_err(csv_error)?;
        for (k, t) in timed.iter().enumerate() {
            let c = &corrected[t.input];
            let g = &c.geometry;
            for set in &c.run.features {
                for f in &set.features {
                    let at = SeriesFeature::at_pixel(g, t.start_s, f.pass, f.x_px, f.y_px);
                    let q = summary.fit.position_of(&at);
                    out.write_record([
                        k.to_string(),
                        f.pass.name().to_string(),
                        format!("{:.4}", f.x_px),
                        format!("{:.4}", f.y_px),
                        format!("{:.6}", at.time_s),
                        format!("{:e}", f.height),
                        format!("{:e}", q[0]),
                        format!("{:e}", q[1]),
                    ])
                    .map_err(csv_error)?;
                }
            }
        }
        out.flush()?;
        Ok(())
    })?;
    Ok(NAME.to_string())
}

/// `trajectory.csv`: the drift over the session with 1σ.
pub fn write_trajectory(dir: &Path, trajectory: &[TrajectoryPoint]) -> Result<String> {
    const NAME: &str = "trajectory.csv";
    write_atomically(&dir.join(NAME), |w| {
        let mut out = csv::Writer::from_writer(w);
        out.write_record(["session_time_s", "dx_m", "dy_m", "sigma_x_m", "sigma_y_m"])
            .map_err(csv_error)?;
        for p in trajectory {
            out.write_record([
                format!("{:.4}", p.time_s),
                format!("{:e}", p.displacement_m[0]),
                format!("{:e}", p.displacement_m[1]),
                format!("{:e}", p.sigma_m[0]),
                format!("{:e}", p.sigma_m[1]),
            ])
            .map_err(csv_error)?;
        }
        out.flush()?;
        Ok(())
    })?;
    Ok(NAME.to_string())
}

/// How a session places every frame's pixels, and what to check its images against.
pub struct Session<'a> {
    /// The fit that places pixels in the session frame.
    pub placement: &'a dyn SessionPlacement,
    /// Its drift over the session.
    pub drift: &'a SessionDrift,
    /// The common grid: the first frame's.
    pub grid: dhct_scan::ScanGeometry,
    /// The lattice the registered images are checked against by FFT (`None`: not checked).
    pub lattice: Option<&'a dyn dhct_lattice::Lattice>,
}

/// Every frame's images registered onto the first frame's grid, their stack and its mean,
/// each image's lattice measured by FFT ([`fft_check`]) where `session` names one, and its
/// shift against the first frame's trace measured from the pixels
/// ([`placement::image_shift`]). Each frame's file is read again here, one at a time.
pub fn write_registered(
    dir: &Path,
    session: &Session,
    timed: &[Timed],
    config: &CorrectConfig,
) -> Result<Registered> {
    let folder = dir.join("registered");
    std::fs::create_dir_all(&folder)
        .with_context(|| format!("cannot create {}", folder.display()))?;
    let grid = &session.grid;
    let mut checks = RegisteredChecks {
        made: session.lattice.is_some(),
        ..RegisteredChecks::default()
    };
    let mut written = Vec::new();
    let mut pages: Vec<(usize, ScanPass, ImageChannel)> = Vec::new();
    for (k, t) in timed.iter().enumerate() {
        let pair = t.source.read(config)?;
        let frame = FrameRegistration {
            session,
            geometry: pair.geometry(),
            start_s: t.start_s,
        };
        let (mut measured, mut unmeasured) = (Vec::new(), Vec::new());
        for (pass, image) in pair.images() {
            let z = frame.register(pass, &image.z, grid)?;
            if let Some(lattice) = session.lattice {
                match fft_check(&frame, lattice, pass, &image.z, &z) {
                    Some(c) => measured.push(c),
                    None => unmeasured.push(pass),
                }
            }
            let name = format!("frame_{k:02}_{}", pass.name());
            let channel =
                ImageChannel::new(format!("{} {name}", image.name), image.unit.clone(), z);
            let file = format!("registered/{name}.gsf");
            write_atomically(&dir.join(&file), |w| {
                gsf::write_pass(&channel, grid, pass, w)
            })?;
            written.push(file);
            pages.push((k, pass, channel));
        }
        checks.frames.push(measured);
        checks.unmeasured.push(unmeasured);
    }
    checks.shifts = shifts_against_first(&pages, timed.len());
    let pages: Vec<ImageChannel> = pages.into_iter().map(|(_, _, page)| page).collect();
    let mean = write_stack_and_mean(dir, &pages, grid, &mut written)?;
    if let Some(lattice) = session.lattice {
        checks.mean = check_corrected_images(&[(ScanPass::Trace, &mean.z)], grid, lattice).pop();
    }
    Ok(Registered {
        files: written,
        checks,
        mean,
    })
}

/// What registering one frame needs.
struct FrameRegistration<'a> {
    session: &'a Session<'a>,
    geometry: &'a dhct_scan::ScanGeometry,
    start_s: f64,
}

impl FrameRegistration<'_> {
    /// `z` (an image of `pass`) resampled onto `grid` in the session frame.
    fn register(
        &self,
        pass: ScanPass,
        z: &Array2<f64>,
        grid: &dhct_scan::ScanGeometry,
    ) -> Result<Array2<f64>> {
        Ok(register_image(
            self.session.placement,
            self.geometry,
            self.start_s,
            pass,
            z,
            grid,
        )?)
    }
}

/// The lattice of a registered image (`registered`, of raw image `raw`) measured by FFT:
/// on the first frame's grid, or, where the frame covers too little of it, on the frame's
/// own grid moved with the sample.
fn fft_check(
    frame: &FrameRegistration,
    lattice: &dyn dhct_lattice::Lattice,
    pass: ScanPass,
    raw: &Array2<f64>,
    registered: &Array2<f64>,
) -> Option<CorrectedImageCheck> {
    let on = |z: &Array2<f64>, grid: &dhct_scan::ScanGeometry| {
        check_corrected_images(&[(pass, z)], grid, lattice).pop()
    };
    on(registered, &frame.session.grid).or_else(|| {
        let grid = own_grid(frame.session.drift, frame.geometry, frame.start_s)?;
        let z = frame.register(pass, raw, &grid).ok()?;
        on(&z, &grid)
    })
}

/// Each registered image's shift against the first frame's trace, from the pixels alone
/// (in parallel), per frame of `frames`; against the frame before's trace where the first
/// frame's overlaps it too little.
fn shifts_against_first(
    pages: &[(usize, ScanPass, ImageChannel)],
    frames: usize,
) -> Vec<Vec<PassShift>> {
    use rayon::prelude::*;
    let trace_of = |frame: usize| {
        pages
            .iter()
            .find(|(k, pass, _)| *k == frame && *pass == ScanPass::Trace)
            .map(|(_, _, page)| page)
    };
    let found: Vec<(usize, PassShift)> = pages
        .par_iter()
        .skip(1)
        .map(|(frame, pass, page)| {
            let against = |reference: usize| {
                let shift = placement::image_shift(&trace_of(reference)?.z, &page.z)?;
                Some((reference, shift))
            };
            let found = against(0).or_else(|| against(frame.checked_sub(1)?));
            let shift = PassShift {
                pass: *pass,
                against_frame: found.map(|(reference, _)| reference),
                shift_px: found.map(|(_, shift)| shift),
            };
            (*frame, shift)
        })
        .collect();
    let mut per_frame = vec![Vec::new(); frames];
    for (frame, shift) in found {
        per_frame[frame].push(shift);
    }
    per_frame
}

/// Writes the stack (multi-page TIFF) and the mean (GSF) of `pages`; returns the mean.
fn write_stack_and_mean(
    dir: &Path,
    pages: &[ImageChannel],
    grid: &dhct_scan::ScanGeometry,
    written: &mut Vec<String>,
) -> Result<ImageChannel> {
    let unit = pages.first().map(|p| p.unit.clone()).unwrap_or_default();
    let mean = ImageChannel::new("mean of the registered frames", unit, mean_image(pages));
    write_atomically(&dir.join("registered/mean.gsf"), |w| {
        gsf::write_pass(&mean, grid, ScanPass::Trace, w)
    })?;
    written.push("registered/mean.gsf".into());
    let refs: Vec<&ImageChannel> = pages.iter().collect();
    write_atomically(&dir.join("registered/stack.tif"), |w| {
        tiff_file::write_f32_pages_with_pixel_size(&refs, [grid.pitch_x(), grid.pitch_y()], w)
    })?;
    written.push("registered/stack.tif".into());
    Ok(mean)
}

/// What [`write_registered`] wrote and measured.
pub struct Registered {
    /// The files written, relative to the output directory.
    pub files: Vec<String>,
    /// The registered images' checks.
    pub checks: RegisteredChecks,
    /// The mean registered image.
    pub mean: ImageChannel,
}

/// The median of `page − reference` where both hold values (0 where they share none).
fn level_against(reference: &Array2<f64>, page: &Array2<f64>) -> f64 {
    let mut differences: Vec<f64> = reference
        .iter()
        .zip(page.iter())
        .filter(|(a, b)| a.is_finite() && b.is_finite())
        .map(|(a, b)| b - a)
        .collect();
    let middle = differences.len() / 2;
    if differences.is_empty() {
        return 0.0;
    }
    *differences.select_nth_unstable_by(middle, f64::total_cmp).1
}

/// The frame's own grid moved with the sample to where the frame scanned it (by the
/// session's drift at its start): its registered image there covers nearly all of it.
fn own_grid(
    drift: &SessionDrift,
    geometry: &dhct_scan::ScanGeometry,
    start_s: f64,
) -> Option<dhct_scan::ScanGeometry> {
    let d = drift.displacement(start_s);
    let (x, y) = geometry.offset();
    geometry.clone().with_offset(x + d[0], y + d[1]).ok()
}

/// The mean of `pages` per pixel over the pages that hold a value there (NaN where none),
/// each page first brought to the first page's height level (less the median of its
/// difference from it where both hold values): frames differ by a z offset (the z piezo
/// creeps too), which would otherwise draw each frame's outline into the mean.
fn mean_image(pages: &[ImageChannel]) -> Array2<f64> {
    let Some(first) = pages.first() else {
        return Array2::zeros((0, 0));
    };
    let mut sum = Array2::<f64>::zeros(first.z.dim());
    let mut count = Array2::<f64>::zeros(first.z.dim());
    for page in pages {
        let offset = level_against(&first.z, &page.z);
        ndarray::Zip::from(&mut sum)
            .and(&mut count)
            .and(&page.z)
            .for_each(|s, n, &v| {
                if v.is_finite() {
                    *s += v - offset;
                    *n += 1.0;
                }
            });
    }
    ndarray::Zip::from(&mut sum).and(&count).for_each(|s, &n| {
        *s = if n > 0.0 { *s / n } else { f64::NAN };
    });
    sum
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_at_other_heights_average_without_their_outlines() {
        let pattern = |r: usize, c: usize| ((r * 7 + c * 3) % 11) as f64;
        let first = Array2::from_shape_fn((20, 20), |(r, c)| pattern(r, c));
        // The second frame 5 units higher, covering the right half only.
        let second = Array2::from_shape_fn((20, 20), |(r, c)| {
            if c >= 10 {
                pattern(r, c) + 5.0
            } else {
                f64::NAN
            }
        });
        let pages = [
            ImageChannel::new("a", "m", first.clone()),
            ImageChannel::new("b", "m", second),
        ];
        let mean = mean_image(&pages);
        let worst = mean
            .iter()
            .zip(first.iter())
            .map(|(m, f)| (m - f).abs())
            .fold(0.0, f64::max);
        assert!(
            worst < 1e-12,
            "the mean departs from the pattern by {worst}"
        );
    }
}
