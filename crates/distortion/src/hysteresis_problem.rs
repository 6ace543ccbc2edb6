//! The hysteresis fit as a least-squares problem: each feature's measured fast-axis scale
//! against the law's prediction (its secant over the neighbours' line times), with the
//! analytic Jacobian in the fit's parameters.
//!
//! Fit parameters: the quartic's `[c0 … c4]`, the power law's `[k, n]`, the exponential's
//! `[A, ln τ_h]` (see [`hysteresis_law`]).

use nalgebra::DMatrix;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::LocalDistortion;
use crate::model::HysteresisLaw;
use crate::secant::{secant, secant_offsets};
use dhct_numerics::lm::Residuals;

/// Which hysteresis law to fit.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum HysteresisChoice {
    /// No hysteresis (`S ≡ 1`).
    None,
    /// The paper's quartic in `τ/τ_s`; `τ_s` defaults to the line scan time.
    Quartic {
        /// `τ_s`, seconds; `None` = line scan time.
        time_scale_s: Option<f64>,
    },
    /// The Matlab power law `S = k·τ^n`.
    Power,
    /// `S = 1 + A·exp(−τ/τ_h)`.
    Exponential,
    /// The power law, the exponential and the quartic each fitted, the one with the lowest
    /// BIC kept (the power law unless another is lower by [`BIC_PREFERENCE`]): the
    /// scanner's law is not known in advance.
    Best,
}

/// How much lower (in BIC) another law must be to replace the power law under
/// [`HysteresisChoice::Best`] (10: "very strong" evidence on Kass & Raftery's scale).
pub const BIC_PREFERENCE: f64 = 10.0;

impl HysteresisChoice {
    /// The family to fit in place of [`HysteresisChoice::Best`]: the family of `law` (what
    /// a fit under `Best` chose), the power law when `law` is no hysteresis. Any other
    /// choice is itself.
    pub fn resolved(self, law: &HysteresisLaw) -> HysteresisChoice {
        match (self, law) {
            (HysteresisChoice::Best, HysteresisLaw::Quartic { time_scale_s, .. }) => {
                HysteresisChoice::Quartic {
                    time_scale_s: Some(*time_scale_s),
                }
            }
            (HysteresisChoice::Best, HysteresisLaw::Exponential { amplitude, .. })
                if *amplitude != 0.0 =>
            {
                HysteresisChoice::Exponential
            }
            (HysteresisChoice::Best, _) => HysteresisChoice::Power,
            (choice, _) => choice,
        }
    }
}

/// Residuals (and Jacobian rows) computed per chunk in parallel; each depends on its own
/// entry only, so the result does not depend on the thread count.
const CHUNK: usize = 1024;

/// The hysteresis fit's data, one entry per local distortion: line times `tau` (s), the
/// measured fast-axis scales `s` and the secant offsets to the neighbours (s; empty
/// without secants).
pub(crate) struct HysteresisData<'a> {
    pub(crate) tau: Vec<f64>,
    pub(crate) s: Vec<f64>,
    pub(crate) offsets: Vec<&'a [f64]>,
}

