//! The verdict: does a gap remain between the fitted model and the data, did named
//! effects close it, and where does what remains lie.
//!
//! Gaps are RMS residuals in units of the noise floor (`√(χ²/2N)`, 1 = at the floor); the
//! threshold is [`GAP_THRESHOLD`] (1.2 × the floor).
//!
//! * `no_gap`: the base model is within the threshold (effects that were still found
//!   significant below it are listed as `below_floor`, never as `effects` or `added`).
//! * `explained`: named effects bring a gap above the threshold to within it.
//! * `partly_explained`: named effects remove at least [`PARTLY_FRACTION`] of the excess
//!   `gap² − 1` but a gap above the threshold remains.
//! * `unexplained`: nothing in the library removes that much; a gap above the threshold
//!   remains.

use serde::{Deserialize, Serialize};

use crate::evidence::location::{Bin, GapLocation};
use crate::evidence::noise::FloorSource;
use crate::report::gap::AddedEffect;
use crate::search::candidates::Candidate;

/// A gap at most this many times the noise floor counts as closed.
pub const GAP_THRESHOLD: f64 = 1.2;

/// Share of the excess `gap² − 1` the named effects must remove for `partly_explained`.
pub const PARTLY_FRACTION: f64 = 0.25;

/// Bins whose excess over the floor is at least this significant (`excess_z`) are places.
const PLACE_Z: f64 = 3.0;

/// The four verdicts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum VerdictKind {
    /// The base model explains the data to the floor.
    NoGap,
    /// Named effects bring the gap to within the threshold.
    Explained,
    /// Named effects explain part of the gap; a located remainder is left.
    PartlyExplained,
    /// A gap remains that nothing in the library explains.
    Unexplained,
}

impl VerdictKind {
    /// The JSON name (`no_gap`, …).
    pub fn name(self) -> &'static str {
        match self {
            VerdictKind::NoGap => "no_gap",
            VerdictKind::Explained => "explained",
            VerdictKind::PartlyExplained => "partly_explained",
            VerdictKind::Unexplained => "unexplained",
        }
    }
}

/// Which view of the residuals a place comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PlaceKind {
    /// A window of frame time (slow axis), seconds.
    TimeWindow,
    /// A range of the fast-line phase τ/T (0 = line start, 1 = line end).
    FastPhase,
    /// A region of the image (cells of a 6 × 6 map).
    Region,
    /// Trace or retrace.
    Pass,
    /// A quintile of apparent feature height.
    Height,
}

/// Where (part of) the remaining gap lies.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GapPlace {
    /// Which view.
    pub kind: PlaceKind,
    /// What it holds, e.g. `"t 12.0–18.0 s"`, `"τ/T 0.00–0.08"`, `"x 2/6, y 4/6"`, `"retrace"`.
    pub label: String,
    /// Features in it.
    pub count: usize,
    /// RMS residual there in units of the floor.
    pub gap_to_noise: f64,
    /// Share of the whole excess χ² (over the floor) that lies there, 0–1.
    pub share: f64,
}

/// The verdict with its numbers.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Verdict {
    /// Which verdict.
    pub kind: VerdictKind,
    /// Gap of the base model, units of the floor.
    pub gap_before: f64,
    /// Gap with the named effects, units of the floor.
    pub gap_after: f64,
    /// The threshold, units of the floor.
    pub threshold: f64,
    /// Share of the excess `gap² − 1` the named effects removed (0 when there was none).
    pub explained_fraction: f64,
    /// The named effects, in the order they were added (none when the verdict is
    /// `no_gap`).
    pub effects: Vec<Candidate>,
    /// With a gap within the floor (`no_gap`, or `unexplained` lowered from it by a pass
    /// offset: [`crate::PassOffsetReading`]): effects still found significant,
    /// whose model stays within the noise floor either way. Not findings: the positions do
    /// not need them.
    #[serde(default)]
    pub below_floor: Vec<Candidate>,
    /// Where the remaining gap lies (after the named effects), largest share first.
    pub remaining: Vec<GapPlace>,
    /// Whether the floor is independent of the residuals (false: it is their own spread,
    /// and the gap cannot be measured).
    pub floor_independent: bool,
    /// The verdict in plain words.
    pub summary: String,
}

