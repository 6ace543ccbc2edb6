//! The position-level model: a list of displacement terms (the simulator's own
//! [`Effect`]s, reused as model terms) plus the lattice the sample frame must match.
//!
//! For observation `i` (controller position `p_c`, metres, at frame time `t` and line time
//! `τ` of its pass) the residual is, in the **sample frame** (metres):
//!
//! `r_i = p_c + Σ_k d_k(t, τ, pass, p_c, z) − (o + D·R(θ)·X_i)`
//!
//! where `d_k` are the terms' displacements ([`Effect::displacement`], tip relative to
//! sample), `X_i` the feature's ideal lattice vector (from the integer indices of the lattice
//! fit), `o` the origin, `θ` the rotation and `D = diag(s_x, s_y)` the scales (fixed at the
//! lattice's nominal size unless asked otherwise: with a known lattice constant — the DHCT
//! internal standard — a free slow-axis scale is degenerate with the slow drift velocity).
//! To first order `r_i` equals the controller-frame gap `measured − predicted`.

use std::fmt::Debug;

use dhct_scan::ScanGeometry;
use dhct_simulate::{AcquisitionContext, Effect, EffectConfig};
use nalgebra::Vector2;

use crate::model::data::{Observation, whiten};

/// A displacement term of the model: the simulator's [`Effect`]s (wrapped by [`SimEffect`])
/// and the diagnosis's own extra terms ([`crate::model::terms`]).
pub(crate) trait ModelTerm: Send + Sync + Debug {
    /// Kind, e.g. `"tip-change"`.
    fn name(&self) -> &'static str;
    /// Tip displacement relative to the sample, metres (`p_sample = p_ctrl + d`).
    fn displacement(&self, at: &AcquisitionContext) -> Vector2<f64>;
    /// Parameter names (SI unit in the name).
    fn parameter_names(&self) -> Vec<&'static str>;
    /// Parameters, SI.
    fn parameters(&self) -> Vec<f64>;
    /// A copy with new parameters, `None` if they are invalid.
    fn with_parameters(&self, p: &[f64]) -> Option<Box<dyn ModelTerm>>;
    /// The simulator config entry, for terms that are simulator effects.
    fn config(&self) -> Option<EffectConfig>;
    /// How the fit varies each parameter ([`transform_of`] its name).
    fn transforms(&self) -> Vec<Transform> {
        self.parameter_names()
            .iter()
            .map(|n| transform_of(n))
            .collect()
    }
}

/// A simulator effect used as a model term.
#[derive(Debug)]
pub(crate) struct SimEffect(pub Box<dyn Effect>);

impl ModelTerm for SimEffect {
    fn name(&self) -> &'static str {
        self.0.name()
    }
    fn displacement(&self, at: &AcquisitionContext) -> Vector2<f64> {
        self.0.displacement(at)
    }
    fn parameter_names(&self) -> Vec<&'static str> {
        self.0.parameter_names()
    }
    fn parameters(&self) -> Vec<f64> {
        self.0.parameters()
    }
    fn with_parameters(&self, p: &[f64]) -> Option<Box<dyn ModelTerm>> {
        self.0
            .with_parameters(p)
            .ok()
            .map(|e| Box::new(SimEffect(e)) as Box<dyn ModelTerm>)
    }
    fn config(&self) -> Option<EffectConfig> {
        Some(self.0.config())
    }
}

/// Wraps a simulator effect config as a term.
pub(crate) fn sim_term(config: &EffectConfig) -> Option<Box<dyn ModelTerm>> {
    config
        .build("effect")
        .ok()
        .map(|e| Box::new(SimEffect(e)) as Box<dyn ModelTerm>)
}

/// How a parameter is varied by the fit (fit space `u` ↔ parameter `p`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Transform {
    /// `u = p`; `typical` sets the finite-difference step.
    Linear { typical: f64 },
    /// `u = ln p` for strictly positive parameters.
    Log,
}

impl Transform {
    /// Fit-space value of parameter `p`.
    pub fn fit_value_of(self, p: f64) -> f64 {
        match self {
            Transform::Linear { .. } => p,
            Transform::Log => p.max(1e-300).ln(),
        }
    }

