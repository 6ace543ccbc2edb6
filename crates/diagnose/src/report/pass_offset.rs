//! The base model's offset across the lines between the two passes, read as a finding
//! when it is larger than measuring the features can make it.
//!
//! The base model fits it always (`model::terms::PassOffset`): levelling the lines of an
//! image leaves the passes up to a picometre or two apart, and no effect should be named
//! for that. Tens of picometres or more are something else: the slow axis stepping during
//! the turnaround, scan directions or a turnaround time the timing does not follow. The
//! correction leaves such an offset in its images (trace and retrace disagree), so it is
//! reported with what to check, and the verdict cannot be that the correction's model
//! explains the scan: `no_gap` becomes `unexplained` (no effect of the library makes the
//! offset), `explained` becomes `partly_explained`.

use dhct_scan::{Axis, ScanGeometry};
use serde::{Deserialize, Serialize};

use crate::VerdictKind;
use crate::model::fit::FittedParameter;
use crate::model::terms::ACROSS_LINES_PARAMETER;
use crate::report::verdict::Verdict;

/// An offset at least this many times the noise floor across the lines is a finding
/// (levelled simulated scans leave at most about 1.1 floors).
pub const PASS_OFFSET_FLOORS: f64 = 2.0;

/// The offset across the lines between the passes that the base model fitted.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PassOffsetReading {
    /// How far the retrace's features sit from the trace's along the slow axis, metres.
    pub across_m: f64,
    /// Its 1σ, metres.
    pub sigma_m: f64,
    /// `|across_m|` over the noise floor along the slow axis.
    pub over_floor: f64,
    /// Whether it is a finding: at least [`PASS_OFFSET_FLOORS`] floors and 3σ.
    pub finding: bool,
}

impl PassOffsetReading {
    /// The reading of the base model's fitted `parameters` (`None` without the term, as
    /// with one pass), against the floor `sigma_m` (x, y).
    pub(crate) fn of(
        parameters: &[FittedParameter],
        sigma_m: [f64; 2],
        geometry: &ScanGeometry,
    ) -> Option<PassOffsetReading> {
        let p = parameters
            .iter()
            .find(|p| p.name == ACROSS_LINES_PARAMETER)?;
        let floor = match geometry.fast_axis() {
            Axis::Horizontal => sigma_m[1],
            Axis::Vertical => sigma_m[0],
        };
        let sigma_m = p.sigma.unwrap_or(f64::NAN);
        let over_floor = p.value.abs() / floor;
        let finding = over_floor >= PASS_OFFSET_FLOORS && p.value.abs() >= 3.0 * sigma_m.max(0.0);
        Some(PassOffsetReading {
            across_m: p.value,
            sigma_m,
            over_floor,
            finding,
        })
    }

    /// `verdict` with the offset taken into account: when it is a finding, the summary
    /// gains [`Self::sentence`] and a verdict that the model explains the scan is lowered.
    pub(crate) fn apply_to(&self, verdict: &mut Verdict) {
        let Some(sentence) = self.sentence() else {
            return;
        };
        verdict.kind = match verdict.kind {
            VerdictKind::NoGap => VerdictKind::Unexplained,
            VerdictKind::Explained => VerdictKind::PartlyExplained,
            kind => kind,
        };
        verdict.summary = format!("{} {sentence}", verdict.summary);
    }

    /// The sentence the verdict's summary gains when the offset is a finding.
    pub fn sentence(&self) -> Option<String> {
        self.finding.then(|| {
            format!(
                "But trace and retrace sit {:.1} ± {:.1} pm apart across the lines ({:.1} × \
                 the floor), the same everywhere: no tip motion does this, and the correction \
                 leaves it in its images (the gap above is with the offset taken out). Check \
                 the scan's timing at the turnaround (a slow axis that steps while the retrace \
                 runs), the scan directions and the turnaround time.",
                self.across_m * 1e12,
                self.sigma_m * 1e12,
                self.over_floor
            )
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use dhct_scan::ScanDirection;

    fn parameter(value: f64, sigma: f64) -> FittedParameter {
        FittedParameter {
            effect: "pass-offset".into(),
            name: ACROSS_LINES_PARAMETER.into(),
            value,
            sigma: Some(sigma),
        }
    }

    #[test]
    fn an_offset_is_a_finding_only_beyond_two_floors_and_three_sigma() {
        let geometry = ScanGeometry::new(
            64,
            64,
            1e-11,
            1e-11,
            1e-4,
            ScanDirection::Right,
            ScanDirection::Down,
        )
        .expect("a geometry");
        let floor = [5e-12, 8e-12];
        let read = |v: f64, s: f64| {
            PassOffsetReading::of(&[parameter(v, s)], floor, &geometry).expect("a reading")
        };
        // Across the lines is y here: 25 pm over an 8 pm floor.
        let large = read(-25e-12, 2e-12);
        assert!(large.finding && (large.over_floor - 25.0 / 8.0).abs() < 1e-9);
        assert!(
            large
                .sentence()
                .expect("a sentence")
                .contains("-25.0 ± 2.0 pm")
        );
        assert!(!read(12e-12, 1e-12).finding, "1.5 floors");
        assert!(!read(20e-12, 9e-12).finding, "2.5 floors but within 3σ");
        assert!(PassOffsetReading::of(&[], floor, &geometry).is_none());
    }
}
