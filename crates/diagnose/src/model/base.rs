//! The base model chosen by the data: the fast-scan hysteresis law (none, the authors'
//! power law, the paper's quartic, a cubic, an exponential) and then, with that law, the
//! form of the creep from frame start (none, DHCT's logarithmic `C·ln(1 + t/t0)`, an
//! exponential relaxation `A·(1 − e^(−t/τ))`) are selected per image by the Bayesian
//! information criterion of the position-level fit, before any candidate effect is
//! screened. A law the base model cannot follow otherwise leaves a residual mirrored
//! between trace and retrace that the candidates then "explain"; a creep of another form
//! leaves a slow residual that they take for a creep event or higher-order drift.
//!
//! Each law starts from the DHCT fit's scale curve `S(τ)` (the law fitted to it over one
//! line, `τ` in seconds since line start), then the whole base model (drift, creep with its
//! `t0` profiled, the law, the lattice) is fitted to the feature positions. The criterion
//! is `BIC = n·ln(χ²/n) + k·ln n` with `n = 2N` coordinates and `k` free parameters
//! (Gaussian residuals of unknown variance: a floor that is somewhat off does not decide
//! the law).

use dhct_features::{FeatureSet, LineLevelling};
use dhct_scan::{HysteresisLaw, ScanGeometry, ScanPass};
use dhct_simulate::EffectConfig;
use dhct_simulate::effects::{ExponentialCreep, FastScanHysteresis};
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use crate::DiagnoseError;
use crate::model::data::Observation;
use crate::model::fit::{BASE_CREEP, Fitted, fit_profiled};
use crate::model::global::{GlobalModel, Term, sim_term};

/// A law with its free-parameter mask (`None`: no hysteresis term).
type LawStart = Option<(HysteresisLaw, Vec<bool>)>;

/// Label of the base model's hysteresis term.
pub(crate) const BASE_HYSTERESIS: &str = "fast-hysteresis";

/// One hysteresis law tried for the base model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LawScore {
    /// `none`, `power`, `quartic`, `cubic` or `exponential`.
    pub law: String,
    /// Free parameters of the whole base model with this law.
    pub parameters: usize,
    /// χ² of the position-level fit at the noise floor.
    pub chi2: f64,
    /// `n·ln(χ²/n) + k·ln n` (lower is better).
    pub bic: f64,
    /// BIC minus the chosen alternative's (0 for the chosen one; negative for one that
    /// fits better by less than the decisive difference).
    pub delta_bic: f64,
    /// Whether it is the base model's law.
    pub chosen: bool,
}

/// The data's choice of base model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BaseChoice {
    /// The chosen hysteresis law (`none`, `power`, …).
    pub hysteresis_law: String,
    /// Every law tried, best first (laws whose fit failed are left out).
    pub hysteresis: Vec<LawScore>,
    /// The chosen form of the creep from frame start (`none`, `log`, `exponential`).
    pub creep_form: String,
    /// Every creep form tried with the chosen law, best first (its `law` field names the
    /// form; forms whose fit failed are left out).
    pub creep: Vec<LawScore>,
    /// When the creep form the positions chose before any effect is not DHCT's log creep:
    /// the BIC of the whole model with that form (its base and the effects its selection
    /// named, each with the price it was accepted at) minus the whole model's with the log
    /// form (whose selection is run as well). An effect the base leaves unmodelled can make
    /// another form fit the base better; the log form is kept unless this is below
    /// `−6`.
    #[serde(default)]
    pub creep_form_whole_model_delta_bic: Option<f64>,
    /// When the base chose a polynomial law: its whole model (base and the effects its
    /// selection named) and each rigid law's that was followed through the selection, as
    /// BIC differences from the best (0). An effect the base leaves unmodelled can make a
    /// polynomial law fit the base better (it takes a piezo non-linearity's odd part); the
    /// law the base chose is kept unless another whole model is lower by more than 6, and
    /// then that law is named `hysteresis_law`. Empty when no other law was followed.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub hysteresis_whole_model: Vec<WholeModelScore>,
    /// How each image's scan lines were levelled before its features were fitted, on the
    /// evidence of its line levels (empty when the diagnosis was given positions, not
    /// images).
    #[serde(default)]
    pub line_levelling: Vec<PassLevelling>,
}