    /// Parameter of fit-space value `u`.
    pub fn parameter_of(self, u: f64) -> f64 {
        match self {
            Transform::Linear { .. } => u,
            Transform::Log => u.exp(),
        }
    }

    /// `|dp/du|` at parameter `p` (turns a fit-space σ into the parameter's).
    pub fn slope(self, p: f64) -> f64 {
        match self {
            Transform::Linear { .. } => 1.0,
            Transform::Log => p.abs(),
        }
    }

    /// Finite-difference step in fit space at parameter `p`.
    pub fn step(self, p: f64) -> f64 {
        match self {
            Transform::Linear { typical } => 1e-5 * p.abs().max(typical),
            Transform::Log => 1e-5,
        }
    }
}

/// Transform of a parameter, from its (simulator) name.
pub(crate) fn transform_of(name: &str) -> Transform {
    let log = name.ends_with("t0_s")
        || name.ends_with("time_constant_s")
        || name == "k"
        || name.ends_with("_k")
        || name == "frequency_hz";
    if log {
        return Transform::Log;
    }
    let typical = if name.ends_with("_m_per_s2") {
        1e-15
    } else if name.ends_with("_m_per_s3") {
        1e-17
    } else if name.ends_with("_m_per_s") {
        1e-12
    } else if name.ends_with("_m") {
        1e-11
    } else if name.ends_with("_rad") {
        0.1
    } else if name.ends_with("start_s") || name == "time_s" {
        1.0
    } else {
        0.01
    };
    Transform::Linear { typical }
}

/// One displacement term: an effect and which of its parameters the fit may change.
#[derive(Debug)]
pub(crate) struct Term {
    pub effect: Box<dyn ModelTerm>,
    pub free: Vec<bool>,
    /// Short label for reports.
    pub label: String,
}

impl Clone for Term {
    fn clone(&self) -> Term {
        let effect = self
            .effect
            .with_parameters(&self.effect.parameters())
            .unwrap_or_else(|| unreachable!("a term's own parameters are valid"));
        Term {
            effect,
            free: self.free.clone(),
            label: self.label.clone(),
        }
    }
}

impl Term {
    pub fn new(effect: Box<dyn ModelTerm>, free: Vec<bool>, label: impl Into<String>) -> Term {
        Term {
            effect,
            free,
            label: label.into(),
        }
    }

    /// All parameters free.
    pub fn all_free(effect: Box<dyn ModelTerm>, label: impl Into<String>) -> Term {
        let n = effect.parameters().len();
        Term::new(effect, vec![true; n], label)
    }

    pub fn free_count(&self) -> usize {
        self.free.iter().filter(|f| **f).count()
    }
}

/// Lattice parameters of the model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct LatticeParams {
    /// `o`, metres.
    pub origin_m: [f64; 2],
    /// `θ`, radians.
    pub angle_rad: f64,
    /// `[s_x, s_y]`.
    pub scale: [f64; 2],
    /// Whether the scales are fitted.
    pub fit_scale: bool,
}

impl LatticeParams {
    pub fn count(&self) -> usize {
        if self.fit_scale { 5 } else { 3 }
    }

    /// `o + D·R(θ)·X`.
    pub fn site(&self, x: [f64; 2]) -> [f64; 2] {
        let (s, c) = self.angle_rad.sin_cos();
        [
            self.origin_m[0] + self.scale[0] * (c * x[0] - s * x[1]),
            self.origin_m[1] + self.scale[1] * (s * x[0] + c * x[1]),
        ]
    }

    /// `∂site/∂(o_x, o_y, θ[, s_x, s_y])`.
    pub fn derivatives(&self, x: [f64; 2]) -> Vec<[f64; 2]> {
        let (s, c) = self.angle_rad.sin_cos();
        let mut out = vec![
            [1.0, 0.0],
            [0.0, 1.0],
            [
                self.scale[0] * (-s * x[0] - c * x[1]),
                self.scale[1] * (c * x[0] - s * x[1]),
            ],
        ];
        if self.fit_scale {
            out.push([c * x[0] - s * x[1], 0.0]);
            out.push([0.0, s * x[0] + c * x[1]]);
        }
        out
    }
}

