//! The frames of a series on one clock: ordered by the start time each file records,
//! spaced by it, and what to say when a file records none or frames overlap in time.

use anyhow::{Result, bail};
use dhct_scan::ScanGeometry;

use super::FrameSource;

/// Start times a file rounds to the second may make back-to-back frames overlap, or seem
/// to pause, by up to this much (seconds); the later frame is then taken to start when the
/// earlier ended. (Where the drift runs at 100 pm/s, a second of pause that is not there
/// carries the drift 100 pm, a third of a graphite period, into the next frame.)
const ROUNDING_OVERLAP_S: f64 = 1.5;

/// One frame's place on the session clock.
#[derive(Debug, Clone, PartialEq)]
pub struct Timed {
    /// Index of the frame among the inputs (path order).
    pub input: usize,
    /// Its file (or frame of a file).
    pub source: FrameSource,
    /// Seconds since the first frame's start.
    pub start_s: f64,
}

/// The frames in time order with their session start times, and notes for the user (an
/// order other than the names', a clock assumed, a start moved past a rounding overlap).
pub fn order(frames: &[(FrameSource, &ScanGeometry)]) -> Result<(Vec<Timed>, Vec<String>)> {
    let mut notes = Vec::new();
    let stated: Vec<Option<f64>> = frames.iter().map(|(_, g)| g.start_time()).collect();
    if stated.iter().any(Option::is_none) {
        let missing: Vec<String> = frames
            .iter()
            .zip(&stated)
            .filter(|(_, s)| s.is_none())
            .map(|((p, _), _)| p.to_string())
            .collect();
        notes.push(format!(
            "assumption: {} of {} frames record no start time ({}); the frames are taken in \
             name order (a file's own frames in its order), each starting when the one \
             before ended (pauses between frames would make the drift between them wrong)",
            missing.len(),
            frames.len(),
            missing.join(", ")
        ));
        let mut start = 0.0;
        let timed = frames
            .iter()
            .enumerate()
            .map(|(input, (path, g))| {
                let t = Timed {
                    input,
                    source: path.clone(),
                    start_s: start,
                };
                start += g.frame_duration();
                t
            })
            .collect();
        return Ok((timed, notes));
    }
    let mut order: Vec<usize> = (0..frames.len()).collect();
    order.sort_by(|&a, &b| {
        stated[a]
            .unwrap_or(0.0)
            .total_cmp(&stated[b].unwrap_or(0.0))
    });
    if order.iter().enumerate().any(|(k, &i)| k != i) {
        notes.push(
            "the frames are taken in the order of their recorded start times, not of their names"
                .into(),
        );
    }
    let first = stated[order[0]].unwrap_or(0.0);
    let mut timed: Vec<Timed> = Vec::new();
    for &i in &order {
        let mut start_s = stated[i].unwrap_or(0.0) - first;
        if let Some(before) = timed.last() {
            let end = before.start_s + frames[before.input].1.frame_duration();
            if start_s < end - ROUNDING_OVERLAP_S {
                bail!(
                    "{} starts {:.1} s into the session but {} (started {:.1} s in) takes {:.1} s: \
                     the frames overlap in time, so they are not one sequence of scans (check \
                     the files' dates and line times)",
                    frames[i].0,
                    start_s,
                    before.source,
                    before.start_s,
                    frames[before.input].1.frame_duration()
                );
            }
            let rounded = |t: Option<f64>| t.is_some_and(|t| t.fract() == 0.0);
            let seeming_pause = start_s > end
                && start_s < end + ROUNDING_OVERLAP_S
                && rounded(stated[i])
                && rounded(stated[before.input]);
            if seeming_pause {
                notes.push(format!(
                    "{} starts {:.1} s after {} ended by the start times the files record, \
                     which are rounded to the second: taken to follow it directly",
                    frames[i].0,
                    start_s - end,
                    before.source
                ));
            }
            if start_s < end || seeming_pause {
                start_s = end;
            }
        }
        timed.push(Timed {
            input: i,
            source: frames[i].0.clone(),
            start_s,
        });
    }
    Ok((timed, notes))
}

#[cfg(test)]
mod tests {
    use super::*;
    use dhct_scan::ScanDirection;

    fn source(k: usize) -> FrameSource {
        FrameSource {
            path: format!("f{k}").into(),
            frame: None,
        }
    }

    fn geometry(start: Option<f64>) -> ScanGeometry {
        // 10 lines of 1 s each way: a 20 s frame.
        ScanGeometry::from_line_time(
            10,
            10,
            1e-10,
            1e-10,
            1.0,
            ScanDirection::Right,
            ScanDirection::Down,
        )
        .unwrap()
        .with_start_time(start)
    }

    #[test]
    fn frames_are_ordered_by_time_and_overlaps_refused() {
        let g = [
            geometry(Some(130.0)),
            geometry(Some(100.0)),
            geometry(Some(119.0)),
        ];
        let frames: Vec<(FrameSource, &ScanGeometry)> =
            g.iter().enumerate().map(|(k, g)| (source(k), g)).collect();
        let err = order(&frames).unwrap_err().to_string();
        assert!(err.contains("overlap"), "{err}");
        let g = [
            geometry(Some(150.0)),
            geometry(Some(100.0)),
            geometry(Some(119.5)),
        ];
        let frames: Vec<(FrameSource, &ScanGeometry)> =
            g.iter().enumerate().map(|(k, g)| (source(k), g)).collect();
        let (timed, notes) = order(&frames).unwrap();
        let starts: Vec<(usize, f64)> = timed.iter().map(|t| (t.input, t.start_s)).collect();
        assert_eq!(starts, [(1, 0.0), (2, 20.0), (0, 50.0)]);
        assert!(notes[0].contains("recorded start times"), "{notes:?}");
        // Whole seconds a second past the frame before's end: taken as back to back (the
        // Nanosurf frames of 26.5 s by their headers, 25.5 s by their line times); two
        // seconds, or a time with a fraction, is a pause.
        let g = [
            geometry(Some(100.0)),
            geometry(Some(121.0)),
            geometry(Some(143.0)),
            geometry(Some(163.5)),
        ];
        let frames: Vec<(FrameSource, &ScanGeometry)> =
            g.iter().enumerate().map(|(k, g)| (source(k), g)).collect();
        let (timed, notes) = order(&frames).unwrap();
        let starts: Vec<f64> = timed.iter().map(|t| t.start_s).collect();
        assert_eq!(starts, [0.0, 20.0, 43.0, 63.5]);
        assert_eq!(notes.len(), 1, "{notes:?}");
        assert!(
            notes[0].contains("taken to follow it directly"),
            "{notes:?}"
        );
        let g = [geometry(Some(100.0)), geometry(None)];
        let frames: Vec<(FrameSource, &ScanGeometry)> =
            g.iter().enumerate().map(|(k, g)| (source(k), g)).collect();
        let (timed, notes) = order(&frames).unwrap();
        assert_eq!(timed[1].start_s, 20.0);
        assert!(
            notes[0].starts_with("assumption: 1 of 2 frames"),
            "{notes:?}"
        );
    }
}