impl<'a> HysteresisData<'a> {
    pub(crate) fn new(local: &'a [LocalDistortion], secant_mode: bool) -> HysteresisData<'a> {
        let tau: Vec<f64> = local.iter().map(|l| l.line_time_s).collect();
        let s: Vec<f64> = local.iter().map(|l| l.scale).collect();
        let offsets = secant_offsets(local, secant_mode, |l| &l.neighbour_dtau_s);
        HysteresisData { tau, s, offsets }
    }

    /// Writes `law`'s predicted scale (its secant over the neighbours where there are
    /// offsets) minus the measured scale into `r`.
    pub(crate) fn residuals(&self, law: &HysteresisLaw, r: &mut [f64]) {
        r.par_chunks_mut(CHUNK).enumerate().for_each(|(c, chunk)| {
            for (k, out) in chunk.iter_mut().enumerate() {
                let i = c * CHUNK + k;
                let predicted = if self.offsets[i].is_empty() {
                    law.scale(self.tau[i])
                } else {
                    1.0 + secant(|x| law.excess_integral(x), self.tau[i], self.offsets[i])
                };
                *out = predicted - self.s[i];
            }
        });
    }

    /// Writes row `i` of the Jacobian (`∂ predicted scale / ∂p`) into `row`: the gradient of
    /// `S(τ)`, or the secant of the gradient of `I(τ)` over the neighbours.
    fn jacobian_row(&self, law: &HysteresisLaw, i: usize, row: &mut [f64]) {
        let (tau, offsets) = (self.tau[i], self.offsets[i]);
        if offsets.is_empty() {
            law_gradient(law, tau, Quantity::Scale, row);
            return;
        }
        let denominator: f64 = offsets.iter().map(|d| d * d).sum();
        let mut at = [0.0; MAX_PARAMETERS];
        let mut g0 = [0.0; MAX_PARAMETERS];
        let n = row.len();
        law_gradient(law, tau, Quantity::ExcessIntegral, &mut g0[..n]);
        row.iter_mut().for_each(|v| *v = 0.0);
        for d in offsets {
            law_gradient(law, tau + d, Quantity::ExcessIntegral, &mut at[..n]);
            for k in 0..n {
                row[k] += d * (at[k] - g0[k]);
            }
        }
        row.iter_mut().for_each(|v| *v /= denominator);
    }
}

/// The most fit parameters of a law (the quartic's five).
const MAX_PARAMETERS: usize = 5;

/// The hysteresis law of `choice` with the fitted parameters `p` (a quartic's time scale
/// defaults to `line_scan_time_s`; the exponential's `p[1]` is `ln τ_h`).
pub(crate) fn hysteresis_law(
    choice: HysteresisChoice,
    line_scan_time_s: f64,
    p: &[f64],
) -> HysteresisLaw {
    match choice {
        HysteresisChoice::None => HysteresisLaw::none(),
        HysteresisChoice::Quartic { time_scale_s } => HysteresisLaw::Quartic {
            coefficients: [p[0], p[1], p[2], p[3], p[4]],
            time_scale_s: time_scale_s.unwrap_or(line_scan_time_s),
        },
        // `Best` is resolved before a fit; the power law is its default family.
        HysteresisChoice::Power | HysteresisChoice::Best => {
            HysteresisLaw::Power { k: p[0], n: p[1] }
        }
        HysteresisChoice::Exponential => HysteresisLaw::Exponential {
            amplitude: p[0],
            time_constant_s: p[1].exp(),
        },
    }
}

/// The fit parameters of `law` under `choice` (the inverse of [`hysteresis_law`]); a law of
/// another family starts `choice` at no hysteresis.
pub(crate) fn law_parameters(
    choice: HysteresisChoice,
    law: &HysteresisLaw,
    line_scan_time_s: f64,
) -> Vec<f64> {
    match (choice, law) {
        (HysteresisChoice::None, _) => Vec::new(),
        (HysteresisChoice::Quartic { .. }, HysteresisLaw::Quartic { coefficients, .. }) => {
            coefficients.to_vec()
        }
        (HysteresisChoice::Quartic { .. }, _) => vec![0.0; 5],
        (HysteresisChoice::Power | HysteresisChoice::Best, &HysteresisLaw::Power { k, n }) => {
            vec![k, n]
        }
        (HysteresisChoice::Power | HysteresisChoice::Best, _) => vec![1.0, 0.0],
        (
            HysteresisChoice::Exponential,
            &HysteresisLaw::Exponential {
                amplitude,
                time_constant_s,
            },
        ) => vec![amplitude, time_constant_s.ln()],
        (HysteresisChoice::Exponential, _) => vec![0.0, (0.1 * line_scan_time_s).ln()],
    }
}

/// Which function of the law a gradient is of.
#[derive(Clone, Copy)]
pub(crate) enum Quantity {
    /// `S(τ)`.
    Scale,
    /// `I(τ) = ∫0^τ (S − 1)`, zero for `τ ≤ 0`.
    ExcessIntegral,
}

/// The gradient of `S(x)` or `I(x)` in the fit parameters of `law` (see the module docs),
/// written to `out` (one entry per parameter; none under [`HysteresisChoice::None`], whose
/// law has no fit parameters, whatever its form).
pub(crate) fn law_gradient(law: &HysteresisLaw, x: f64, quantity: Quantity, out: &mut [f64]) {
    if out.is_empty() {
        return;
    }
    if matches!(quantity, Quantity::ExcessIntegral) && x <= 0.0 {
        out.iter_mut().for_each(|v| *v = 0.0);
        return;
    }
    match (law, quantity) {
        (&HysteresisLaw::Quartic { time_scale_s, .. }, Quantity::Scale) => {
            let u = x / time_scale_s;
            // ∂S/∂c_k = u^k.
            let mut power = 1.0;
            for v in out.iter_mut() {
                *v = power;
                power *= u;
            }
        }
        (&HysteresisLaw::Quartic { time_scale_s, .. }, Quantity::ExcessIntegral) => {
            let u = x / time_scale_s;
            // ∂I/∂c_k = τ_s·u^(k+1)/(k+1).
            let mut power = u;
            for (k, v) in out.iter_mut().enumerate() {
                *v = time_scale_s * power / (k + 1) as f64;
                power *= u;
            }
        }
        (&HysteresisLaw::Power { k, n }, Quantity::Scale) => {
            // S = k·x^n.
            let x = x.max(0.0);
            let xn = x.powf(n);
            out[0] = xn;
            out[1] = k * xn * x.ln();
        }
        (&HysteresisLaw::Power { k, n }, Quantity::ExcessIntegral) => {
            // I = k·x^(n+1)/(n+1) − x.
            let m = n + 1.0;
            let xm = x.powf(m);
            out[0] = xm / m;
            out[1] = k * xm * (x.ln() / m - 1.0 / (m * m));
        }
        (
            &HysteresisLaw::Exponential {
                amplitude,
                time_constant_s,
            },
            quantity,
        ) => {
            let ratio = x / time_constant_s;
            let decay = (-ratio).exp();
            match quantity {
                // S = 1 + A·e^(−x/τ_h); ∂/∂ln τ_h = τ_h·∂/∂τ_h.
                Quantity::Scale => {
                    out[0] = decay;
                    out[1] = amplitude * decay * ratio;
                }
                // I = −A·τ_h·expm1(−x/τ_h).
                Quantity::ExcessIntegral => {
                    let expm1 = (-ratio).exp_m1();
                    out[0] = -time_constant_s * expm1;
                    out[1] = -amplitude * time_constant_s * (expm1 + ratio * decay);
                }
            }
        }
    }
}

/// The hysteresis fit: `data`'s residuals under the law of `choice` at the fit parameters,
/// with the analytic Jacobian.
pub(crate) struct HysteresisProblem<'a> {
    pub(crate) data: &'a HysteresisData<'a>,
    pub(crate) choice: HysteresisChoice,
    pub(crate) line_scan_time_s: f64,
}

