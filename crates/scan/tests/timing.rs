//! The timing formulas of `ScanGeometry` checked against an explicit simulation of the tip's
//! raster, for every fast/slow direction combination, non-square images and turnaround.

use dhct_scan::{GeometryError, ScanDirection, ScanGeometry, ScanPass};
use proptest::prelude::*;

use ScanDirection::{Down, Left, Right, Up};

const ALL_COMBINATIONS: [(ScanDirection, ScanDirection); 8] = [
    (Right, Down),
    (Right, Up),
    (Left, Down),
    (Left, Up),
    (Down, Right),
    (Down, Left),
    (Up, Right),
    (Up, Left),
];

/// One pixel visit of the simulated raster: pass, column, row, time since frame start,
/// time since line start.
type Visit = (ScanPass, usize, usize, f64, f64);

/// Walks the tip through the raster step by step, keeping a clock, independently of the
/// closed-form formulas under test.
fn simulate_raster(
    columns: usize,
    rows: usize,
    period: f64,
    turnaround: f64,
    fast: ScanDirection,
    slow: ScanDirection,
) -> Vec<Visit> {
    let horizontal_fast = matches!(fast, Left | Right);
    let (n_fast, n_slow) = if horizontal_fast {
        (columns, rows)
    } else {
        (rows, columns)
    };
    // Positions along an axis in the order a direction visits them.
    let ordered = |direction: ScanDirection, n: usize| -> Vec<usize> {
        match direction {
            Right | Down => (0..n).collect(),
            Left | Up => (0..n).rev().collect(),
        }
    };
    let mut clock = 0.0;
    let mut visits = Vec::new();
    for slow_position in ordered(slow, n_slow) {
        for (pass, direction) in [(ScanPass::Trace, fast), (ScanPass::Retrace, reverse(fast))] {
            for (k, fast_position) in ordered(direction, n_fast).into_iter().enumerate() {
                let (col, row) = if horizontal_fast {
                    (fast_position, slow_position)
                } else {
                    (slow_position, fast_position)
                };
                let in_line = (k as f64 + 0.5) * period;
                visits.push((pass, col, row, clock + in_line, in_line));
            }
            clock += n_fast as f64 * period + turnaround;
        }
    }
    visits
}

fn reverse(d: ScanDirection) -> ScanDirection {
    match d {
        Right => Left,
        Left => Right,
        Down => Up,
        Up => Down,
    }
}

#[test]
fn every_direction_combination_matches_the_simulated_raster() {
    let (columns, rows, period, turnaround) = (7, 5, 2e-3, 3e-4);
    for (fast, slow) in ALL_COMBINATIONS {
        let geometry = ScanGeometry::new(columns, rows, 1e-10, 2e-10, period, fast, slow)
            .unwrap()
            .with_turnaround(turnaround)
            .unwrap();
        let visits = simulate_raster(columns, rows, period, turnaround, fast, slow);
        assert_eq!(visits.len(), 2 * columns * rows);
        for (pass, col, row, frame_time, line_time) in visits {
            let t = geometry.acquisition_time(pass, col as f64, row as f64);
            assert!(
                (t.since_frame_start - frame_time).abs() < 1e-12,
                "{fast:?}/{slow:?} {pass:?} ({col},{row}): {} vs simulated {frame_time}",
                t.since_frame_start
            );
            assert!((t.since_line_start - line_time).abs() < 1e-12);
        }
        let last_visit_end = geometry.frame_duration() - turnaround - 0.5 * period;
        let (frame_map, _) = geometry.acquisition_time_maps(ScanPass::Retrace);
        let latest = frame_map.iter().cloned().fold(f64::MIN, f64::max);
        assert!((latest - last_visit_end).abs() < 1e-12, "{fast:?}/{slow:?}");
    }
}

#[test]
fn the_trace_starts_at_the_corner_where_both_directions_begin() {
    let expected_first = |fast: ScanDirection, slow: ScanDirection| {
        let col_start = |d| if d == Left { 6 } else { 0 };
        let row_start = |d| if d == Up { 4 } else { 0 };
        let col = if matches!(fast, Left | Right) {
            col_start(fast)
        } else {
            col_start(slow)
        };
        let row = if matches!(fast, Up | Down) {
            row_start(fast)
        } else {
            row_start(slow)
        };
        (col, row)
    };
    for (fast, slow) in ALL_COMBINATIONS {
        let g = ScanGeometry::new(7, 5, 1e-10, 1e-10, 1e-3, fast, slow).unwrap();
        let (map, _) = g.acquisition_time_maps(ScanPass::Trace);
        let ((row, col), _) = map
            .indexed_iter()
            .min_by(|a, b| a.1.total_cmp(b.1))
            .unwrap();
        assert_eq!((col, row), expected_first(fast, slow), "{fast:?}/{slow:?}");
    }
}

#[test]
fn retrace_follows_the_trace_line_and_runs_backwards() {
    let g = ScanGeometry::new(4, 3, 1e-10, 1e-10, 1e-3, Right, Down)
        .unwrap()
        .with_turnaround(5e-4)
        .unwrap();
    // Last pixel of trace line 0 (col 3) at 3.5 ms; retrace starts at 4 ms + 0.5 ms turnaround.
    let trace_end = g.acquisition_time(ScanPass::Trace, 3.0, 0.0);
    let retrace_start = g.acquisition_time(ScanPass::Retrace, 3.0, 0.0);
    assert!((trace_end.since_frame_start - 3.5e-3).abs() < 1e-15);
    assert!((retrace_start.since_frame_start - 5.0e-3).abs() < 1e-15);
    assert!((retrace_start.since_line_start - 0.5e-3).abs() < 1e-15);
    // Next trace line starts after the retrace and its turnaround: 2 * 4.5 ms.
    let next = g.acquisition_time(ScanPass::Trace, 0.0, 1.0);
    assert!((next.since_frame_start - 9.5e-3).abs() < 1e-15);
    assert!((g.line_period() - 4.5e-3).abs() < 1e-15);
    assert!((g.frame_duration() - 27e-3).abs() < 1e-15);
}