fn place(kind: PlaceKind, b: &Bin, total_excess: f64) -> GapPlace {
    let excess = ((b.chi2_per_dof - 1.0) * b.count as f64).max(0.0);
    let label = match kind {
        PlaceKind::TimeWindow => b.label.replace("t/s ", "t ") + " s",
        _ => b.label.clone(),
    };
    GapPlace {
        kind,
        label,
        count: b.count,
        gap_to_noise: b.chi2_per_dof.max(0.0).sqrt(),
        share: if total_excess > 0.0 {
            (excess / total_excess).min(1.0)
        } else {
            0.0
        },
    }
}

/// The places with a significant excess, largest share first (at most six).
fn places(location: &GapLocation, total_excess: f64) -> Vec<GapPlace> {
    let views: [(PlaceKind, &[Bin]); 5] = [
        (PlaceKind::TimeWindow, &location.by_frame_time),
        (PlaceKind::FastPhase, &location.by_fast_phase),
        (PlaceKind::Region, &location.by_position),
        (PlaceKind::Pass, &location.by_pass),
        (PlaceKind::Height, &location.by_height),
    ];
    let mut out: Vec<GapPlace> = views
        .iter()
        .flat_map(|(kind, bins)| {
            bins.iter()
                .filter(|b| b.excess_z > PLACE_Z && b.count > 0)
                .map(|b| place(*kind, b, total_excess))
        })
        .collect();
    out.sort_by(|a, b| b.share.total_cmp(&a.share));
    out.truncate(6);
    out
}