impl Residuals for HysteresisProblem<'_> {
    fn residuals(&self, p: &[f64], r: &mut [f64]) {
        let law = hysteresis_law(self.choice, self.line_scan_time_s, p);
        self.data.residuals(&law, r);
    }

    fn jacobian(&self, p: &[f64], _r0: &[f64]) -> DMatrix<f64> {
        let law = hysteresis_law(self.choice, self.line_scan_time_s, p);
        let (m, n) = (self.data.tau.len(), p.len());
        let mut rows = vec![0.0; m * n];
        rows.par_chunks_mut(CHUNK * n)
            .enumerate()
            .for_each(|(c, chunk)| {
                for (k, row) in chunk.chunks_exact_mut(n).enumerate() {
                    self.data.jacobian_row(&law, c * CHUNK + k, row);
                }
            });
        DMatrix::from_row_slice(m, n, &rows)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use dhct_numerics::lm::forward_difference;

    /// The analytic Jacobian equals forward differences for every law, with and without
    /// secants, including entries whose neighbours reach before the line start.
    #[test]
    fn analytic_jacobian_matches_forward_differences() {
        let line = 0.02;
        let tau: Vec<f64> = (0..40).map(|i| 1e-4 + line * i as f64 / 40.0).collect();
        let s: Vec<f64> = tau
            .iter()
            .map(|t| 1.0 + 0.05 * (-t / 0.004).exp())
            .collect();
        let offsets_storage: Vec<Vec<f64>> = (0..40)
            .map(|i| vec![-6e-4, 6e-4, 3e-4 * (i % 3) as f64 - 2e-4])
            .collect();
        for with_secants in [false, true] {
            let data = HysteresisData {
                tau: tau.clone(),
                s: s.clone(),
                offsets: offsets_storage
                    .iter()
                    .map(|o| if with_secants { o.as_slice() } else { &[] })
                    .collect(),
            };
            for (choice, p) in [
                (
                    HysteresisChoice::Quartic { time_scale_s: None },
                    vec![0.02, -0.1, 0.3, -0.2, 0.05],
                ),
                (HysteresisChoice::Power, vec![0.9, -0.03]),
                (HysteresisChoice::Exponential, vec![0.05, (0.004f64).ln()]),
            ] {
                let problem = HysteresisProblem {
                    data: &data,
                    choice,
                    line_scan_time_s: line,
                };
                let mut r0 = vec![0.0; tau.len()];
                problem.residuals(&p, &mut r0);
                let analytic = problem.jacobian(&p, &r0);
                let numeric = forward_difference(&problem, &p, &r0);
                // Forward differences are good to about 1e-4 of each column's size.
                for (column_a, column_n) in analytic.column_iter().zip(numeric.column_iter()) {
                    let size = column_n.amax();
                    assert!(size > 0.0);
                    for (a, b) in column_a.iter().zip(column_n.iter()) {
                        assert!(
                            (a - b).abs() <= 1e-4 * size,
                            "{choice:?} secants {with_secants}: {a} vs {b} (column {size})"
                        );
                    }
                }
            }
        }
    }
}
