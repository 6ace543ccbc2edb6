//! `dhct info FILE`: what a file holds, with geometry and timing.

use std::fmt::Write as _;
use std::path::Path;

use anyhow::{Context, Result};
use dhct_scan::{ScanFile, ScanGeometry, ScanPair, ValueSource};
use serde::Serialize;

/// Machine-readable summary of one channel (for `--json`).
#[derive(Serialize)]
struct ChannelSummary<'a> {
    name: &'a str,
    unit: &'a str,
    trace: bool,
    retrace: bool,
    geometry: &'a ScanGeometry,
    width_m: f64,
    height_m: f64,
    line_period_s: f64,
    frame_duration_s: f64,
    z_range: Option<(f64, f64)>,
    non_finite_values: usize,
}

#[derive(Serialize)]
struct FileSummary<'a> {
    path: &'a Path,
    format: &'static str,
    metadata: &'a std::collections::BTreeMap<String, String>,
    channels: Vec<ChannelSummary<'a>>,
}

fn summarise<'a>(path: &'a Path, file: &'a ScanFile) -> FileSummary<'a> {
    let channels = file
        .pairs
        .iter()
        .map(|pair: &ScanPair| {
            let g = pair.geometry();
            let unit = pair.images().next().map(|(_, c)| c.unit.as_str());
            let z_range = pair
                .images()
                .filter_map(|(_, c)| c.finite_range())
                .reduce(|a, b| (a.0.min(b.0), a.1.max(b.1)));
            ChannelSummary {
                name: pair.name(),
                unit: unit.unwrap_or(""),
                trace: pair.trace().is_some(),
                retrace: pair.retrace().is_some(),
                geometry: g,
                width_m: g.width(),
                height_m: g.height(),
                line_period_s: g.line_period(),
                frame_duration_s: g.frame_duration(),
                z_range,
                non_finite_values: pair.images().map(|(_, c)| c.non_finite_count()).sum(),
            }
        })
        .collect();
    FileSummary {
        path,
        format: file.format.name(),
        metadata: &file.metadata,
        channels,
    }
}

/// Formats a value in SI with a prefix that keeps it readable: 2.205e-8 m → "22.05 nm".
pub fn si(value: f64, unit: &str) -> String {
    crate::units::si(value, unit)
}

fn source_note(source: ValueSource) -> &'static str {
    match source {
        ValueSource::Stated => "",
        ValueSource::Assumed => {
            "  [assumed: not in the file or not usable as stated (see above); override with options]"
        }
    }
}

/// One line per channel: name, unit, directions and size (`--channel NAME` picks one).
fn channel_list(summary: &FileSummary) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "channels ({}; pick one with --channel NAME):",
        summary.channels.len()
    );
    let width = summary
        .channels
        .iter()
        .map(|c| c.name.chars().count())
        .max()
        .unwrap_or(0);
    for c in &summary.channels {
        let g = c.geometry;
        let mut passes = Vec::new();
        if c.trace {
            passes.push(format!("trace {:?}", g.trace_fast()).to_lowercase());
        }
        if c.retrace {
            passes.push(format!("retrace {:?}", g.trace_fast().reversed()).to_lowercase());
        }
        let unit = if c.unit.is_empty() { "-" } else { c.unit };
        let _ = writeln!(
            out,
            "  {:width$}  [{unit}]  {}, slow {}  {} x {} px, {} x {}",
            c.name,
            passes.join(" + "),
            format!("{:?}", g.slow_direction()).to_lowercase(),
            g.columns(),
            g.rows(),
            si(c.width_m, "m"),
            si(c.height_m, "m"),
        );
    }
    out
}

fn human(summary: &FileSummary) -> String {
    let mut out = String::new();
    let _ = writeln!(out, "{}: {}", summary.path.display(), summary.format);
    out.push_str(&channel_list(summary));
    for (key, value) in summary.metadata {
        // Multi-line values (RHK session texts, comments) stay indented under their key.
        let value: Vec<&str> = value
            .lines()
            .map(str::trim_end)
            .filter(|l| !l.is_empty())
            .collect();
        let _ = writeln!(out, "  {key}: {}", value.join("\n      "));
    }
    for (index, c) in summary.channels.iter().enumerate() {
        let g = c.geometry;
        let passes = match (c.trace, c.retrace) {
            (true, true) => "trace + retrace",
            (true, false) => "trace only",
            _ => "retrace only",
        };
        let _ = writeln!(out, "channel {index}: {} [{}] ({passes})", c.name, c.unit);
        let _ = writeln!(
            out,
            "  size:        {} x {} px, {} x {}",
            g.columns(),
            g.rows(),
            si(c.width_m, "m"),
            si(c.height_m, "m")
        );
        let _ = writeln!(
            out,
            "  pixel pitch: {} (x), {} (y){}",
            si(g.pitch_x(), "m"),
            si(g.pitch_y(), "m"),
            source_note(g.scale_source())
        );
        let _ = writeln!(
            out,
            "  scan:        trace lines {}, slow axis {}, angle {:.2}°{}",
            crate::report::html::direction_words(g.trace_fast()),
            crate::report::html::direction_words(g.slow_direction()),
            g.scan_angle().to_degrees(),
            source_note(g.timing_source())
        );
        let _ = writeln!(
            out,
            "  timing:      {} per pixel, {} per line (incl. {} turnaround), frame {}{}",
            si(g.pixel_period(), "s"),
            si(c.line_period_s, "s"),
            si(g.turnaround_time(), "s"),
            si(c.frame_duration_s, "s"),
            source_note(g.timing_source())
        );
        let _ = writeln!(
            out,
            "  speeds:      fast {}, slow {}",
            si(g.fast_speed(), "m/s"),
            si(g.slow_speed(), "m/s")
        );
        match c.z_range {
            Some((lo, hi)) => {
                let _ = writeln!(
                    out,
                    "  z range:     {} to {} (span {})",
                    si(lo, c.unit),
                    si(hi, c.unit),
                    si(hi - lo, c.unit)
                );
            }
            None => {
                let _ = writeln!(out, "  z range:     no finite values");
            }
        }
        if c.non_finite_values > 0 {
            let _ = writeln!(out, "  missing:     {} NaN/inf values", c.non_finite_values);
        }
    }
    out
}

/// Reads `path` and prints its summary (JSON when `json`).
pub fn run(path: &Path, overrides: &dhct_sm4_io::GeometryOverrides, json: bool) -> Result<()> {
    let file = dhct_sm4_io::read_path_with_limits(path, overrides, &crate::read_limits::get())
        .with_context(|| path.display().to_string())?;
    let summary = summarise(path, &file);
    // Through a locked stdout: a closed pipe (`dhct info --json | head -1`) is not a panic.
    if json {
        crate::diagnose::write_stdout(&format!("{}\n", serde_json::to_string_pretty(&summary)?))
    } else {
        crate::diagnose::write_stdout(&human(&summary))
    }
}

#[cfg(test)]
mod tests {
    use super::si;

    #[test]
    fn si_prefixes() {
        assert_eq!(si(2.205e-8, "m"), "22.05 nm");
        assert_eq!(si(1.51e-3, "s"), "1.51 ms");
        assert_eq!(si(-3.2e-10, "m"), "-320 pm");
        assert_eq!(si(2.0, "s"), "2 s");
    }
}
