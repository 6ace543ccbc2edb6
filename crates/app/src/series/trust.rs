//! What a series' results should not be trusted for: frames the session's model does not
//! explain, and registered images whose lattice, measured by FFT as an outside check
//! would, is not the lattice given. Each is a typed [`Warning`], as `dhct correct` gives.

use dhct_distortion::series::SeriesFit;
use dhct_lattice::Lattice;
use dhct_pipeline::{
    CorrectedImageCheck, UserInput, Warning, WarningCode, image_off_message,
    image_unchecked_message,
};
use dhct_scan::quantity::length;

use super::outputs::RegisteredChecks;
use super::{FrameSummary, PassShift, Timed};

/// A registered image shifted more than this (pixels of the first frame's grid) against
/// the frame it is compared with does not line up with it. The registration's own error is
/// ~0.01 px on simulated sessions (`crates/cli/tests/series.rs`), and the pixel measurement
/// of it reads 0.01–0.035 px there.
pub const SHIFT_WARNING_PX: f64 = 0.1;

/// A frame whose rms deviation from the lattice is more than this many times the frames'
/// median is not explained by the session's model.
pub const UNEXPLAINED_FRAME_RATIO: f64 = 3.0;

/// Frames whose features the session's model leaves far off their sites (a frame placed a
/// lattice vector off, or something the model does not hold happened during it).
pub fn unexplained_frames(fit: &SeriesFit, timed: &[Timed]) -> Vec<Warning> {
    let mut sorted: Vec<f64> = fit
        .frame_rms_m
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .collect();
    sorted.sort_by(f64::total_cmp);
    let Some(&median) = sorted.get(sorted.len() / 2) else {
        return Vec::new();
    };
    fit.frame_rms_m
        .iter()
        .zip(timed)
        .enumerate()
        .filter(|(_, (rms, _))| **rms > UNEXPLAINED_FRAME_RATIO * median)
        .map(|(k, (rms, t))| {
            Warning::new(
                WarningCode::FrameNotExplained,
                format!(
                    "frame {k} ({}) deviates {} rms from the lattice, the frames' median is {}: \
                     the session's model does not explain it (placed a lattice period off, a \
                     tip change, or a move the headers do not record)",
                    t.source,
                    length(*rms),
                    length(median)
                ),
                "check its registered image; leave the frame out, or split the series where \
                 the tip was moved",
            )
        })
        .collect()
}

/// Registered images whose pixels are shifted more than [`SHIFT_WARNING_PX`] against the
/// frame they were compared with.
pub fn shift_warnings(frames: &[FrameSummary], pitch_m: [f64; 2]) -> Vec<Warning> {
    let frames = frames
        .iter()
        .map(|f| (f.file.as_str(), f.registered_shifts.as_slice()));
    shifts_beyond(frames, pitch_m, SHIFT_WARNING_PX)
}

/// Registered images (each frame's file and shifts, in time order) whose pixels are
/// shifted more than `limit_px` against the frame they were compared with.
pub fn shifts_beyond<'a>(
    frames: impl Iterator<Item = (&'a str, &'a [PassShift])>,
    pitch_m: [f64; 2],
    limit_px: f64,
) -> Vec<Warning> {
    let mut warnings = Vec::new();
    for (k, (file, shifts)) in frames.enumerate() {
        for s in shifts {
            let (Some(d), Some(against)) = (s.shift_px, s.against_frame) else {
                continue;
            };
            if d[0].hypot(d[1]) <= limit_px {
                continue;
            }
            warnings.push(Warning::new(
                WarningCode::FramesDisagree,
                format!(
                    "registered frame {k} ({file}), {}: its pixels lie ({:.3}, {:.3}) px ({}) \
                     off frame {against}'s trace, more than {limit_px} px: the two are not \
                     registered alike (a creep, tip change or move the session's model does \
                     not hold, or a placement a lattice period off)",
                    s.pass,
                    d[0],
                    d[1],
                    length((d[0] * pitch_m[0]).hypot(d[1] * pitch_m[1]))
                ),
                "compare the frames in registered/stack.tif; leave the frame out, or split \
                 the series where it changes",
            ));
        }
    }
    warnings
}

/// The registered images (each frame's, and their mean) whose lattice is not the lattice
/// given, or could not be measured although the raw image's could.
pub fn registered_image_warnings(
    checks: &RegisteredChecks,
    timed: &[Timed],
    lattice: &dyn Lattice,
) -> Vec<Warning> {
    if !checks.made {
        return Vec::new();
    }
    let mut warnings = Vec::new();
    for (k, (measured, t)) in checks.frames.iter().zip(timed).enumerate() {
        let what = format!("registered frame {k} ({})", t.source);
        for c in measured.iter().filter(|c| !c.passes()) {
            warnings.push(image_off(&format!("{what}, {}", c.pass), c, lattice));
        }
        if let Some(passes) = checks.unmeasured.get(k).filter(|p| !p.is_empty()) {
            let passes: Vec<String> = passes.iter().map(|p| p.to_string()).collect();
            warnings.push(image_unchecked(&format!(
                "{what}, {}",
                passes.join(" and ")
            )));
        }
    }
    match &checks.mean {
        Some(c) if !c.passes() => warnings.push(image_off("the mean image", c, lattice)),
        Some(_) => {}
        None => warnings.push(image_unchecked("the mean image")),
    }
    warnings
}