/// One alternative base's whole model against the chosen one's.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WholeModelScore {
    /// The alternative (a hysteresis law's name).
    pub law: String,
    /// Its whole model's BIC minus the chosen whole model's (negative = fits better).
    pub delta_bic: f64,
    /// The effects its selection named, in order.
    pub effects: Vec<String>,
}

impl BaseChoice {
    /// Names `law` the base model's hysteresis law (the whole models' comparison chose
    /// it), with the alternatives' BIC differences measured from it.
    pub(crate) fn choose_law(&mut self, law: &str) {
        self.hysteresis_law = law.into();
        let chosen = self
            .hysteresis
            .iter()
            .find(|c| c.law == law)
            .map(|c| c.delta_bic);
        for c in &mut self.hysteresis {
            c.chosen = c.law == law;
            c.delta_bic -= chosen.unwrap_or(0.0);
        }
    }

    /// Marks DHCT's log creep as the chosen form (the whole models' comparison kept it).
    pub(crate) fn keep_log_creep(&mut self) {
        self.creep_form = "log".into();
        let log = self
            .creep
            .iter()
            .find(|c| c.law == "log")
            .map(|c| c.delta_bic);
        for c in &mut self.creep {
            c.chosen = c.law == "log";
            c.delta_bic -= log.unwrap_or(0.0);
        }
    }
}

/// How one image's scan lines were levelled before its features were fitted.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PassLevelling {
    /// Trace or retrace.
    pub pass: ScanPass,
    /// The levelling and its evidence.
    #[serde(flatten)]
    pub levelling: LineLevelling,
}

impl PassLevelling {
    /// Each of `sets`' levelling.
    pub fn of_sets(sets: &[&FeatureSet]) -> Vec<PassLevelling> {
        sets.iter()
            .map(|s| PassLevelling {
                pass: s.pass,
                levelling: s.line_levelling.clone(),
            })
            .collect()
    }
}

/// Polynomial `S − 1 = Σ_{k<degree+1} c_k u^k` fitted to `curve` (`u`, `S`) by least squares.
fn polynomial(curve: &[(f64, f64)], degree: usize) -> [f64; 5] {
    let a = DMatrix::from_fn(curve.len(), degree + 1, |i, k| curve[i].0.powi(k as i32));
    let b = DVector::from_iterator(curve.len(), curve.iter().map(|(_, s)| s - 1.0));
    let mut out = [0.0; 5];
    if let Ok(x) = a.svd(true, true).solve(&b, 1e-12) {
        for (k, v) in x.iter().enumerate() {
            out[k] = if v.is_finite() { *v } else { 0.0 };
        }
    }
    out
}

/// `S = 1 + A·exp(−τ/τ_h)` fitted to `curve` (`τ`, `S`): `τ_h` on a log grid, `A` linear.
fn exponential(curve: &[(f64, f64)], line: f64) -> HysteresisLaw {
    let mut best = (f64::INFINITY, 1e-3, 0.1 * line);
    for k in 0..40 {
        let tau_h = line * 10f64.powf(-3.0 + 3.0 * k as f64 / 39.0);
        let e: Vec<f64> = curve.iter().map(|(t, _)| (-t / tau_h).exp()).collect();
        let ee: f64 = e.iter().map(|v| v * v).sum();
        let es: f64 = e.iter().zip(curve).map(|(v, (_, s))| v * (s - 1.0)).sum();
        let a = if ee > 0.0 { es / ee } else { 0.0 };
        let cost: f64 = e
            .iter()
            .zip(curve)
            .map(|(v, (_, s))| (s - 1.0 - a * v).powi(2))
            .sum();
        if cost < best.0 {
            best = (cost, a, tau_h);
        }
    }
    // A zero amplitude leaves τ_h without a gradient: start a little off it.
    let amplitude = if best.1.abs() > 1e-6 { best.1 } else { 1e-3 };
    HysteresisLaw::Exponential {
        amplitude,
        time_constant_s: best.2,
    }
}

