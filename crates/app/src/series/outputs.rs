//! What `dhct series` writes: the features of every frame in the session frame
//! (`features.csv`), the drift over the session (`trajectory.csv`), every frame's images
//! registered onto one grid (`registered/frame_NN_{trace,retrace}.gsf`, the stack as one
//! multi-page TIFF, and their mean), and `series.json`.

use std::io::Write as _;
use std::path::Path;

use anyhow::{Context, Result};
use dhct_calibrate::MIN_BINNED_NN_PX;
use dhct_distortion::series::{
    SeriesFeature, SessionDrift, SessionPlacement, TrajectoryPoint, register_image_sampled,
};
use dhct_pipeline::{CorrectedImageCheck, check_corrected_images};
use dhct_scan::{ImageChannel, ScanPass};
use dhct_sm4_io::{AtomicFile, WriteError, gsf, tiff_file, write_atomically};
use ndarray::Array2;
use rayon::prelude::*;

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
/// ([`placement::image_shift`]). Each frame's file is read again here; frames are
/// registered side by side, one per worker thread, and each is written (its GSF files, its
/// stack pages, its share of the mean) before the next few are read: memory holds the first
/// and the latest frame's registered traces and the frames in hand, however long the
/// session.
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
    let mut stack_file = AtomicFile::create(&dir.join(STACK))?;
    let mut stack = tiff_file::F32Pages::with_pixel_size(
        stack_file.writer(),
        [grid.pitch_x(), grid.pitch_y()],
    )?;
    let mut mean = MeanImage::default();
    let mut unit = None;
    // The first frame alone, then as many at a time as there are worker threads.
    let first = register_frame(dir, session, config, 0, &timed[0], None)?;
    let first_trace = first.trace().cloned();
    let mut latest_trace = first_trace.clone();
    let mut in_hand = vec![first];
    let mut next = 1;
    loop {
        // Each frame's shifts, side by side: one that the first frame's trace overlaps too
        // little is measured against the latest trace before it.
        let shifts: Vec<Vec<PassShift>> = (0..in_hand.len())
            .into_par_iter()
            .map(|j| {
                let before = in_hand[..j].iter().rev().find_map(RegisteredFrame::trace);
                in_hand[j].shifts(before.or(latest_trace.as_ref()))
            })
            .collect();
        checks.shifts.extend(shifts);
        for frame in in_hand.drain(..) {
            for (pass, page) in &frame.pages {
                stack.push(page)?;
                mean.add(&page.z);
                unit.get_or_insert_with(|| page.unit.clone());
                written.push(format!("registered/{}.gsf", page_name(frame.index, *pass)));
            }
            checks.frames.push(frame.measured);
            checks.unmeasured.push(frame.unmeasured);
            // The frame's trace is the next frame's fallback reference; the rest is let go.
            if let Some((_, trace)) = frame.pages.into_iter().find(|(p, _)| *p == ScanPass::Trace) {
                latest_trace = Some(trace.z);
            }
        }
        if next == timed.len() {
            break;
        }
        let chunk = (next..timed.len()).take(rayon::current_num_threads().max(1));
        in_hand = chunk
            .clone()
            .collect::<Vec<_>>()
            .into_par_iter()
            .map(|k| register_frame(dir, session, config, k, &timed[k], first_trace.as_ref()))
            .collect::<Result<_>>()?;
        next += chunk.len();
    }
    stack_file.commit()?;
    let mean = ImageChannel::new(
        "mean of the registered frames",
        unit.unwrap_or_default(),
        mean.finish(),
    );
    write_atomically(&dir.join("registered/mean.gsf"), |w| {
        gsf::write_pass(&mean, grid, ScanPass::Trace, w)
    })?;
    written.push("registered/mean.gsf".into());
    written.push(STACK.into());
    if let Some(lattice) = session.lattice {
        checks.mean = check_corrected_images(&[(ScanPass::Trace, &mean.z)], grid, lattice).pop();
    }
    Ok(Registered {
        files: written,
        checks,
        mean,
    })
}

/// The registered stack, one page per image in time order (trace before retrace).
const STACK: &str = "registered/stack.tif";

/// `frame_NN_trace` or `frame_NN_retrace`.
fn page_name(frame: usize, pass: ScanPass) -> String {
    format!("frame_{frame:02}_{}", pass.name())
}

/// One frame registered: its pages (written as GSF already) and what was measured of them.
struct RegisteredFrame {
    index: usize,
    pages: Vec<(ScanPass, ImageChannel)>,
    measured: Vec<CorrectedImageCheck>,
    unmeasured: Vec<ScanPass>,
    /// Per page, its shift against the first frame's trace (`None`: not measured there;
    /// the first frame's trace itself has none).
    against_first: Vec<Option<[f64; 2]>>,
}

impl RegisteredFrame {
    fn trace(&self) -> Option<&Array2<f64>> {
        self.pages
            .iter()
            .find(|(pass, _)| *pass == ScanPass::Trace)
            .map(|(_, page)| &page.z)
    }

    /// Each page's shift against the first frame's trace, or, where the first overlaps it
    /// too little, against `before` (the frame before's registered trace).
    fn shifts(&self, before: Option<&Array2<f64>>) -> Vec<PassShift> {
        self.pages
            .iter()
            .zip(&self.against_first)
            .filter(|((pass, _), _)| self.index > 0 || *pass != ScanPass::Trace)
            .map(|((pass, page), first)| {
                let found = first.map(|shift| (0, shift)).or_else(|| {
                    let before = before.filter(|_| self.index > 0)?;
                    Some((self.index - 1, placement::image_shift(before, &page.z)?))
                });
                PassShift {
                    pass: *pass,
                    against_frame: found.map(|(reference, _)| reference),
                    shift_px: found.map(|(_, shift)| shift),
                }
            })
            .collect()
    }
}

