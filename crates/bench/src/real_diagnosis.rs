//! `dhct diagnose` on a file of the real-data corpus, as a user would run it: the verdict
//! (is a gap left between the fitted model and the image, did a named effect close it),
//! where what remains lies, and the residual's size against the noise floor.

use std::path::Path;

use crate::real_corpus::{first_error_line, run_dhct};

/// What the diagnosis said of one file (read from its `diagnosis.json`).
#[derive(Debug, Clone, PartialEq)]
pub struct DiagnosisOutcome {
    /// `no_gap`, `explained`, `partly_explained` or `unexplained`.
    pub verdict: String,
    /// Gap over the noise floor with the base model.
    pub gap_before: f64,
    /// The same after the effects named.
    pub gap_after: f64,
    /// The effects named (closing the gap), in order.
    pub effects: Vec<String>,
    /// Places where the remaining gap lies, as the verdict labels them.
    pub remaining: Vec<String>,
    /// The noise floor, metres `[x, y]`.
    pub floor_m: [f64; 2],
    /// The verdict in words.
    pub summary: String,
}

/// Runs `dhct diagnose INPUT -o OUT ARGS` from `root` and reads what it wrote;
/// `Err` with the first error line when it is refused.
pub fn diagnose_file(
    dhct: &Path,
    input: &Path,
    args: &[String],
    root: &Path,
    out: &Path,
) -> Result<DiagnosisOutcome, String> {
    run_dhct(dhct, "diagnose", input, args, root, out)
        .map_err(|stderr| first_error_line(&stderr))?;
    let text = std::fs::read_to_string(out.join("diagnosis.json"))
        .map_err(|e| format!("diagnosis.json: {e}"))?;
    let report: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| format!("diagnosis.json: {e}"))?;
    Ok(outcome_of(&report))
}

/// The outcome held in a `diagnosis.json` document.
fn outcome_of(report: &serde_json::Value) -> DiagnosisOutcome {
    let details = &report["verdict_details"];
    let strings = |v: &serde_json::Value| -> Vec<String> {
        let items = v.as_array().into_iter().flatten();
        items
            .filter_map(|s| s.as_str().map(str::to_owned))
            .collect()
    };
    let places = details["remaining"].as_array().into_iter().flatten();
    let floor = &report["noise"]["sigma_m"];
    DiagnosisOutcome {
        verdict: report["verdict"].as_str().unwrap_or("?").to_string(),
        gap_before: details["gap_before"].as_f64().unwrap_or(f64::NAN),
        gap_after: details["gap_after"].as_f64().unwrap_or(f64::NAN),
        effects: strings(&details["effects"]),
        remaining: places
            .filter_map(|p| p["label"].as_str().map(str::to_owned))
            .collect(),
        floor_m: [0, 1].map(|k| floor[k].as_f64().unwrap_or(f64::NAN)),
        summary: details["summary"].as_str().unwrap_or("").to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_outcome_is_read_from_the_report_fields() {
        let report = serde_json::json!({
            "verdict": "partly_explained",
            "noise": { "sigma_m": [2e-12, 3e-12] },
            "verdict_details": {
                "gap_before": 2.5, "gap_after": 1.6,
                "effects": ["tip-change"],
                "remaining": [{ "label": "late in the frame" }],
                "summary": "a tip change; the rest lies late in the frame",
            },
        });
        let outcome = outcome_of(&report);
        assert_eq!(outcome.verdict, "partly_explained");
        assert_eq!(outcome.effects, ["tip-change"]);
        assert_eq!(outcome.remaining, ["late in the frame"]);
        assert_eq!(outcome.floor_m, [2e-12, 3e-12]);
        assert!((outcome.gap_after - 1.6).abs() < 1e-12);
    }
}
