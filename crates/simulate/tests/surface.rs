//! The sample model: vacancies, adatoms, step edges, a rotated second domain, strain,
//! molecule lobes and tip broadening.

mod common;

use common::{A, PITCH, base_config, cell, peaks, run};
use dhct_simulate::surface::FeatureKind;
use dhct_simulate::{LatticeConfig, Lobe, Region, SecondDomain, StepEdge, StrainRegion};

fn lattice_sites(output: &dhct_simulate::SimulationOutput) -> usize {
    output
        .truth
        .features
        .iter()
        .filter(|f| matches!(f.kind, FeatureKind::LatticeSite { .. }))
        .count()
}

#[test]
fn random_vacancies_remove_the_requested_fraction() {
    let full = lattice_sites(&run(&base_config()));
    let mut config = base_config();
    config.surface.defects.vacancy_fraction = 0.25;
    let output = run(&config);
    let left = lattice_sites(&output) as f64;
    let expected = 0.75 * full as f64;
    let sigma = (full as f64 * 0.25 * 0.75).sqrt();
    assert!((left - expected).abs() < 4.0 * sigma, "{left} of {full}");
    // The pattern depends on the seed only, not on the effects (scanned area).
    config
        .effects
        .push(dhct_simulate::EffectConfig::ThermalDrift(
            dhct_simulate::effects::ThermalDrift {
                velocity_m_per_s: [0.0, 1e-12],
                acceleration_m_per_s2: [0.0, 0.0],
            },
        ));
    let drifted = run(&config);
    let cells = |o: &dhct_simulate::SimulationOutput| {
        let mut c: Vec<_> = o.truth.features.iter().filter_map(cell).collect();
        c.sort();
        c
    };
    let (a, b) = (cells(&output), cells(&drifted));
    let common_cells = a.iter().filter(|c| b.binary_search(c).is_ok()).count();
    assert!(common_cells as f64 > 0.95 * a.len().min(b.len()) as f64);
}

#[test]
fn listed_vacancies_remove_the_nearest_site() {
    let mut config = base_config();
    // The site at cell (3, 4): origin 0.25 nm + (3, 4)·0.5 nm, probed 0.1 nm off.
    let site = [0.25e-9 + 3.0 * A, 0.25e-9 + 4.0 * A];
    config.surface.defects.vacancy_positions_m = vec![[site[0] + 0.1e-9, site[1] - 0.05e-9]];
    let full = run(&base_config());
    let output = run(&config);
    assert_eq!(lattice_sites(&output) + 1, lattice_sites(&full));
    assert!(
        output
            .truth
            .features
            .iter()
            .all(|f| cell(f) != Some((3, 4)))
    );
    let z = &output.pair.trace().unwrap().z;
    let (col, row) = (
        (site[0] / PITCH).round() as usize,
        (site[1] / PITCH).round() as usize,
    );
    assert!(
        z[[row, col]] < 1e-14,
        "vacancy still bright: {}",
        z[[row, col]]
    );
    assert!(full.pair.trace().unwrap().z[[row, col]] > 40e-12);
}

#[test]
fn adatoms_are_added_bright() {
    let mut config = base_config();
    config.surface.defects.adatom_count = 5;
    config.surface.defects.adatom_positions_m = vec![[3.0e-9, 3.0e-9]];
    config.surface.defects.adatom_relative_height = 2.0;
    let output = run(&config);
    let adatoms: Vec<_> = output
        .truth
        .features
        .iter()
        .filter(|f| matches!(f.kind, FeatureKind::Adatom { .. }))
        .collect();
    assert_eq!(adatoms.len(), 6);
    assert!(adatoms.iter().all(|f| f.amplitude_m == 100e-12));
    let z = &output.pair.trace().unwrap().z;
    assert!(z[[60, 60]] > 95e-12, "{}", z[[60, 60]]);
}

#[test]
fn a_step_edge_raises_its_terrace_by_its_height() {
    let mut config = base_config();
    let height = 0.335e-9;
    config.surface.steps.push(StepEdge {
        region: Region::HalfPlane {
            point_m: [3.2e-9, 0.0],
            normal: [1.0, 0.2],
        },
        height_m: height,
    });
    config.tip.sigma_m = 30e-12;
    let output = run(&config);
    let z = &output.pair.trace().unwrap().z;
    // Between atoms (cell corners at odd multiples of 5 px + 5) the surface is flat.
    let low = z[[10, 10]];
    let high = z[[10, 120]];
    assert!((high - low - height).abs() < 1e-15, "{low} {high}");
    // Features keep their height; the terrace carries them.
    assert!(
        output
            .truth
            .features
            .iter()
            .all(|f| f.amplitude_m == 50e-12)
    );
}