/// `what` (a registered image) shows another lattice than the one given.
fn image_off(what: &str, check: &CorrectedImageCheck, lattice: &dyn Lattice) -> Warning {
    Warning::new(
        WarningCode::CorrectedImageOff,
        image_off_message(what, check, lattice),
        "do not take lengths from this image: check the frames' timing, scan angles and \
         offsets, and the lattice constant given",
    )
    .with_inputs(&[
        UserInput::LineTime,
        UserInput::ScanDirections,
        UserInput::NearestNeighbourDistance,
    ])
}

/// `what` (a registered image) has no lattice an FFT can measure.
fn image_unchecked(what: &str) -> Warning {
    Warning::new(
        WarningCode::CorrectedImageUnchecked,
        image_unchecked_message(what),
        "check lengths in this image against a known feature before taking them",
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use dhct_calibrate::Calibration;
    use dhct_lattice::Hexagonal;
    use dhct_scan::ScanPass;
    use std::path::PathBuf;

    fn timed(n: usize) -> Vec<Timed> {
        (0..n)
            .map(|k| Timed {
                input: k,
                source: crate::series::FrameSource {
                    path: PathBuf::from(format!("f{k}.sm4")),
                    frame: None,
                },
                start_s: 60.0 * k as f64,
            })
            .collect()
    }

    fn check(pass: ScanPass, scale_y: f64) -> CorrectedImageCheck {
        let mut calibration = Calibration::identity();
        calibration.scale[1] = scale_y;
        calibration.matrix[1][1] = scale_y;
        CorrectedImageCheck {
            pass,
            calibration,
            angle_error_deg: 0.0,
        }
    }

    #[test]
    fn registered_images_off_or_unmeasured_are_named_by_frame_and_pass() {
        let lattice = Hexagonal::graphite();
        let checks = RegisteredChecks {
            frames: vec![
                vec![check(ScanPass::Trace, 1.0), check(ScanPass::Retrace, 1.0)],
                vec![check(ScanPass::Trace, 1.04)],
            ],
            unmeasured: vec![vec![], vec![ScanPass::Retrace]],
            mean: Some(check(ScanPass::Trace, 1.0)),
            made: true,
            shifts: Vec::new(),
        };
        let warnings = registered_image_warnings(&checks, &timed(2), &lattice);
        let codes: Vec<WarningCode> = warnings.iter().map(|w| w.code).collect();
        assert_eq!(
            codes,
            [
                WarningCode::CorrectedImageOff,
                WarningCode::CorrectedImageUnchecked
            ]
        );
        assert!(
            warnings[0]
                .message
                .contains("registered frame 1 (f1.sm4), trace"),
            "{}",
            warnings[0].message
        );
        assert!(warnings[0].message.contains("104.00 %"), "{}", warnings[0]);
        // A mean image off is named too; none of it when the raw lattice was not measured.
        let off_mean = RegisteredChecks {
            mean: Some(check(ScanPass::Trace, 0.97)),
            ..RegisteredChecks::default()
        };
        assert!(registered_image_warnings(&off_mean, &timed(2), &lattice).is_empty());
        let made = RegisteredChecks {
            made: true,
            ..off_mean
        };
        let warnings = registered_image_warnings(&made, &timed(2), &lattice);
        assert_eq!(warnings.len(), 1);
        assert!(
            warnings[0].message.starts_with("the mean image"),
            "{}",
            warnings[0]
        );
    }

    #[test]
    fn frames_whose_pixels_do_not_line_up_are_named() {
        let frame = |k: usize, d: Option<[f64; 2]>| FrameSummary {
            file: format!("f{k}.sm4"),
            start_s: 60.0 * k as f64,
            scan_angle_deg: 0.0,
            offset_m: [0.0; 2],
            features: 100,
            own_hysteresis: Vec::new(),
            warnings: Vec::new(),
            registered_checks: Vec::new(),
            registered_shifts: vec![super::super::PassShift {
                pass: ScanPass::Trace,
                against_frame: Some(0),
                shift_px: d,
            }],
        };
        let frames = [
            frame(1, Some([0.03, -0.02])),
            frame(2, Some([0.12, 0.05])),
            frame(3, None),
        ];
        let warnings = shift_warnings(&frames, [1e-11; 2]);
        assert_eq!(warnings.len(), 1, "{warnings:?}");
        assert_eq!(warnings[0].code, WarningCode::FramesDisagree);
        assert!(
            warnings[0]
                .message
                .starts_with("registered frame 1 (f2.sm4), trace"),
            "{}",
            warnings[0].message
        );
    }
}
