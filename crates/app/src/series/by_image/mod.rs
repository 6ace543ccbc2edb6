//! `dhct series --register image`: frames of one area without a resolved lattice
//! (molecules on a substrate whose atoms are not resolved, a rough or amorphous surface)
//! registered by what their images share, under the same smooth drift over the session as
//! the lattice route. Each consecutive pair is compared band by band of scan lines
//! ([`comparisons`]); every band measures the drift's change between the two moments that
//! scanned one sample area, and one spline `D(T)` is fitted to all of them
//! ([`dhct_distortion::series::fit_drift_differences`]). Without a lattice nothing fixes
//! the absolute scale or the hysteresis: they stay as the files state them (see
//! [`UNDETERMINED`]).

mod comparisons;
mod report;

use anyhow::{Context, Result, bail};
use dhct_distortion::series::{
    DifferenceDriftFit, DriftDifference, ImageRegistration, MoveTiming, SplineBasis,
    fit_drift_differences,
};
use dhct_pipeline::{Warning, WarningCode};
use dhct_scan::{ScanGeometry, ScanPass};
use rayon::prelude::*;
use serde::Serialize;

use super::outputs::{self, Session};
use super::{FrameSource, PassShift, SeriesRequest, Timed, order};
use comparisons::{FrameImage, PairComparison};

/// What comparing images cannot determine, as `series.json` and the report say it.
pub const UNDETERMINED: [&str; 4] = [
    "the absolute scale: the files' pixel size is taken as stated (no lattice measures it)",
    "the fast-scan hysteresis and any other distortion the same in every frame: it cancels \
     in every comparison and stays in the registered images",
    "a drift that repeats with the frame period: every comparison spans one frame period",
    "where the session frame lies: D averages zero over the first frame",
];

/// Times across the first frame at which `D` is pinned to average zero.
const FIRST_FRAME_SAMPLES: usize = 64;

/// One frame as the image registration saw it.
#[derive(Debug, Clone, Serialize)]
pub struct ImageFrame {
    /// Its file.
    pub file: String,
    /// Seconds since the first frame's start.
    pub start_s: f64,
    /// Its scan angle, degrees.
    pub scan_angle_deg: f64,
    /// Its frame centre, metres (instrument frame).
    pub offset_m: [f64; 2],
    /// Its registered images' shifts against the first frame's registered trace (or the
    /// frame before's), measured from the pixels alone.
    pub registered_shifts: Vec<PassShift>,
}

/// `series.json` of a registration by image.
#[derive(Debug, Clone, Serialize)]
pub struct ImageSeriesSummary {
    /// Always `"image"`: the frames were registered by their images, not by a lattice.
    pub registration: &'static str,
    /// The frames in time order.
    pub frames: Vec<ImageFrame>,
    /// What each consecutive pair showed.
    pub comparisons: Vec<PairComparison>,
    /// Where each frame's retrace shows what its trace showed at a pixel, less that pixel
    /// (columns, rows; the median over the frames): the passes' hysteresis differs by it.
    /// `None` without retraces or where the passes show no common structure.
    pub retrace_shift_px: Option<[f64; 2]>,
    /// The drift over the session fitted to the comparisons.
    pub drift: DifferenceDriftFit,
    /// [`ImageSeriesSummary::retrace_shift_px`] in the instrument frame, metres: each pass
    /// is registered half of it from the drift alone, so the passes meet halfway.
    pub retrace_offset_m: [f64; 2],
    /// What the registration could not determine.
    pub undetermined: Vec<String>,
    /// What not to trust (pairs matched on few bands, registered images that do not line
    /// up), typed as `dhct correct`'s.
    pub warnings: Vec<Warning>,
    /// Notes and assumptions (clock, order).
    pub notes: Vec<String>,
    /// Files written into the output directory.
    pub outputs: Vec<String>,
}

/// A pair whose bands were measured on fewer than this fraction is named in a warning.
const FEW_BANDS: f64 = 0.5;

/// A registered image further than this from the first frame's (pixels) is named in a
/// warning: the image route's registration is good to about 0.05-0.2 px on simulated
/// sessions without hysteresis (`crates/cli/tests/series.rs`), so the lattice route's
/// 0.1 px would warn on sessions it registers right.
const MISALIGNED_PX: f64 = 0.5;

