//! A validation case simulated: every lattice site's true controller position plus
//! localisation noise (the fast path, [`simulate_positions`]), or rendered images and the
//! feature finder (the full chain, [`simulate_images`], [`simulate_rendered`]).
//!
//! Vibration is simulated at 0.07–1.6 Hz (at least six cycles per frame); a faster one
//! moves the tip by more than a row pitch between consecutive line pairs (0.24 s apart
//! here), so the controller → sample map folds along the slow axis, the simulator's
//! feature location does not converge and features are lost (a limitation of the
//! continuous-time inversion, not of the diagnosis).

use dhct_diagnose::{DiagnoseError, DiagnoseOptions, DiagnosisReport};
use dhct_features::{Feature, FeatureOptions, FeatureSet, FitStatus, find_features_in_pair};
use dhct_scan::{ScanGeometry, ScanPair, ScanPass};
use dhct_simulate::raster::Displacer;
use dhct_simulate::surface::Terrace;
use dhct_simulate::truth::locate;
use dhct_simulate::{Effect, Simulation, SimulationConfig};
use nalgebra::Vector2;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

use crate::set::{NoiseForm, ScanForm};

/// A simulated pair of feature sets.
#[derive(Debug, Clone)]
pub struct SimulatedScan {
    /// The scan.
    pub geometry: ScanGeometry,
    /// Trace features (controller frame, with times).
    pub trace: Vec<Feature>,
    /// Retrace features.
    pub retrace: Vec<Feature>,
}

#[allow(clippy::too_many_arguments)]
fn feature(
    id: usize,
    pass: ScanPass,
    geometry: &ScanGeometry,
    x_px: f64,
    y_px: f64,
    sigma_m: f64,
    height: f64,
    z0: f64,
) -> Feature {
    let time = geometry.acquisition_time(pass, x_px, y_px);
    Feature {
        id,
        pass,
        x_px,
        y_px,
        x_m: x_px * geometry.pitch_x(),
        y_m: y_px * geometry.pitch_y(),
        x_sigma_px: sigma_m / geometry.pitch_x(),
        y_sigma_px: sigma_m / geometry.pitch_y(),
        sigma_major_px: 4.0,
        sigma_minor_px: 4.0,
        theta_rad: 0.0,
        amplitude: height.abs(),
        height,
        z0,
        removed_level: 0.0,
        residual_rms: 0.0,
        pixel_count: 100,
        ncc_peak: 1.0,
        status: FitStatus::Converged,
        fit_iterations: 1,
        time_s: time.since_frame_start,
        line_time_s: time.since_line_start,
    }
}

impl SimulatedScan {
    /// The diagnosis of this scan of `config` (its lattice) with `options`.
    pub fn diagnosed(
        &self,
        config: &SimulationConfig,
        options: &DiagnoseOptions,
    ) -> Result<DiagnosisReport, DiagnoseError> {
        let lattice = config.surface.lattice.build()?;
        dhct_diagnose::diagnose(&self.inputs(), &self.geometry, lattice.as_ref(), options)
    }

    /// Both passes as inputs of [`dhct_diagnose::diagnose`] (no masks).
    pub fn inputs(&self) -> [dhct_distortion::PassInput<'_>; 2] {
        [
            dhct_distortion::PassInput {
                features: &self.trace,
                mask: None,
            },
            dhct_distortion::PassInput {
                features: &self.retrace,
                mask: None,
            },
        ]
    }
}

/// Localisation noise of the position-only path, metres per axis: white, plus a part
/// correlated in time within each pass (an Ornstein–Uhlenbeck process in acquisition time:
/// image noise correlated over lines, 1/f noise, moves neighbouring features of one pass
/// alike; the two passes' image noise is independent). Every feature's reported
/// uncertainty is the total σ.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PositionNoise {
    /// σ of the independent part, metres.
    pub white_m: f64,
    /// σ of the part correlated in time, metres.
    pub correlated_m: f64,
    /// Its correlation time, seconds.
    pub correlation_time_s: f64,
}