/// `S = k·τ^n` fitted to `curve` (`τ`, `S > 0`) in logs.
fn power(curve: &[(f64, f64)]) -> HysteresisLaw {
    let pts: Vec<(f64, f64)> = curve
        .iter()
        .filter(|(t, s)| *t > 0.0 && *s > 0.0)
        .map(|(t, s)| (t.ln(), s.ln()))
        .collect();
    let n = pts.len() as f64;
    let (mx, my) = (
        pts.iter().map(|p| p.0).sum::<f64>() / n,
        pts.iter().map(|p| p.1).sum::<f64>() / n,
    );
    let sxx: f64 = pts.iter().map(|p| (p.0 - mx).powi(2)).sum();
    let sxy: f64 = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    let slope = if sxx > 0.0 { sxy / sxx } else { 0.0 };
    let (k, n) = ((my - slope * mx).exp(), slope.clamp(-0.9, 5.0));
    if k.is_finite() && k > 0.0 {
        HysteresisLaw::Power { k, n }
    } else {
        HysteresisLaw::Power { k: 1.0, n: 0.0 }
    }
}

/// The laws to try, each started from the DHCT fit's law `fitted`, with its free mask.
fn starts(fitted: &HysteresisLaw, line: f64) -> Vec<(&'static str, HysteresisLaw, Vec<bool>)> {
    let curve: Vec<(f64, f64)> = (1..=200)
        .map(|i| {
            let t = line * i as f64 / 200.0;
            (t, fitted.scale(t))
        })
        .collect();
    let unit: Vec<(f64, f64)> = curve.iter().map(|(t, s)| (t / line, *s)).collect();
    let quartic = |coefficients| HysteresisLaw::Quartic {
        coefficients,
        time_scale_s: line,
    };
    let power_start = match fitted {
        HysteresisLaw::Power { .. } => fitted.clone(),
        _ => power(&curve),
    };
    vec![
        ("power", power_start, vec![true; 2]),
        ("quartic", quartic(polynomial(&unit, 4)), vec![true; 5]),
        (
            "cubic",
            quartic(polynomial(&unit, 3)),
            vec![true, true, true, true, false],
        ),
        ("exponential", exponential(&curve, line), vec![true; 2]),
    ]
}

fn with_law(base: &GlobalModel, law: LawStart) -> Option<GlobalModel> {
    let mut model = base.clone();
    model.terms.retain(|t| t.label != BASE_HYSTERESIS);
    if let Some((law, free)) = law {
        let effect = sim_term(&EffectConfig::FastHysteresis(FastScanHysteresis { law }))?;
        model.terms.push(Term::new(effect, free, BASE_HYSTERESIS));
    }
    Some(model)
}

/// The base model with the creep from frame start in form `form` instead of DHCT's
/// logarithmic creep (term [`BASE_CREEP`], its `t0` or `τ` profiled by the fit): `none`
/// leaves it out, `exponential` starts at the log creep's displacement over the frame and
/// `τ = t0`.
fn with_creep_form(log: &GlobalModel, form: &str, frame_s: f64) -> Option<GlobalModel> {
    let mut model = log.clone();
    let slot = model.terms.iter().position(|t| t.label == BASE_CREEP)?;
    let term = model.terms.remove(slot);
    if form == "none" {
        return Some(model);
    }
    let [cx, cy, t0, _] = term.effect.parameters()[..] else {
        return None;
    };
    let reach = (1.0 + frame_s / t0).ln();
    let effect = sim_term(&EffectConfig::ExponentialCreep(ExponentialCreep {
        amplitude_m: [cx * reach, cy * reach],
        time_constant_s: t0,
        start_s: 0.0,
    }))?;
    model.terms.insert(
        slot,
        Term::new(effect, vec![true, true, false, false], BASE_CREEP),
    );
    Some(model)
}