/// Runs `dhct series --register image`; returns the summary (also written as
/// `series.json`).
pub fn run(request: &SeriesRequest) -> Result<ImageSeriesSummary> {
    let sources = super::sources::find_frames(request)?;
    let staged =
        crate::output_dir::StagedOutput::prepare(request.output, request.config.overwrite)?;
    let config = &request.config;
    let geometries: Vec<ScanGeometry> = sources
        .par_iter()
        .map(|source| source.read(config).map(|pair| pair.geometry().clone()))
        .collect::<Result<_>>()?;
    let listed: Vec<(FrameSource, &ScanGeometry)> =
        sources.iter().cloned().zip(&geometries).collect();
    let (timed, notes) = order::order(&listed)?;
    check_comparable(&timed, &geometries)?;
    let (pairs, differences) = compare_all(&timed, &geometries, request)?;
    let fit = fit(&timed, &geometries, &differences, request.knots)?;
    let retrace_shift_px = retrace_shift(&timed, request)?;
    let grid = geometries[timed[0].input].clone();
    let registration = ImageRegistration {
        fit,
        retrace_offset_m: retrace_shift_px.map_or([0.0; 2], |s| {
            grid.vector_to_instrument([s[0] * grid.pitch_x(), s[1] * grid.pitch_y()])
        }),
    };
    let session = Session {
        placement: &registration,
        drift: &registration.fit.drift,
        grid: grid.clone(),
        lattice: None,
    };
    let mut files = vec![outputs::write_trajectory(
        staged.path(),
        &registration.fit.trajectory,
    )?];
    let registered = outputs::write_registered(staged.path(), &session, &timed, config)?;
    files.extend(registered.files.iter().cloned());
    let frames: Vec<ImageFrame> = timed
        .iter()
        .zip(registered.checks.shifts)
        .map(|(t, shifts)| frame_summary(t, &geometries[t.input], shifts))
        .collect();
    let mut summary = ImageSeriesSummary {
        registration: "image",
        warnings: warnings(&pairs, &frames, [grid.pitch_x(), grid.pitch_y()]),
        frames,
        comparisons: pairs,
        retrace_shift_px,
        drift: registration.fit,
        retrace_offset_m: registration.retrace_offset_m,
        undetermined: UNDETERMINED.iter().map(|s| s.to_string()).collect(),
        notes,
        outputs: Vec::new(),
    };
    let colormap = config
        .colormap
        .unwrap_or(dhct_sm4_io::png_file::Colormap::Gold);
    let mean = super::report::MeanImage {
        channel: &registered.mean,
        grid: &grid,
    };
    files.extend(report::write_report(
        staged.path(),
        &summary,
        &mean,
        colormap,
    )?);
    files.push(outputs::SERIES_JSON.to_string());
    summary.outputs = files;
    outputs::write_summary(staged.path(), &summary)?;
    staged.commit()?;
    Ok(summary)
}

/// Refuses frames a comparison of images cannot relate: another size, pitch or scan angle
/// than the first's.
fn check_comparable(timed: &[Timed], geometries: &[ScanGeometry]) -> Result<()> {
    let first = &geometries[timed[0].input];
    for t in &timed[1..] {
        let g = &geometries[t.input];
        let same = (g.columns(), g.rows()) == (first.columns(), first.rows())
            && g.pitch_x() == first.pitch_x()
            && g.pitch_y() == first.pitch_y()
            && g.scan_angle() == first.scan_angle()
            && g.fast_axis() == first.fast_axis();
        if !same {
            bail!(
                "registration by image compares frames of one size, pixel size, scan angle \
                 and fast axis: {} is {} x {} px of {:.4} x {:.4} nm at {:.1}°, the first frame \
                 {} is {} x {} px of {:.4} x {:.4} nm at {:.1}°",
                t.source,
                g.columns(),
                g.rows(),
                g.pitch_x() * 1e9,
                g.pitch_y() * 1e9,
                g.scan_angle().to_degrees(),
                timed[0].source,
                first.columns(),
                first.rows(),
                first.pitch_x() * 1e9,
                first.pitch_y() * 1e9,
                first.scan_angle().to_degrees()
            );
        }
    }
    Ok(())
}