#[test]
fn a_second_domain_is_rotated_inside_its_region() {
    let mut config = base_config();
    config.surface.lattice = LatticeConfig::Hexagonal { a_m: A };
    let angle = 0.3;
    config.surface.second_domain = Some(SecondDomain {
        region: Region::Circle {
            centre_m: [3.2e-9, 3.2e-9],
            radius_m: 2.0e-9,
        },
        angle_rad: angle,
        origin_m: [3.2e-9, 3.2e-9],
    });
    let output = run(&config);
    let second: Vec<_> = output
        .truth
        .features
        .iter()
        .filter(|f| matches!(f.kind, FeatureKind::LatticeSite { domain: 1, .. }))
        .collect();
    let first: Vec<_> = output
        .truth
        .features
        .iter()
        .filter(|f| matches!(f.kind, FeatureKind::LatticeSite { domain: 0, .. }))
        .collect();
    assert!(second.len() > 40, "{}", second.len());
    let centre = [3.2e-9, 3.2e-9];
    let distance = |p: [f64; 2]| ((p[0] - centre[0]).powi(2) + (p[1] - centre[1]).powi(2)).sqrt();
    assert!(
        second
            .iter()
            .all(|f| distance(f.sample_position_m) <= 2.0e-9)
    );
    assert!(first.iter().all(|f| distance(f.sample_position_m) > 2.0e-9));
    // Nearest-neighbour bonds of the second domain point along 0.3 rad + k·60°.
    let mut bonds = 0;
    for a in &second {
        for b in &second {
            let d = [
                b.sample_position_m[0] - a.sample_position_m[0],
                b.sample_position_m[1] - a.sample_position_m[1],
            ];
            let length = (d[0] * d[0] + d[1] * d[1]).sqrt();
            if (length - A).abs() < 1e-3 * A {
                let relative = (d[1].atan2(d[0]) - angle).rem_euclid(std::f64::consts::FRAC_PI_3);
                let off = relative.min(std::f64::consts::FRAC_PI_3 - relative);
                assert!(off < 1e-9, "bond angle off by {off}");
                bonds += 1;
            }
        }
    }
    assert!(bonds > 100);
}

#[test]
fn strain_scales_the_spacing_inside_its_region() {
    let mut config = base_config();
    let strain = 0.04;
    config.surface.strain.push(StrainRegion {
        region: Region::Rectangle {
            min_m: [0.0, 0.0],
            max_m: [6.4e-9, 3.0e-9],
        },
        strain: [[strain, 0.0], [0.0, 0.0]],
        anchor_m: [0.25e-9, 0.0],
    });
    let output = run(&config);
    for a in &output.truth.features {
        for b in &output.truth.features {
            let (Some((na, ma)), Some((nb, mb))) = (cell(a), cell(b)) else {
                continue;
            };
            if ma == mb && nb == na + 1 {
                let dx = b.sample_position_m[0] - a.sample_position_m[0];
                let inside = a.sample_position_m[1] < 3.0e-9 && a.sample_position_m[0] > 0.0;
                let outside = a.sample_position_m[1] > 3.2e-9;
                if inside && b.sample_position_m[0] < 6.4e-9 {
                    assert!((dx - A * (1.0 + strain)).abs() < 1e-18, "{dx}");
                } else if outside {
                    assert!((dx - A).abs() < 1e-18, "{dx}");
                }
            }
        }
    }
}

#[test]
fn molecule_lobes_and_tip_broadening_shape_the_features() {
    let mut config = base_config();
    config.surface.feature.lobes = vec![
        Lobe {
            offset_m: [-100e-12, 0.0],
            relative_height: 1.0,
            sigma_m: Some([50e-12, 50e-12]),
            angle_rad: None,
        },
        Lobe {
            offset_m: [100e-12, 0.0],
            relative_height: 0.5,
            sigma_m: Some([50e-12, 50e-12]),
            angle_rad: None,
        },
    ];
    let output = run(&config);
    let image = output.pair.trace().unwrap();
    // Each molecule shows two maxima 4 px apart, the left one twice as bright.
    let found = peaks(image, 10e-12);
    let near = |x: f64, y: f64| {
        found
            .iter()
            .any(|p| (p[0] - x).abs() < 0.05 && (p[1] - y).abs() < 0.05)
    };
    assert!(near(53.0, 55.0) && near(57.0, 55.0), "{found:?}");
    // (the lobes overlap by exp(−8) ≈ 3e-4 of a peak)
    assert!((image.z[[55, 53]] / image.z[[55, 57]] - 2.0).abs() < 3e-3);

    // A Gaussian tip of σ_t lowers a σ feature's peak by σ²/(σ² + σ_t²) = ½ here, and
    // widens it to √8 px, so the 4 neighbours at 10 px add exp(−100/16) each.
    let mut blunt = base_config();
    blunt.tip.sigma_m = 100e-12;
    let z = run(&blunt).pair.trace().unwrap().z[[55, 55]];
    let expected = 25e-12 * (1.0 + 4.0 * (-100.0f64 / 16.0).exp());
    assert!((z - expected).abs() < 1e-6 * expected, "{z} vs {expected}");
}

#[test]
fn a_tilted_sample_adds_its_plane_to_every_pixel() {
    let flat = run(&base_config());
    let mut config = base_config();
    let slope = [0.03, -0.05];
    config.surface.plane_slope = slope;
    let tilted = run(&config);
    let (a, b) = (
        &flat.pair.trace().unwrap().z,
        &tilted.pair.trace().unwrap().z,
    );
    for (row, column) in [(0, 0), (10, 90), (64, 64), (127, 3)] {
        let expected = slope[0] * column as f64 * PITCH + slope[1] * row as f64 * PITCH;
        let added = b[[row, column]] - a[[row, column]];
        assert!(
            (added - expected).abs() < 1e-15,
            "({row}, {column}): {added} vs {expected}"
        );
    }
    // The features themselves stay where they were.
    assert_eq!(flat.truth.features.len(), tilted.truth.features.len());
}