#[test]
fn derived_quantities_use_the_right_axes_for_non_square_images() {
    // Vertical fast axis: lines are columns, 3 px long; 8 lines.
    let g = ScanGeometry::new(8, 3, 2e-10, 1e-10, 1e-3, Up, Left).unwrap();
    assert_eq!((g.fast_len(), g.slow_len()), (3, 8));
    assert_eq!((g.fast_pitch(), g.slow_pitch()), (1e-10, 2e-10));
    assert!((g.fast_speed() - 1e-7).abs() < 1e-20);
    assert!((g.slow_speed() - 2e-10 / 6e-3).abs() < 1e-20);
    assert!((g.width() - 1.6e-9).abs() < 1e-20 && (g.height() - 3e-10).abs() < 1e-20);
    let g = ScanGeometry::from_line_time(10, 4, 1e-10, 1e-10, 0.5, Right, Down).unwrap();
    assert!((g.pixel_period() - 0.05).abs() < 1e-15);
}

#[test]
fn invalid_geometries_are_rejected_with_the_reason() {
    let new = |c, r, px, p, f, s| ScanGeometry::new(c, r, px, 1e-10, p, f, s);
    assert!(matches!(
        new(0, 5, 1e-10, 1e-3, Right, Down),
        Err(GeometryError::EmptyImage { .. })
    ));
    assert!(matches!(
        new(5, 5, -1e-10, 1e-3, Right, Down),
        Err(GeometryError::NotPositive {
            what: "x pixel pitch",
            ..
        })
    ));
    assert!(matches!(
        new(5, 5, 1e-10, f64::NAN, Right, Down),
        Err(GeometryError::NotPositive {
            what: "pixel period",
            ..
        })
    ));
    assert!(matches!(
        new(5, 5, 1e-10, 1e-3, Right, Left),
        Err(GeometryError::NotPerpendicular { .. })
    ));
    let g = new(5, 5, 1e-10, 1e-3, Right, Down).unwrap();
    assert!(g.clone().with_turnaround(-1.0).is_err());
    assert!(g.with_scan_angle(f64::INFINITY).is_err());
}

#[test]
fn geometry_serialises_with_units_and_validates_on_load() {
    let g = ScanGeometry::new(6, 4, 1e-10, 2e-10, 1e-3, Down, Right)
        .unwrap()
        .with_turnaround(1e-4)
        .unwrap()
        .with_scan_angle(0.3)
        .unwrap();
    let json = serde_json::to_string(&g).unwrap();
    assert!(json.contains("\"pixel_period_s\":0.001"), "{json}");
    let back: ScanGeometry = serde_json::from_str(&json).unwrap();
    assert_eq!(back, g);
    let bad = json.replace("\"slow\":\"right\"", "\"slow\":\"up\"");
    assert!(serde_json::from_str::<ScanGeometry>(&bad).is_err());
}

proptest! {
    #[test]
    fn position_of_inverts_the_fast_and_slow_indices(
        combination in 0usize..8,
        retrace in any::<bool>(),
        columns in 1usize..40,
        rows in 1usize..40,
        fx in 0.0f64..1.0,
        fy in 0.0f64..1.0,
    ) {
        let (fast, slow) = ALL_COMBINATIONS[combination];
        let pass = if retrace { ScanPass::Retrace } else { ScanPass::Trace };
        let g = ScanGeometry::new(columns, rows, 1e-10, 1e-10, 1e-3, fast, slow).unwrap();
        let (x, y) = (fx * (columns - 1) as f64, fy * (rows - 1) as f64);
        let (bx, by) = g.position_of(pass, g.fast_index(pass, x, y), g.slow_index(x, y));
        prop_assert!((bx - x).abs() < 1e-9 && (by - y).abs() < 1e-9);
    }

    #[test]
    fn sub_pixel_times_interpolate_linearly_along_a_line(
        combination in 0usize..8,
        retrace in any::<bool>(),
        fraction in 0.0f64..1.0,
    ) {
        let (fast, slow) = ALL_COMBINATIONS[combination];
        let pass = if retrace { ScanPass::Retrace } else { ScanPass::Trace };
        let g = ScanGeometry::new(9, 6, 1e-10, 1e-10, 1e-3, fast, slow).unwrap();
        let (x0, y0) = (3.0, 2.0);
        let (x1, y1) = if matches!(fast, Left | Right) { (4.0, 2.0) } else { (3.0, 3.0) };
        let a = g.acquisition_time(pass, x0, y0).since_frame_start;
        let b = g.acquisition_time(pass, x1, y1).since_frame_start;
        let (xm, ym) = (x0 + fraction * (x1 - x0), y0 + fraction * (y1 - y0));
        let m = g.acquisition_time(pass, xm, ym).since_frame_start;
        prop_assert!((m - (a + fraction * (b - a))).abs() < 1e-12);
        prop_assert!(((b - a).abs() - 1e-3).abs() < 1e-12);
    }
}