/// Decides the verdict from the base and final gaps (units of the floor), the named
/// effects and the location of the final residuals (`n` features used).
pub(crate) fn decide(
    gap_before: f64,
    gap_after: f64,
    effects: Vec<Candidate>,
    final_location: Option<&GapLocation>,
    n: usize,
    source: FloorSource,
) -> Verdict {
    let excess = |g: f64| (g * g - 1.0).max(0.0);
    let explained_fraction = if excess(gap_before) > 0.0 {
        (1.0 - excess(gap_after) / excess(gap_before)).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let kind = if gap_before <= GAP_THRESHOLD {
        VerdictKind::NoGap
    } else if gap_after <= GAP_THRESHOLD && !effects.is_empty() {
        VerdictKind::Explained
    } else if !effects.is_empty() && explained_fraction >= PARTLY_FRACTION {
        VerdictKind::PartlyExplained
    } else {
        VerdictKind::Unexplained
    };
    // Excess χ² per degree of freedom × features: comparable with a bin's
    // `(χ²/dof − 1) · count`.
    // A gap within the floor needs no effect: what was still significant is kept apart.
    let (effects, below_floor) = if kind == VerdictKind::NoGap {
        (Vec::new(), effects)
    } else {
        (effects, Vec::new())
    };
    let total_excess = excess(gap_after) * n as f64;
    let remaining = match (kind, final_location) {
        (VerdictKind::PartlyExplained | VerdictKind::Unexplained, Some(l)) => {
            places(l, total_excess)
        }
        _ => Vec::new(),
    };
    let mut verdict = Verdict {
        kind,
        gap_before,
        gap_after,
        threshold: GAP_THRESHOLD,
        explained_fraction,
        effects,
        below_floor,
        remaining,
        floor_independent: source != FloorSource::ResidualSpread,
        summary: String::new(),
    };
    verdict.summary = words(&verdict);
    verdict
}

impl Verdict {
    /// Adds to the summary, for each effect in `added` that others explain about as well
    /// (its `about_as_good`), that the data do not tell them apart.
    pub(crate) fn note_near_ties(&mut self, added: &[AddedEffect]) {
        for a in added.iter().filter(|a| !a.about_as_good.is_empty()) {
            let others: Vec<&str> = a.about_as_good.iter().map(|c| c.name()).collect();
            self.summary.push_str(&format!(
                " {} explains the positions about as well as {} (χ² reduction within \
                 {:.0} %): the data do not tell them apart.",
                others.join(" or "),
                a.candidate,
                100.0 * crate::report::gap::NEAR_TIE_FRACTION
            ));
        }
    }
}

/// Candidate names joined by commas.
pub(crate) fn names(effects: &[Candidate]) -> String {
    effects
        .iter()
        .map(|c| c.to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

/// The verdict in plain words.
fn words(v: &Verdict) -> String {
    let mut s = match v.kind {
        VerdictKind::NoGap if v.below_floor.is_empty() => format!(
            "No gap: the base model (drift, creep, hysteresis) explains the feature positions \
             to the noise floor ({:.2} × floor; threshold {:.1}).",
            v.gap_before, v.threshold
        ),
        VerdictKind::NoGap => format!(
            "No gap: the base model explains the feature positions to the noise floor ({:.2} × \
             floor; threshold {:.1}); below the floor, not a finding: {} is significant but \
             changes the gap only to {:.2} × floor.",
            v.gap_before,
            v.threshold,
            names(&v.below_floor),
            v.gap_after
        ),
        VerdictKind::Explained => format!(
            "Explained: {} brings the gap from {:.2} to {:.2} × the noise floor.",
            names(&v.effects),
            v.gap_before,
            v.gap_after
        ),
        VerdictKind::PartlyExplained => format!(
            "Partly explained: {} brings the gap from {:.2} to {:.2} × the noise floor ({:.0} % \
             of the excess); the rest is not explained by any effect in the library.",
            names(&v.effects),
            v.gap_before,
            v.gap_after,
            100.0 * v.explained_fraction
        ),
        VerdictKind::Unexplained => format!(
            "Unexplained: a gap of {:.2} × the noise floor remains ({:.2} with {}) that no \
             effect in the library explains.",
            v.gap_before,
            v.gap_after,
            if v.effects.is_empty() {
                "nothing added".to_string()
            } else {
                names(&v.effects)
            }
        ),
    };
    if !v.remaining.is_empty() {
        let list: Vec<String> = v
            .remaining
            .iter()
            .map(|p| {
                format!(
                    "{} ({:.2} × floor, {:.0} % of the excess)",
                    p.label,
                    p.gap_to_noise,
                    100.0 * p.share
                )
            })
            .collect();
        s.push_str(&format!(" It lies in: {}.", list.join("; ")));
    }
    if !v.floor_independent {
        s.push_str(
            " No independent noise floor could be estimated (the residuals' own spread is \
             used), so the gap is not measured.",
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn v(before: f64, after: f64, effects: Vec<Candidate>) -> Verdict {
        decide(before, after, effects, None, 500, FloorSource::Localisation)
    }

    #[test]
    fn verdicts_follow_the_gap_and_the_effects() {
        assert_eq!(v(1.05, 1.05, vec![]).kind, VerdictKind::NoGap);
        assert_eq!(
            v(3.0, 1.1, vec![Candidate::TipChange]).kind,
            VerdictKind::Explained
        );
        // 3² − 1 = 8 → 2² − 1 = 3: 62 % of the excess removed.
        let partly = v(3.0, 2.0, vec![Candidate::TipChange]);
        assert_eq!(partly.kind, VerdictKind::PartlyExplained);
        assert!((partly.explained_fraction - 0.625).abs() < 1e-12);
        // 4² − 1 = 15 → 3.9² − 1 = 14.2: 5 %.
        assert_eq!(
            v(4.0, 3.9, vec![Candidate::Vibration]).kind,
            VerdictKind::Unexplained
        );
        let none = v(2.0, 2.0, vec![]);
        assert_eq!(none.kind, VerdictKind::Unexplained);
        assert!(!none.summary.contains("no unmodelled effect needed"));
        assert!(none.summary.starts_with("Unexplained"));
    }

    #[test]
    fn effects_significant_below_the_floor_are_not_listed_as_effects() {
        let verdict = v(1.17, 1.02, vec![Candidate::Vibration]);
        assert_eq!(verdict.kind, VerdictKind::NoGap);
        assert!(verdict.effects.is_empty());
        assert_eq!(verdict.below_floor, [Candidate::Vibration]);
        assert!(
            verdict.summary.contains("not a finding"),
            "{}",
            verdict.summary
        );
        let explained = v(3.0, 1.1, vec![Candidate::TipChange]);
        assert!(explained.below_floor.is_empty());
    }

    #[test]
    fn a_floor_that_is_the_residual_spread_says_so() {
        let verdict = decide(1.0, 1.0, vec![], None, 100, FloorSource::ResidualSpread);
        assert!(!verdict.floor_independent);
        assert!(verdict.summary.contains("not measured"));
    }
}