/// Every consecutive pair compared (side by side, each reading its two traces).
fn compare_all(
    timed: &[Timed],
    geometries: &[ScanGeometry],
    request: &SeriesRequest,
) -> Result<(Vec<PairComparison>, Vec<DriftDifference>)> {
    let config = &request.config;
    let trace = |t: &Timed| -> Result<ndarray::Array2<f64>> {
        let pair = t.source.read(config)?;
        let g = pair.geometry().clone();
        let z = pair
            .images()
            .next()
            .map(|(_, image)| image.z.clone())
            .unwrap_or_default();
        Ok(comparisons::prepared(&z, g.fast_axis()))
    };
    let compared: Vec<(PairComparison, Vec<DriftDifference>)> = (1..timed.len())
        .into_par_iter()
        .map(|k| -> Result<_> {
            let (z0, z1) = (trace(&timed[k - 1])?, trace(&timed[k])?);
            let image = |t: &Timed, z| FrameImage {
                geometry: &geometries[t.input],
                start_s: t.start_s,
                trace: z,
            };
            Ok(comparisons::compare(
                k,
                &image(&timed[k - 1], &z0),
                &image(&timed[k], &z1),
            )?)
        })
        .collect::<Result<_>>()?;
    let mut pairs = Vec::new();
    let mut differences = Vec::new();
    for (pair, found) in compared {
        pairs.push(pair);
        differences.extend(found);
    }
    Ok((pairs, differences))
}

/// The median over the frames of where the retrace shows what the trace showed (pixels),
/// each frame read again (side by side); `None` when no frame has a retrace whose shift
/// could be measured.
fn retrace_shift(timed: &[Timed], request: &SeriesRequest) -> Result<Option<[f64; 2]>> {
    let config = &request.config;
    let shifts: Vec<Option<[f64; 2]>> = timed
        .par_iter()
        .map(|t| -> Result<_> {
            let pair = t.source.read(config)?;
            let axis = pair.geometry().fast_axis();
            let levelled = |pass| {
                pair.image(pass)
                    .map(|image| comparisons::prepared(&image.z, axis))
            };
            Ok(
                match (levelled(ScanPass::Trace), levelled(ScanPass::Retrace)) {
                    (Some(trace), Some(retrace)) => comparisons::pass_shift(&trace, &retrace, axis),
                    _ => None,
                },
            )
        })
        .collect::<Result<_>>()?;
    let found: Vec<[f64; 2]> = shifts.into_iter().flatten().collect();
    if found.is_empty() {
        return Ok(None);
    }
    let median = |axis: usize| {
        let mut v: Vec<f64> = found.iter().map(|s| s[axis]).collect();
        v.sort_by(f64::total_cmp);
        let n = v.len();
        if n % 2 == 1 {
            v[n / 2]
        } else {
            0.5 * (v[n / 2 - 1] + v[n / 2])
        }
    };
    Ok(Some([median(0), median(1)]))
}

/// The drift spline fitted to `differences`: one interior knot per frame after the first
/// unless `knots` says otherwise (knots closer than a frame period would be left free by
/// comparisons that each span one).
fn fit(
    timed: &[Timed],
    geometries: &[ScanGeometry],
    differences: &[DriftDifference],
    knots: Option<usize>,
) -> Result<DifferenceDriftFit> {
    let duration = geometries[timed[0].input].frame_duration();
    let last = timed.last().expect("at least two frames");
    let end_s = last.start_s + geometries[last.input].frame_duration();
    let basis = SplineBasis {
        start_s: 0.0,
        end_s,
        interior_knots: knots.unwrap_or(timed.len() - 1),
    };
    let first: Vec<f64> = (0..FIRST_FRAME_SAMPLES)
        .map(|i| duration * (i as f64 + 0.5) / FIRST_FRAME_SAMPLES as f64)
        .collect();
    let starts: Vec<f64> = timed.iter().map(|t| t.start_s).collect();
    fit_drift_differences(
        differences,
        basis,
        &moves(timed, geometries),
        &first,
        &starts,
    )
    .context("the drift could not be fitted to the frames' comparisons")
}