/// Reads frame `index` (`t`) again, registers its images, checks them, writes each as GSF
/// and measures each against `first_trace` (the first frame's registered trace; `None` for
/// the first frame itself, whose retrace is measured against its own trace).
fn register_frame(
    dir: &Path,
    session: &Session,
    config: &CorrectConfig,
    index: usize,
    t: &Timed,
    first_trace: Option<&Array2<f64>>,
) -> Result<RegisteredFrame> {
    let pair = t.source.read(config)?;
    let frame = FrameRegistration {
        session,
        geometry: pair.geometry(),
        start_s: t.start_s,
    };
    let grid = &session.grid;
    let mut done = RegisteredFrame {
        index,
        pages: Vec::new(),
        measured: Vec::new(),
        unmeasured: Vec::new(),
        against_first: Vec::new(),
    };
    for (pass, image) in pair.images() {
        let z = frame.register(pass, &image.z, grid, 1)?;
        if let Some(lattice) = session.lattice {
            match fft_check(&frame, lattice, pass, &image.z, &z) {
                Some(c) => done.measured.push(c),
                None => done.unmeasured.push(pass),
            }
        }
        let name = page_name(index, pass);
        let channel = ImageChannel::new(format!("{} {name}", image.name), image.unit.clone(), z);
        write_atomically(&dir.join(format!("registered/{name}.gsf")), |w| {
            gsf::write_pass(&channel, grid, pass, w)
        })?;
        let reference = first_trace.or_else(|| done.trace());
        let shift = match (index, pass) {
            (0, ScanPass::Trace) => None,
            _ => reference.and_then(|r| placement::image_shift(r, &channel.z)),
        };
        done.against_first.push(shift);
        done.pages.push((pass, channel));
    }
    Ok(done)
}

/// What registering one frame needs.
struct FrameRegistration<'a> {
    session: &'a Session<'a>,
    geometry: &'a dhct_scan::ScanGeometry,
    start_s: f64,
}

impl FrameRegistration<'_> {
    /// `z` (an image of `pass`) resampled onto `grid` in the session frame, from every
    /// `step`-th pixel and line of `z` ([`register_image_sampled`]).
    fn register(
        &self,
        pass: ScanPass,
        z: &Array2<f64>,
        grid: &dhct_scan::ScanGeometry,
        step: usize,
    ) -> Result<Array2<f64>> {
        Ok(register_image_sampled(
            self.session.placement,
            self.geometry,
            self.start_s,
            pass,
            z,
            grid,
            step,
        )?)
    }
}

/// The lattice of a registered image (`registered`, of raw image `raw`) measured by FFT:
/// on the first frame's grid, or, where the frame covers too little of it, on the frame's
/// own grid moved with the sample (registered again there, from every second pixel and
/// line where the lattice keeps [`MIN_BINNED_NN_PX`] px a neighbour distance so: the FFT's
/// measurement then bins the image that far anyway on large frames).
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
        let g = frame.geometry;
        let nn_px = lattice.nearest_neighbour_distance() / g.pitch_x().max(g.pitch_y());
        let step = if nn_px / 2.0 >= MIN_BINNED_NN_PX {
            2
        } else {
            1
        };
        let grid = own_grid(frame.session.drift, g, frame.start_s, step)?;
        let z = frame.register(pass, raw, &grid, step).ok()?;
        on(&z, &grid)
    })
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
/// session's drift at its start), with `step` times its pitch (a `step`-th of its pixels
/// a side, over the same area): its registered image there covers nearly all of it.
fn own_grid(
    drift: &SessionDrift,
    geometry: &dhct_scan::ScanGeometry,
    start_s: f64,
    step: usize,
) -> Option<dhct_scan::ScanGeometry> {
    let d = drift.displacement(start_s);
    let (x, y) = geometry.offset();
    geometry
        .binned(step)
        .and_then(|g| g.with_offset(x + d[0], y + d[1]))
        .ok()
}

/// The mean of the registered pages per pixel over the pages that hold a value there (NaN
/// where none), each page first brought to the first page's height level (less the median
/// of its difference from it where both hold values): frames differ by a z offset (the z
/// piezo creeps too), which would otherwise draw each frame's outline into the mean.
/// Accumulated a page at a time.
#[derive(Default)]
struct MeanImage {
    first: Option<Array2<f64>>,
    sum: Array2<f64>,
    count: Array2<f64>,
}

impl MeanImage {
    fn add(&mut self, page: &Array2<f64>) {
        let first = self.first.get_or_insert_with(|| page.clone());
        let offset = level_against(first, page);
        if self.sum.dim() != page.dim() {
            self.sum = Array2::zeros(page.dim());
            self.count = Array2::zeros(page.dim());
        }
        ndarray::Zip::from(&mut self.sum)
            .and(&mut self.count)
            .and(page)
            .for_each(|s, n, &v| {
                if v.is_finite() {
                    *s += v - offset;
                    *n += 1.0;
                }
            });
    }

    fn finish(mut self) -> Array2<f64> {
        ndarray::Zip::from(&mut self.sum)
            .and(&self.count)
            .for_each(|s, &n| {
                *s = if n > 0.0 { *s / n } else { f64::NAN };
            });
        self.sum
    }
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
        let mut mean = MeanImage::default();
        mean.add(&first);
        mean.add(&second);
        let mean = mean.finish();
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