impl PositionNoise {
    /// White noise of `sigma_m` only.
    pub fn white(sigma_m: f64) -> PositionNoise {
        PositionNoise {
            white_m: sigma_m,
            correlated_m: 0.0,
            correlation_time_s: 1.0,
        }
    }

    /// The noise of a set's scans with a total σ of `sigma_m`: white, or with
    /// [`NoiseForm::Correlated`] 36 % of the variance (1.2 pm of 2 pm) correlated over one
    /// second (about four lines pairs, a third of a row of features: the features of one
    /// row, acquired in the same lines, share it).
    pub fn of_form(scans: &ScanForm, sigma_m: f64) -> PositionNoise {
        match scans.position_noise {
            NoiseForm::Correlated => PositionNoise {
                white_m: 0.8 * sigma_m,
                correlated_m: 0.6 * sigma_m,
                correlation_time_s: 1.0,
            },
            NoiseForm::White => PositionNoise::white(sigma_m),
        }
    }

    /// The total σ, metres.
    pub fn total_m(&self) -> f64 {
        self.white_m.hypot(self.correlated_m)
    }
}

/// Feature positions only (fast path): true controller positions of every lattice site
/// plus Gaussian noise of `noise_m` (metres, per axis), drawn from `noise_seed`.
pub fn simulate_positions(
    config: &SimulationConfig,
    noise_m: f64,
    noise_seed: u64,
) -> Result<SimulatedScan, DiagnoseError> {
    simulate_positions_with(config, &PositionNoise::white(noise_m), noise_seed)
}

/// A lattice site as one pass acquires it: true controller position (pixels) and terrace
/// height (metres).
struct TrueSite {
    pass: ScanPass,
    x_px: f64,
    y_px: f64,
    z_m: f64,
}

/// [`simulate_positions`] with any [`PositionNoise`].
pub fn simulate_positions_with(
    config: &SimulationConfig,
    noise: &PositionNoise,
    noise_seed: u64,
) -> Result<SimulatedScan, DiagnoseError> {
    config.validate()?;
    let geometry = config.scan.geometry()?;
    let sites = true_sites(config, &geometry)?;
    // Drawn in the sites' order, trace and retrace interleaved (as before correlated noise
    // existed, so that white-noise sets keep their scans); the correlated part has its own
    // stream.
    let mut rng = ChaCha8Rng::seed_from_u64(noise_seed ^ 0xF00D);
    let mut correlated_rng = ChaCha8Rng::seed_from_u64(noise_seed ^ 0xC0AA_E1A7);
    let correlated = ScanPass::BOTH
        .map(|pass| correlated_noise(&sites, pass, &geometry, noise, &mut correlated_rng));
    let mut out = [Vec::new(), Vec::new()];
    for (i, site) in sites.iter().enumerate() {
        let k = usize::from(site.pass == ScanPass::Retrace);
        let c = correlated[k][i];
        let nx: f64 = StandardNormal.sample(&mut rng);
        let ny: f64 = StandardNormal.sample(&mut rng);
        let xp = site.x_px + (nx * noise.white_m + c[0]) / geometry.pitch_x();
        let yp = site.y_px + (ny * noise.white_m + c[1]) / geometry.pitch_y();
        let id = out[k].len();
        out[k].push(feature(
            id,
            site.pass,
            &geometry,
            xp,
            yp,
            noise.total_m(),
            config.surface.feature.height_m,
            site.z_m,
        ));
    }
    let [trace, retrace] = out;
    Ok(SimulatedScan {
        geometry,
        trace,
        retrace,
    })
}

/// The correlated part of the noise at the sites of `pass` (zero at the others'), metres
/// `[x, y]`: an Ornstein–Uhlenbeck process sampled at the sites' acquisition times.
fn correlated_noise(
    sites: &[TrueSite],
    pass: ScanPass,
    geometry: &ScanGeometry,
    noise: &PositionNoise,
    rng: &mut ChaCha8Rng,
) -> Vec<[f64; 2]> {
    let mut out = vec![[0.0; 2]; sites.len()];
    if noise.correlated_m <= 0.0 {
        return out;
    }
    let time = |s: &TrueSite| {
        geometry
            .acquisition_time(pass, s.x_px, s.y_px)
            .since_frame_start
    };
    let mut order: Vec<(f64, usize)> = sites
        .iter()
        .enumerate()
        .filter(|(_, s)| s.pass == pass)
        .map(|(i, s)| (time(s), i))
        .collect();
    order.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut state = [0.0; 2];
    let mut last: Option<f64> = None;
    for (t, i) in order {
        let rho = last.map_or(0.0, |l| (-(t - l) / noise.correlation_time_s).exp());
        let fresh = (1.0 - rho * rho).sqrt() * noise.correlated_m;
        for v in &mut state {
            let n: f64 = StandardNormal.sample(rng);
            *v = rho * *v + fresh * n;
        }
        out[i] = state;
        last = Some(t);
    }
    out
}