/// A fitted alternative of the base model with its χ² and BIC.
struct Scored {
    name: &'static str,
    fitted: Fitted,
    chi2: f64,
    bic: f64,
}

/// χ² of `fitted`'s residuals at the noise floor `sigma` (metres per axis) and its
/// `BIC = n·ln(χ²/n) + k·ln n` (`n` coordinates, `k` free parameters).
pub(crate) fn chi2_and_bic(fitted: &Fitted, sigma: [f64; 2]) -> (f64, f64) {
    let n = (2 * fitted.residuals.len()) as f64;
    let chi2: f64 = fitted
        .residuals
        .iter()
        .map(|r| (r[0] / sigma[0]).powi(2) + (r[1] / sigma[1]).powi(2))
        .sum();
    let bic = n * (chi2.max(1e-300) / n).ln() + fitted.model.free_count() as f64 * n.ln();
    (chi2, bic)
}

impl Scored {
    /// `fitted` scored at the noise floor `sigma` (`None` if its BIC is not finite).
    fn of(name: &'static str, fitted: Fitted, sigma: [f64; 2]) -> Option<Scored> {
        let (chi2, bic) = chi2_and_bic(&fitted, sigma);
        bic.is_finite().then_some(Scored {
            name,
            fitted,
            chi2,
            bic,
        })
    }
}

/// BIC difference below which another alternative does not displace the preferred one
/// (6: "strong" evidence on Kass & Raftery's scale). DHCT's logarithmic creep and an
/// exponential relaxation of a creep that has not settled within the frame differ by
/// less than this on scans with either (ΔBIC 0.6–1.7 on `base_config` seeds 1–4).
pub(crate) const DECISIVE_BIC: f64 = 6.0;

/// The name of the chosen alternative among `scores`.
fn chosen_name(scores: &[LawScore]) -> String {
    scores
        .iter()
        .find(|s| s.chosen)
        .map_or_else(String::new, |s| s.law.clone())
}

