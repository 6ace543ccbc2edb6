//! The final model rendered forward and compared with the image, pixel by pixel (issue 17,
//! item 4): what the residual image shows that no feature position does.

use dhct_diagnose::{
    DiagnoseOptions, LINE_JITTER_EVIDENCE, LINE_TILT_EVIDENCE, PassResidual, diagnose, pair_views,
};
use dhct_distortion::PassInput;
use dhct_features::{FeatureOptions, FeatureSet, find_features_in_pair};
use dhct_scan::{ScanPair, ScanPass};
use dhct_simulate::{Simulation, SimulationConfig};

mod common;

/// The shared 512² graphite scan (`common::graphite_512`) with `extra` effects.
fn config(extra: &str) -> SimulationConfig {
    common::graphite_512("image-residual", 41, extra)
}

/// `pair` with a height signal `amplitude_m · sin(2π f t)` added at every pixel's
/// acquisition time (electrical pickup: no lateral motion at all).
fn with_height_signal(pair: ScanPair, hz: f64, amplitude_m: f64) -> ScanPair {
    let (geometry, trace, retrace) = pair.into_parts();
    let add = |pass: ScanPass, channel: Option<dhct_scan::ImageChannel>| {
        channel.map(|mut c| {
            let (times, _) = geometry.acquisition_time_maps(pass);
            c.z.zip_mut_with(&times, |z, t| {
                *z += amplitude_m * (2.0 * std::f64::consts::PI * hz * t + 0.4).sin()
            });
            c
        })
    };
    let trace = add(ScanPass::Trace, trace);
    let retrace = add(ScanPass::Retrace, retrace);
    ScanPair::from_parts(geometry, trace, retrace).unwrap()
}