/// Every lattice site as each pass acquires it inside the image (4 px from its edges), in
/// lattice order, trace before retrace.
fn true_sites(
    config: &SimulationConfig,
    geometry: &ScanGeometry,
) -> Result<Vec<TrueSite>, DiagnoseError> {
    let lattice = config.surface.lattice.build()?;
    let effects: Vec<Box<dyn Effect>> = config
        .effects
        .iter()
        .enumerate()
        .map(|(k, e)| e.build(&format!("effects[{k}]")))
        .collect::<Result<_, _>>()?;
    let terrace = Terrace::new(&config.surface, config.tip.sigma_m);
    let displacer = Displacer::new(geometry, &effects, &terrace);
    let [a1, a2] = lattice.primitive_vectors();
    let (s, c) = config.surface.angle_rad.sin_cos();
    let rot = |v: Vector2<f64>| Vector2::new(c * v.x - s * v.y, s * v.x + c * v.y);
    let (r1, r2) = (rot(a1), rot(a2));
    let origin = Vector2::from(config.surface.origin_m);
    let (w, h) = (geometry.width(), geometry.height());
    let margin = 3.0 * lattice.nearest_neighbour_distance();
    let reach = ((w + h) / r1.norm().min(r2.norm())).ceil() as i64 + 2;
    let mut out = Vec::new();
    let border = 4.0;
    for n in -reach..=reach {
        for m in -reach..=reach {
            for site in 0..lattice.motif().len() {
                let p = origin + r1 * n as f64 + r2 * m as f64 + rot(lattice.site_position(site));
                if p.x < -margin || p.y < -margin || p.x > w + margin || p.y > h + margin {
                    continue;
                }
                let z_m = terrace.height(p);
                for pass in ScanPass::BOTH {
                    let a = locate(&displacer, pass, p);
                    let [x_px, y_px] = a.controller_position_px;
                    if a.converged
                        && x_px >= border
                        && y_px >= border
                        && x_px <= geometry.columns() as f64 - 1.0 - border
                        && y_px <= geometry.rows() as f64 - 1.0 - border
                    {
                        out.push(TrueSite {
                            pass,
                            x_px,
                            y_px,
                            z_m,
                        });
                    }
                }
            }
        }
    }
    Ok(out)
}

/// The full chain: rendered images, then feature finding with the pipeline's default line
/// levelling (`"lattice"`, as `PipelineOptions::for_lattice` sets it).
pub fn simulate_images(config: &SimulationConfig) -> Result<SimulatedScan, DiagnoseError> {
    let (pair, sets, _) = render_and_find(config)?;
    Ok(scan_of(&pair, sets))
}

/// A rendered scan: its images, its features and how they were found.
#[derive(Debug, Clone)]
pub struct RenderedScan {
    /// The rendered images.
    pub pair: ScanPair,
    /// The features of each image.
    pub sets: Vec<FeatureSet>,
    /// The options they were found with.
    pub options: FeatureOptions,
}

impl RenderedScan {
    /// The diagnosis of this scan of `config` with `options`, as `dhct diagnose` makes
    /// it: the feature positions, then what only the images show
    /// ([`dhct_diagnose::with_pair_views`]).
    pub fn diagnosed(
        &self,
        config: &SimulationConfig,
        options: &DiagnoseOptions,
    ) -> Result<DiagnosisReport, DiagnoseError> {
        let report = scan_of(&self.pair, self.sets.clone()).diagnosed(config, options)?;
        let sets: Vec<&FeatureSet> = self.sets.iter().collect();
        Ok(dhct_diagnose::with_pair_views(
            report,
            &self.pair,
            &sets,
            &self.options,
            None,
        ))
    }
}