/// The chosen alternative's fit, every alternative's score (lowest BIC first) and the
/// other alternatives' fits by name.
type Chosen = (Fitted, Vec<LawScore>, Vec<(&'static str, Fitted)>);

/// Fits every alternative (`None`: it could not be built; failed fits are left out) and
/// returns the chosen fit with every alternative's score, lowest BIC first, and the other
/// fits. The chosen one has the lowest BIC, unless `preferred` is within [`DECISIVE_BIC`]
/// of it. `what` names the alternatives in the error when none could be fitted.
fn best_by_bic(
    alternatives: Vec<(&'static str, Option<Result<Fitted, DiagnoseError>>)>,
    sigma: [f64; 2],
    what: &str,
    preferred: Option<&str>,
) -> Result<Chosen, DiagnoseError> {
    let mut results: Vec<Scored> = Vec::new();
    let mut last_error = None;
    for (name, fitted) in alternatives {
        match fitted {
            Some(Ok(f)) => results.extend(Scored::of(name, f, sigma)),
            Some(Err(e)) => last_error = Some(e),
            None => {}
        }
    }
    results.sort_by(|a, b| a.bic.total_cmp(&b.bic));
    let Some(best_bic) = results.first().map(|r| r.bic) else {
        return Err(last_error.unwrap_or(DiagnoseError::FitFailed {
            model: "base model".into(),
            reason: format!("no {what} could be fitted"),
        }));
    };
    let chosen = results
        .iter()
        .position(|r| Some(r.name) == preferred && r.bic - best_bic < DECISIVE_BIC)
        .unwrap_or(0);
    let chosen_bic = results[chosen].bic;
    let scores = results
        .iter()
        .enumerate()
        .map(|(k, r)| LawScore {
            law: r.name.to_string(),
            parameters: r.fitted.model.free_count(),
            chi2: r.chi2,
            bic: r.bic,
            delta_bic: r.bic - chosen_bic,
            chosen: k == chosen,
        })
        .collect();
    let best = results.remove(chosen).fitted;
    let others = results.into_iter().map(|r| (r.name, r.fitted)).collect();
    Ok((best, scores, others))
}

/// The base model the data chose before any effect, and what else was fitted.
pub(crate) struct ChosenBase {
    /// The fit with the chosen hysteresis law and creep form.
    pub best: Fitted,
    /// The choice with every alternative's score.
    pub choice: BaseChoice,
    /// The chosen law with DHCT's log creep, when another creep form was chosen.
    pub log_form: Option<Fitted>,
    /// Every other hysteresis law's fit (with DHCT's log creep), by name.
    pub other_laws: Vec<(&'static str, Fitted)>,
}

/// Fits the base model with every hysteresis law and keeps the best by BIC, then fits
/// that with every form of the creep from frame start and keeps the best of those;
/// returns that fit with the scores, the fit with DHCT's log creep if another form was
/// chosen, and the other laws' fits. `fitted` is the DHCT fit's law (its scale curve
/// seeds the others).
pub(crate) fn choose_base(
    base: &GlobalModel,
    fitted: &HysteresisLaw,
    geometry: &ScanGeometry,
    observations: &[Observation],
    sigma: [f64; 2],
    iterations: usize,
    t0_bounds: (f64, f64),
) -> Result<ChosenBase, DiagnoseError> {
    let fit_one =
        |m: GlobalModel| fit_profiled(m, geometry, observations, sigma, iterations, t0_bounds);
    let line = geometry.line_scan_time();
    let mut laws = vec![("none", with_law(base, None).map(fit_one))];
    laws.extend(
        starts(fitted, line)
            .into_iter()
            .map(|(name, law, free)| (name, with_law(base, Some((law, free))).map(fit_one))),
    );
    let (with_log, hysteresis, other_laws) = best_by_bic(laws, sigma, "hysteresis law", None)?;
    let hysteresis_law = chosen_name(&hysteresis);
    let frame = geometry.frame_duration();
    let other_form = |form: &str| with_creep_form(&with_log.model, form, frame).map(fit_one);
    let log_fit = with_log.clone();
    let forms = vec![
        ("none", other_form("none")),
        ("exponential", other_form("exponential")),
        ("log", Some(Ok(with_log))),
    ];
    let (best, creep, _) = best_by_bic(forms, sigma, "creep form", Some("log"))?;
    let log_form = (chosen_name(&creep) != "log").then_some(log_fit);
    Ok(ChosenBase {
        best,
        choice: BaseChoice {
            hysteresis_law,
            hysteresis,
            creep_form: chosen_name(&creep),
            creep,
            creep_form_whole_model_delta_bic: None,
            hysteresis_whole_model: Vec::new(),
            line_levelling: Vec::new(),
        },
        log_form,
        other_laws,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_start_follows_the_curve_it_was_fitted_to() {
        let line = 0.12;
        // A cubic in (1 − τ/T): exactly a cubic polynomial in u = τ/T.
        let truth = HysteresisLaw::Quartic {
            coefficients: [0.04, -0.12, 0.12, -0.04, 0.0],
            time_scale_s: line,
        };
        for (name, law, _) in starts(&truth, line) {
            let worst = (1..100)
                .map(|i| {
                    let t = line * i as f64 / 100.0;
                    (law.scale(t) - truth.scale(t)).abs()
                })
                .fold(0.0, f64::max);
            match name {
                "cubic" | "quartic" => assert!(worst < 1e-9, "{name}: {worst}"),
                // The others approximate it (the cubic starts at 4 %).
                _ => assert!(worst < 0.04, "{name}: {worst}"),
            }
        }
    }
}