/// Where the frame centre changed from one frame to the next (the offset in the headers):
/// a creep starts with the later frame.
fn moves(timed: &[Timed], geometries: &[ScanGeometry]) -> Vec<MoveTiming> {
    timed
        .windows(2)
        .filter_map(|w| {
            let (g0, g1) = (&geometries[w[0].input], &geometries[w[1].input]);
            (g0.offset() != g1.offset()).then(|| MoveTiming {
                start_s: w[1].start_s,
                line_time_s: g1.line_scan_time(),
                frame_s: g1.frame_duration(),
            })
        })
        .collect()
}

fn frame_summary(t: &Timed, g: &ScanGeometry, shifts: Vec<PassShift>) -> ImageFrame {
    ImageFrame {
        file: t.source.to_string(),
        start_s: t.start_s,
        scan_angle_deg: g.scan_angle().to_degrees(),
        offset_m: [g.offset().0, g.offset().1],
        registered_shifts: shifts,
    }
}

/// Pairs with few bands compared, registered images that do not line up.
fn warnings(pairs: &[PairComparison], frames: &[ImageFrame], pitch_m: [f64; 2]) -> Vec<Warning> {
    let few = pairs
        .iter()
        .filter(|p| (p.bands_measured as f64) < FEW_BANDS * p.bands as f64)
        .map(|p| {
            Warning::new(
                WarningCode::FewComparisons,
                format!(
                    "frame {} was matched to frame {} on {} of its {} bands of lines only: \
                     the drift within it rests on the spline's smoothness",
                    p.frame,
                    p.frame - 1,
                    p.bands_measured,
                    p.bands
                ),
                "check the two frames in registered/stack.tif (a changed area, a tip change); \
                 leave the frame out, or split the series there",
            )
        });
    let shifts = frames
        .iter()
        .map(|f| (f.file.as_str(), f.registered_shifts.as_slice()));
    few.chain(super::trust::shifts_beyond(shifts, pitch_m, MISALIGNED_PX))
        .collect()
}

/// What `dhct series --register image` prints.
pub fn text_summary(summary: &ImageSeriesSummary, output: &std::path::Path) -> String {
    use super::report::shown;
    use dhct_scan::quantity::length;
    use std::fmt::Write as _;
    let mut text = String::new();
    for note in &summary.notes {
        let _ = writeln!(text, "note: {note}");
    }
    let fit = &summary.drift;
    let bands: usize = summary.comparisons.iter().map(|p| p.bands).sum();
    let _ = writeln!(
        text,
        "{} frames over {:.0} s registered by their images (no lattice): {} of {} bands of \
         lines compared, the drift fitted to them within ({}, {}) rms, {} outliers",
        summary.frames.len(),
        fit.trajectory.last().map_or(0.0, |p| p.time_s),
        fit.comparisons,
        bands,
        length(fit.rms_residual_m[0]),
        length(fit.rms_residual_m[1]),
        fit.outliers
    );
    for (k, (frame, start)) in summary.frames.iter().zip(&fit.frame_starts).enumerate() {
        let _ = writeln!(
            text,
            "  frame {k:>2} at {:>7.1} s: D = ({}, {}) {}",
            frame.start_s,
            shown(start.displacement_m[0], start.sigma_m[0]),
            shown(start.displacement_m[1], start.sigma_m[1]),
            frame.file
        );
    }
    let largest = summary
        .frames
        .iter()
        .flat_map(|f| &f.registered_shifts)
        .filter_map(|s| s.shift_px.map(|d| d[0].hypot(d[1])))
        .fold(0.0, f64::max);
    let _ = writeln!(
        text,
        "registered images line up within {largest:.3} px of each other by their pixels"
    );
    let _ = writeln!(text, "not determined without a lattice:");
    for what in &summary.undetermined {
        let _ = writeln!(text, "  {what}");
    }
    let _ = writeln!(text, "outputs: {}", output.display());
    let _ = writeln!(text, "report: {}", output.join("report.html").display());
    text
}

/// The warnings, for stderr.
pub fn warning_lines(summary: &ImageSeriesSummary) -> String {
    summary
        .warnings
        .iter()
        .map(|w| format!("warning: {}\n", crate::flags::warning_line(w)))
        .collect()
}