/// [`simulate_images`], keeping the images, so that a validation sees what `dhct
/// diagnose` reports ([`RenderedScan::diagnosed`]).
pub fn simulate_rendered(config: &SimulationConfig) -> Result<RenderedScan, DiagnoseError> {
    let (pair, sets, options) = render_and_find(config)?;
    Ok(RenderedScan {
        pair,
        sets,
        options,
    })
}

/// Renders `config`'s images and finds their features.
fn render_and_find(
    config: &SimulationConfig,
) -> Result<(ScanPair, Vec<FeatureSet>, FeatureOptions), DiagnoseError> {
    let output = Simulation::from_config(config)?.run()?;
    let lattice = config.surface.lattice.build()?;
    let options = FeatureOptions {
        line_correction: dhct_features::LineCorrection::Lattice,
        ..FeatureOptions::for_neighbour_distance(lattice.nearest_neighbour_distance())
    };
    let sets = find_features_in_pair(&output.pair, &options)?;
    Ok((output.pair, sets, options))
}

/// The pair's features as a [`SimulatedScan`].
fn scan_of(pair: &ScanPair, sets: Vec<FeatureSet>) -> SimulatedScan {
    let mut trace = Vec::new();
    let mut retrace = Vec::new();
    for set in sets {
        match set.pass {
            ScanPass::Trace => trace = set.features,
            ScanPass::Retrace => retrace = set.features,
        }
    }
    SimulatedScan {
        geometry: pair.geometry().clone(),
        trace,
        retrace,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{ValidationCase, ValidationSet};

    /// Noise of each trace feature (noisy minus noise-free position, metres along x), in
    /// acquisition order.
    fn trace_noise_x(noise: &PositionNoise) -> Vec<f64> {
        let tuned = ValidationSet::named("tuned").expect("shipped");
        let case = ValidationCase::effect_free(7, &tuned);
        let exact = simulate_positions(&case.config, 0.0, 7).expect("simulates");
        let noisy = simulate_positions_with(&case.config, noise, 7).expect("simulates");
        let pitch = exact.geometry.pitch_x();
        let mut pairs: Vec<(f64, f64)> = exact
            .trace
            .iter()
            .zip(&noisy.trace)
            .map(|(a, b)| (a.time_s, (b.x_px - a.x_px) * pitch))
            .collect();
        pairs.sort_by(|a, b| a.0.total_cmp(&b.0));
        pairs.into_iter().map(|p| p.1).collect()
    }

    /// Mean square of the noise, and of the difference between features acquired one after
    /// the other.
    fn spreads(d: &[f64]) -> (f64, f64) {
        let ms = d.iter().map(|v| v * v).sum::<f64>() / d.len() as f64;
        let diff = d.windows(2).map(|w| (w[1] - w[0]).powi(2)).sum::<f64>() / (d.len() - 1) as f64;
        (ms, diff)
    }

    #[test]
    fn correlated_position_noise_is_shared_by_features_acquired_together() {
        let sigma = 2e-12;
        let (ms, diff) = spreads(&trace_noise_x(&PositionNoise::white(sigma)));
        // White: successive differences carry twice the variance.
        assert!((ms / (sigma * sigma) - 1.0).abs() < 0.15, "{ms:e}");
        assert!((diff / ms - 2.0).abs() < 0.3, "{}", diff / ms);
        let foreign = ValidationSet::named("foreign-2").expect("shipped");
        let noise = PositionNoise::of_form(&foreign.scans, sigma);
        assert!((noise.total_m() - sigma).abs() < 1e-18);
        let (ms, diff) = spreads(&trace_noise_x(&noise));
        assert!((ms / (sigma * sigma) - 1.0).abs() < 0.25, "{ms:e}");
        // Correlated: the shared part (36 % of the variance) cancels in the differences of
        // features acquired within a fraction of the correlation time.
        assert!(diff / ms < 1.5, "{}", diff / ms);
    }
}