/// `pair` with each line tilted along itself: a slope drawn per line (pseudo-random,
/// the same in trace and retrace), `rms_m` the rms rise from one end of a line to the other.
fn with_line_tilts(pair: ScanPair, rms_m: f64) -> ScanPair {
    let (geometry, trace, retrace) = pair.into_parts();
    let columns = geometry.columns() as f64;
    let mut state = 7u64;
    let slopes: Vec<f64> = (0..geometry.rows())
        .map(|_| {
            // Sum of four uniforms: near normal, unit variance.
            (0..4)
                .map(|_| {
                    state = state
                        .wrapping_mul(6364136223846793005)
                        .wrapping_add(1442695040888963407);
                    (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
                })
                .sum::<f64>()
                * 3f64.sqrt()
                * rms_m
                / columns
        })
        .collect();
    let tilt = |channel: Option<dhct_scan::ImageChannel>| {
        channel.map(|mut c| {
            for ((row, column), z) in c.z.indexed_iter_mut() {
                *z += slopes[row] * (column as f64 - 0.5 * columns);
            }
            c
        })
    };
    ScanPair::from_parts(geometry.clone(), tilt(trace), tilt(retrace)).unwrap()
}

/// The residual views of `pair` after the default diagnosis of its features, and the
/// verdict's words.
fn views(config: &SimulationConfig, pair: &ScanPair) -> (Vec<PassResidual>, String) {
    let lattice = config.surface.lattice.build().unwrap();
    let options = FeatureOptions {
        line_correction: dhct_features::LineCorrection::Lattice,
        ..FeatureOptions::for_neighbour_distance(lattice.nearest_neighbour_distance())
    };
    let sets = find_features_in_pair(pair, &options).unwrap();
    let inputs: Vec<PassInput> = sets
        .iter()
        .map(|s| PassInput {
            features: &s.features,
            mask: None,
        })
        .collect();
    let report = diagnose(
        &inputs,
        pair.geometry(),
        lattice.as_ref(),
        &DiagnoseOptions::default(),
    )
    .unwrap();
    let refs: Vec<&FeatureSet> = sets.iter().collect();
    let (report, images) = pair_views(report, pair, &refs, &options, None);
    assert_eq!(images.len(), 2);
    let shape = (pair.geometry().rows(), pair.geometry().columns());
    assert!(images.iter().all(|i| i.residual.dim() == shape));
    (report.image_residual, report.verdict_details.summary)
}

fn rendered(config: &SimulationConfig) -> ScanPair {
    Simulation::from_config(config).unwrap().run().unwrap().pair
}

/// A height signal of a third of the pixel noise at 430 Hz (electrical pickup: it moves
/// nothing) is found at its frequency and amplitude in both passes and named in the
/// verdict's words as what it is; the same scan without it shows no such signal and a
/// residual near the pixel noise everywhere. Lines tilted one by one show as line slopes
/// beyond the noise.
#[test]
fn a_height_signal_below_the_noise_is_found_in_the_image() {
    let clean = config("");
    let pair = rendered(&clean);
    let (quiet, _) = views(&clean, &pair);
    for p in &quiet {
        println!("clean {}", p.describe());
        assert!(p.rms_over_noise < 1.2, "{p:?}");
        assert!(
            p.by_fast_phase.iter().all(|b| b.is_some_and(|v| v < 1.3)),
            "{p:?}"
        );
        assert_eq!(p.excess_lines, 0, "{p:?}");
        assert!(!p.along_line.as_ref().unwrap().is_found(), "{p:?}");
        assert!(p.line_tilt_evidence.unwrap() < LINE_TILT_EVIDENCE, "{p:?}");
        assert!(
            p.line_shifts_over_noise.unwrap() < LINE_JITTER_EVIDENCE,
            "{p:?}"
        );
    }
    // Lines tilted one by one by 5 pm rms end to end (the size of the line offsets).
    let (tilted, _) = views(&clean, &with_line_tilts(pair.clone(), 5e-12));
    for p in &tilted {
        println!("tilted {}", p.describe());
        assert!(p.line_tilt_evidence.unwrap() > LINE_TILT_EVIDENCE, "{p:?}");
    }
    let (signal, summary) = views(&clean, &with_height_signal(pair, 430.0, 1e-12));
    for p in &signal {
        println!("430 Hz {}", p.describe());
        let peak = p.along_line.as_ref().unwrap();
        assert!(peak.is_found(), "{peak:?}");
        assert!((peak.frequency_hz / 430.0 - 1.0).abs() < 0.01, "{peak:?}");
        assert!((peak.amplitude / 1e-12 - 1.0).abs() < 0.15, "{peak:?}");
    }
    assert!(summary.contains("height signal"), "{summary}");
}

/// A 37 Hz lateral vibration moves the atoms, which modulates the lattice's own lines in
/// the residual: sidebands next to them, never a height signal at 37 Hz.
#[test]
fn a_lateral_vibration_is_not_called_a_height_signal() {
    let vibration = config(
        "[[effects]]\nkind = \"vibration\"\nfrequency_hz = 37.0\n\
         amplitude_m = [9.84e-12, 0.0]\nphase_rad = [0.3, 0.0]",
    );
    let (passes, _) = views(&vibration, &rendered(&vibration));
    for p in &passes {
        println!("{}", p.describe());
        assert!(!p.along_line.as_ref().unwrap().is_found(), "{p:?}");
    }
}

/// Every line moved along itself by its own offset, 4 pm rms (a third of a pixel; the
/// simulator's `line-jitter`): each line's residual against the model's gradient reads
/// the offsets, beyond what the pixel noise gives.
#[test]
fn line_jitter_shows_as_line_shifts_beyond_the_noise() {
    let jitter = config("[[effects]]\nkind = \"line-jitter\"\nrms_m = [4e-12, 0.0]\nseed = 5");
    let (passes, _) = views(&jitter, &rendered(&jitter));
    for p in &passes {
        println!("{}", p.describe());
        assert!(
            p.line_shifts_over_noise.unwrap() > LINE_JITTER_EVIDENCE,
            "{p:?}"
        );
        let rms = p.line_jitter_m.unwrap();
        assert!((rms / 4e-12 - 1.0).abs() < 0.3, "{rms:e}");
    }
}

/// A tip switching between two apexes 36 pm apart (telegraph noise, out of the library):
/// the lines where it switches depart from the rendered model far more than the rest, and
/// the windows listed lie at the switches.
#[test]
fn a_tip_switching_between_apexes_shows_as_lines_at_its_switches() {
    let tip = dhct_simulate::effects::TelegraphTip {
        jump_m: [3e-11, 2e-11],
        rate_hz: 0.05,
    };
    let telegraph = config(&format!(
        "[[effects]]\nkind = \"telegraph-tip\"\njump_m = [{:e}, {:e}]\nrate_hz = {}",
        tip.jump_m[0], tip.jump_m[1], tip.rate_hz
    ));
    let switches: Vec<f64> = (1..6200)
        .map(|i| f64::from(i) * 0.01)
        .filter(|t| tip.switched(*t) != tip.switched(t - 0.01))
        .collect();
    let (passes, _) = views(&telegraph, &rendered(&telegraph));
    let windows: Vec<_> = passes.iter().flat_map(|p| &p.excess_windows).collect();
    println!("switches {switches:?}");
    for p in &passes {
        println!("{}", p.describe());
    }
    assert!(windows.len() >= 3, "{windows:?}");
    for w in windows {
        let nearest = switches
            .iter()
            .map(|s| (s - 0.5 * (w.start_s + w.end_s)).abs())
            .fold(f64::INFINITY, f64::min);
        assert!(nearest < 1.0, "{w:?} is {nearest:.2} s from a switch");
    }
}
