//! Height noise: white, line offsets, spikes and 1/f, each with its configured size.

mod common;

use common::{base_config, run};
use dhct_scan::ScanDirection;
use dhct_simulate::SimulationConfig;

/// The base config with a flat sample (zero-height features), so the image is the noise.
fn flat() -> SimulationConfig {
    let mut config = base_config();
    config.surface.feature.height_m = 0.0;
    config
}

fn rms(values: impl Iterator<Item = f64>) -> f64 {
    let v: Vec<f64> = values.collect();
    let mean = v.iter().sum::<f64>() / v.len() as f64;
    (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / v.len() as f64).sqrt()
}

#[test]
fn white_noise_has_the_configured_rms() {
    let mut config = flat();
    config.noise.white_sigma_m = 5e-12;
    let output = run(&config);
    for (_, image) in output.pair.images() {
        let sigma = rms(image.z.iter().copied());
        assert!((sigma - 5e-12).abs() < 0.03 * 5e-12, "{sigma}");
    }
}

#[test]
fn line_offsets_are_constant_along_each_scan_line() {
    for (fast, slow) in [
        (ScanDirection::Right, ScanDirection::Down),
        (ScanDirection::Down, ScanDirection::Left),
    ] {
        let mut config = flat();
        config.scan.trace_fast = fast;
        config.scan.slow = slow;
        config.noise.line_offset_sigma_m = 10e-12;
        let output = run(&config);
        for (_, image) in output.pair.images() {
            let lines: Vec<Vec<f64>> = if fast == ScanDirection::Right {
                image.z.rows().into_iter().map(|r| r.to_vec()).collect()
            } else {
                image.z.columns().into_iter().map(|c| c.to_vec()).collect()
            };
            for line in &lines {
                assert!(line.iter().all(|&v| v == line[0]));
            }
            let sigma = rms(lines.iter().map(|l| l[0]));
            assert!((sigma - 10e-12).abs() < 0.25 * 10e-12, "{sigma}");
        }
        let trace = output.pair.trace().unwrap();
        let retrace = output.pair.retrace().unwrap();
        assert_ne!(trace.z, retrace.z, "each pass has its own offsets");
    }
}

#[test]
fn spikes_appear_at_the_configured_rate_and_size() {
    let mut config = flat();
    config.noise.spike_probability = 0.01;
    config.noise.spike_height_m = 50e-12;
    let output = run(&config);
    let spikes: Vec<f64> = output
        .pair
        .images()
        .flat_map(|(_, image)| {
            image
                .z
                .iter()
                .copied()
                .filter(|v| *v != 0.0)
                .collect::<Vec<_>>()
        })
        .collect();
    let pixels = 2.0 * 128.0 * 128.0;
    let expected = 0.01 * pixels;
    assert!((spikes.len() as f64 - expected).abs() < 4.0 * (expected * 0.99).sqrt());
    assert!(spikes.iter().all(|v| (25e-12..=75e-12).contains(&v.abs())));
    let positive = spikes.iter().filter(|v| **v > 0.0).count() as f64;
    assert!((positive / spikes.len() as f64 - 0.5).abs() < 0.1);
}

#[test]
fn pink_noise_has_more_power_at_low_frequencies() {
    let mut config = flat();
    config.noise.pink_sigma_m = 5e-12;
    let output = run(&config);
    let trace = output.pair.trace().unwrap();
    let sigma = rms(trace.z.iter().copied());
    assert!(sigma > 2e-12 && sigma < 8e-12, "{sigma}");
    // Mean periodogram of the 256 lines (trace + retrace rows).
    let n = 128;
    let mut power = vec![0.0; n / 2 + 1];
    for (_, image) in output.pair.images() {
        for row in image.z.rows() {
            let mean = row.sum() / n as f64;
            for (k, p) in power.iter_mut().enumerate() {
                let (mut re, mut im) = (0.0, 0.0);
                for (i, v) in row.iter().enumerate() {
                    let phase = std::f64::consts::TAU * (k * i) as f64 / n as f64;
                    re += (v - mean) * phase.cos();
                    im += (v - mean) * phase.sin();
                }
                *p += re * re + im * im;
            }
        }
    }
    let low: f64 = power[1..=4].iter().sum::<f64>() / 4.0;
    let high: f64 = power[48..=64].iter().sum::<f64>() / 17.0;
    assert!(low > 5.0 * high, "low {low:e} high {high:e}");
    // Correlated across lines too: the line means vary much more than white noise would.
    let line_means = rms(trace.z.rows().into_iter().map(|r| r.sum() / n as f64));
    assert!(line_means > 3.0 * sigma / (n as f64).sqrt(), "{line_means}");
}
