//! What the image views add to a report: the residual images' height signal in the
//! verdict's words, and a vibration found below one feature as a named effect.

use crate::image_view::along_line::z_value;
use crate::image_view::image_residual::PassResidual;
use crate::image_view::sub_feature::SubFeatureView;
use crate::report::diagnosis::DiagnosisReport;
use crate::report::verdict::VerdictKind;
use crate::search::candidates::Candidate;

impl DiagnosisReport {
    /// The report with the residual images' summaries; a height signal found along the
    /// lines is named in the verdict's words as what it is (z only: the verdict's kind is
    /// about scan distortions and stays as it is).
    pub fn with_image_residual(mut self, passes: Vec<PassResidual>) -> Self {
        let found: Vec<String> = passes
            .iter()
            .filter_map(|p| {
                let peak = p.along_line.as_ref().filter(|peak| peak.is_found())?;
                Some(format!(
                    "{} {:.1} Hz ({})",
                    p.pass,
                    peak.frequency_hz,
                    z_value(peak.amplitude, &p.z_unit)
                ))
            })
            .collect();
        if !found.is_empty() {
            self.verdict_details.summary.push_str(&format!(
                " The image also holds a height signal along the lines that moves no feature \
                 ({}): electrical pickup or a vibration in z, not a scan distortion.",
                found.join(", ")
            ));
        }
        self.image_residual = passes;
        self
    }
}

impl DiagnosisReport {
    /// Adds the image view below one feature. A vibration found there is one of the named
    /// effects: a verdict of `no_gap` becomes `explained` and names the vibration first
    /// (what the positions added there stayed within the floor), and the verdict's words
    /// lead with it (the position gap numbers are unchanged: the positions do not see it).
    pub fn with_sub_feature_view(mut self, view: SubFeatureView) -> Self {
        if view.vibration_found {
            let v = &mut self.verdict_details;
            let vibration = Candidate::Vibration;
            if v.kind == VerdictKind::NoGap {
                v.kind = VerdictKind::Explained;
                v.effects.retain(|c| *c != vibration);
                v.effects.insert(0, vibration);
                v.summary = format!(
                    "Explained {}. The feature positions alone: {}",
                    view.describe(),
                    v.summary
                );
            } else {
                if !v.effects.contains(&vibration) {
                    v.effects.push(vibration);
                }
                v.summary = format!("{}. {}", capitalised(&view.describe()), v.summary);
            }
            self.verdict = v.kind;
        }
        self.sub_feature = Some(view);
        self
    }
}

fn capitalised(text: &str) -> String {
    let mut chars = text.chars();
    chars
        .next()
        .map(|c| c.to_uppercase().chain(chars).collect())
        .unwrap_or_default()
}