/// Terms + lattice.
#[derive(Debug, Clone)]
pub(crate) struct GlobalModel {
    pub terms: Vec<Term>,
    pub lattice: LatticeParams,
}

/// The acquisition context of an observation.
pub(crate) fn context<'a>(geometry: &'a ScanGeometry, o: &Observation) -> AcquisitionContext<'a> {
    AcquisitionContext {
        geometry,
        pass: o.pass,
        time_since_frame_start: o.time_s,
        time_since_line_start: o.line_time_s,
        controller: Vector2::new(o.controller_m[0], o.controller_m[1]),
        surface_height: o.terrace_height_m,
    }
}

/// Displacement of one effect at every observation, metres, as the residuals see it (each
/// observation's [`Observation::whitening`] applied).
pub(crate) fn term_displacements(
    effect: &dyn ModelTerm,
    geometry: &ScanGeometry,
    observations: &[Observation],
) -> Vec<[f64; 2]> {
    observations
        .iter()
        .map(|o| {
            let d = effect.displacement(&context(geometry, o));
            whiten(&o.whitening, [d.x, d.y])
        })
        .collect()
}

impl GlobalModel {
    /// Number of free parameters.
    pub fn free_count(&self) -> usize {
        self.terms.iter().map(Term::free_count).sum::<usize>() + self.lattice.count()
    }

    /// The free parameters in fit space (transformed).
    pub fn free_vector(&self) -> Vec<f64> {
        let mut u = Vec::new();
        for term in &self.terms {
            for ((p, t), free) in term
                .effect
                .parameters()
                .iter()
                .zip(term.effect.transforms())
                .zip(&term.free)
            {
                if *free {
                    u.push(t.fit_value_of(*p));
                }
            }
        }
        let l = &self.lattice;
        u.extend([l.origin_m[0], l.origin_m[1], l.angle_rad]);
        if l.fit_scale {
            u.extend(l.scale);
        }
        u
    }

    /// A copy with free parameters `u` (fit space); `None` if an effect rejects them.
    pub fn with_free_vector(&self, u: &[f64]) -> Option<GlobalModel> {
        if u.iter().any(|v| !v.is_finite()) {
            return None;
        }
        let mut k = 0;
        let mut terms = Vec::with_capacity(self.terms.len());
        for term in &self.terms {
            let mut p = term.effect.parameters();
            for (j, t) in term.effect.transforms().iter().enumerate() {
                if term.free[j] {
                    p[j] = t.parameter_of(u[k]);
                    k += 1;
                }
            }
            let effect = term.effect.with_parameters(&p)?;
            terms.push(Term {
                effect,
                free: term.free.clone(),
                label: term.label.clone(),
            });
        }
        let mut lattice = self.lattice;
        lattice.origin_m = [u[k], u[k + 1]];
        lattice.angle_rad = u[k + 2];
        if lattice.fit_scale {
            lattice.scale = [u[k + 3], u[k + 4]];
        }
        Some(GlobalModel { terms, lattice })
    }

    /// Unweighted residuals `[r_x, r_y]` (metres, sample frame) of every observation, each
    /// with its [`Observation::whitening`] applied.
    pub fn residuals(
        &self,
        geometry: &ScanGeometry,
        observations: &[Observation],
    ) -> Vec<[f64; 2]> {
        let mut r: Vec<[f64; 2]> = observations
            .iter()
            .map(|o| {
                let site = self.lattice.site(o.lattice_vector_m);
                let r = [o.controller_m[0] - site[0], o.controller_m[1] - site[1]];
                whiten(&o.whitening, r)
            })
            .collect();
        for term in &self.terms {
            for (ri, d) in r.iter_mut().zip(term_displacements(
                term.effect.as_ref(),
                geometry,
                observations,
            )) {
                ri[0] += d[0];
                ri[1] += d[1];
            }
        }
        r
    }
}
