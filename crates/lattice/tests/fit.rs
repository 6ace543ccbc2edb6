//! Whole-image lattice fit on synthetic points with known parameters.

use dhct_lattice::{
    Hexagonal, Honeycomb, Lattice, LatticeFitError, LatticeFitOptions, Square,
    angular_distribution, fit_calibrated_lattice, fit_lattice, lattice_sites,
};
use nalgebra::{Matrix2, Vector2};

type Sites = Vec<(i64, i64, usize)>;

/// Lattice sites of `lattice` in a `size` square, rotated by `angle`, scaled by `scale` along
/// x and y, shifted by `shift`, with deterministic pseudo-random jitter of rms ≈ `jitter` m.
fn points(
    lattice: &dyn Lattice,
    size: f64,
    angle: f64,
    scale: [f64; 2],
    shift: [f64; 2],
    jitter: f64,
) -> (Vec<[f64; 2]>, Sites) {
    let sites = lattice_sites(lattice, Vector2::new(0.37e-10, 0.21e-10), angle, size, size);
    let d = Matrix2::new(scale[0], 0.0, 0.0, scale[1]);
    let mut state = 12345u64;
    let mut noise = || {
        // xorshift, uniform in [-√3, √3]·jitter (rms = jitter)
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        ((state >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0) * 3f64.sqrt() * jitter
    };
    let mut out = Vec::new();
    let mut truth = Vec::new();
    for s in sites {
        let p = d * s.position + Vector2::from(shift);
        out.push([p.x + noise(), p.y + noise()]);
        truth.push((s.n, s.m, s.site));
    }
    (out, truth)
}

/// The fitted indices equal the true ones up to one global integer relabelling
/// `fitted = U·true + t` (a lattice symmetry and a choice of origin cell), with U found by
/// least squares over all points, rounded, and then checked exactly for every point.
fn assert_consistent_indices(fitted: &[(i64, i64, usize)], truth: &[(i64, i64, usize)]) {
    let count = fitted.len() as f64;
    let mean = |v: &dyn Fn(usize) -> f64| (0..fitted.len()).map(v).sum::<f64>() / count;
    let (tn, tm) = (mean(&|i| truth[i].0 as f64), mean(&|i| truth[i].1 as f64));
    let (fn_, fm) = (mean(&|i| fitted[i].0 as f64), mean(&|i| fitted[i].1 as f64));
    let (mut ata, mut bta) = (Matrix2::zeros(), Matrix2::zeros());
    for i in 0..fitted.len() {
        let a = Vector2::new(truth[i].0 as f64 - tn, truth[i].1 as f64 - tm);
        let b = Vector2::new(fitted[i].0 as f64 - fn_, fitted[i].1 as f64 - fm);
        ata += a * a.transpose();
        bta += b * a.transpose();
    }
    let u = (bta * ata.try_inverse().unwrap()).map(|v| v.round() as i64);
    let [u00, u01, u10, u11] = [u[(0, 0)], u[(0, 1)], u[(1, 0)], u[(1, 1)]];
    assert_eq!(
        (u00 * u11 - u01 * u10).abs(),
        1,
        "relabelling must be unimodular: {u}"
    );
    let offset = (
        fitted[0].0 - (u00 * truth[0].0 + u01 * truth[0].1),
        fitted[0].1 - (u10 * truth[0].0 + u11 * truth[0].1),
    );
    for (k, (f, t)) in fitted.iter().zip(truth).enumerate() {
        let expected = (
            u00 * t.0 + u01 * t.1 + offset.0,
            u10 * t.0 + u11 * t.1 + offset.1,
        );
        assert_eq!((f.0, f.1), expected, "point {k}: fitted {f:?}, true {t:?}");
    }
}

#[test]
fn recovers_rotation_scales_and_indices_of_a_hexagonal_lattice() {
    let graphite = Hexagonal::graphite();
    let (angle, scale) = (0.3, [1.02, 0.99]);
    let (pts, truth) = points(&graphite, 8e-9, angle, scale, [1e-10, -2e-10], 5e-12);
    let fit = fit_lattice(&graphite, &[&pts], &LatticeFitOptions::default()).unwrap();
    // θ is defined modulo the lattice's 60° symmetry.
    let dtheta = (fit.angle_rad - angle).rem_euclid(std::f64::consts::FRAC_PI_3);
    let dtheta = dtheta.min(std::f64::consts::FRAC_PI_3 - dtheta);
    assert!(dtheta < 1e-4, "angle {} vs {angle}", fit.angle_rad);
    assert!(
        (fit.scale[0] - scale[0]).abs() < 2e-4 && (fit.scale[1] - scale[1]).abs() < 2e-4,
        "{:?}",
        fit.scale
    );
    // 2-D rms of a jitter of 5 pm per axis is √2 · 5 pm.
    assert!(
        (fit.rms_deviation_m / (2f64.sqrt() * 5e-12) - 1.0).abs() < 0.1,
        "rms {}",
        fit.rms_deviation_m
    );
    assert_eq!(fit.used, pts.len());
    let fitted: Vec<_> = fit.points[0].iter().map(|p| (p.n, p.m, p.site)).collect();
    assert_consistent_indices(&fitted, &truth);
}

#[test]
fn honeycomb_and_square_lattices_are_indexed_with_their_sites() {
    let graphene = Honeycomb::graphene();
    let (pts, truth) = points(&graphene, 6e-9, -0.2, [1.0, 1.0], [0.0, 0.0], 3e-12);
    let fit = fit_lattice(&graphene, &[&pts], &LatticeFitOptions::default()).unwrap();
    let fitted: Vec<_> = fit.points[0].iter().map(|p| (p.n, p.m, p.site)).collect();
    // Sublattice labels may swap globally under the relabelling; they must be consistent.
    let swapped = fitted[0].2 != truth[0].2;
    for (f, t) in fitted.iter().zip(&truth) {
        assert_eq!(f.2 != t.2, swapped, "sublattice of {f:?} vs {t:?}");
    }
    assert!(
        fit.rms_deviation_m < 1.1 * 2f64.sqrt() * 3e-12,
        "{}",
        fit.rms_deviation_m
    );

    let square = Square::new(3e-10).unwrap();
    let (pts, truth) = points(&square, 8e-9, 0.5, [1.0, 1.01], [0.0, 0.0], 4e-12);
    let fit = fit_lattice(&square, &[&pts], &LatticeFitOptions::default()).unwrap();
    let fitted: Vec<_> = fit.points[0].iter().map(|p| (p.n, p.m, p.site)).collect();
    assert_consistent_indices(&fitted, &truth);
}

#[test]
fn trace_retrace_offset_is_fitted_jointly() {
    let graphite = Hexagonal::graphite();
    let (trace, _) = points(&graphite, 6e-9, 0.1, [1.0, 1.0], [0.0, 0.0], 3e-12);
    let offset = [0.3e-10, -0.2e-10];
    let retrace: Vec<[f64; 2]> = trace
        .iter()
        .map(|p| [p[0] + offset[0] + 1e-12, p[1] + offset[1] - 1e-12])
        .collect();
    let fit = fit_lattice(
        &graphite,
        &[&trace, &retrace],
        &LatticeFitOptions::default(),
    )
    .unwrap();
    let d = fit.set_offsets_m[1];
    assert!(
        (d[0] - offset[0] - 1e-12).abs() < 1e-15 && (d[1] - offset[1] + 1e-12).abs() < 1e-15,
        "{d:?}"
    );
    assert_eq!(fit.points[1].len(), retrace.len());
    assert_eq!(
        fit.points[0].iter().map(|p| (p.n, p.m)).collect::<Vec<_>>(),
        fit.points[1].iter().map(|p| (p.n, p.m)).collect::<Vec<_>>()
    );
}

#[test]
fn the_angular_distribution_finds_the_bond_angle() {
    let graphite = Hexagonal::graphite();
    let (pts, _) = points(&graphite, 6e-9, 0.2, [1.0, 1.0], [0.0, 0.0], 2e-12);
    let adf = angular_distribution(&graphite, &pts, 0.35, 180).unwrap();
    assert!(
        (adf.lattice_angle_rad - 0.2).abs() < 1e-3,
        "{}",
        adf.lattice_angle_rad
    );
    assert!((adf.period_rad - std::f64::consts::FRAC_PI_3).abs() < 1e-12);
    assert!(
        (adf.median_nn_m / 2.46e-10 - 1.0).abs() < 0.01,
        "{}",
        adf.median_nn_m
    );
    // Three bond directions 60° apart hold almost all bonds.
    let peak_bins = adf.counts.iter().filter(|&&c| c > adf.bonds / 20).count();
    assert!(peak_bins <= 9, "{peak_bins}");
}

/// Features found twice on every atom (a template that splits each atom's peak): their
/// median neighbour distance is the pairs' spacing, so the first indexing disc holds one
/// pair; the error says the features are clustered, not that the fit diverged.
#[test]
fn features_in_pairs_are_named_as_clustered() {
    let graphite = Hexagonal::graphite();
    let a = 2.46e-10;
    let mut points = Vec::new();
    for n in 0..12 {
        for m in 0..12 {
            let x = a * (n as f64 + 0.5 * m as f64);
            let y = a * 3f64.sqrt() / 2.0 * m as f64;
            points.push([x, y]);
            points.push([x + 2e-12, y]);
        }
    }
    let error = fit_lattice(&graphite, &[&points], &LatticeFitOptions::default()).unwrap_err();
    assert!(
        matches!(error, LatticeFitError::SparseSeed { found, needed, .. } if found < needed),
        "{error}"
    );
    assert!(error.to_string().contains("clustered"), "{error}");
}

#[test]
fn random_points_and_too_few_points_are_clear_errors() {
    let graphite = Hexagonal::graphite();
    let mut state = 99u64;
    let mut uniform = || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let random: Vec<[f64; 2]> = (0..800)
        .map(|_| [uniform() * 6e-9, uniform() * 6e-9])
        .collect();
    let error = fit_lattice(&graphite, &[&random], &LatticeFitOptions::default()).unwrap_err();
    assert!(
        matches!(
            error,
            LatticeFitError::Diverged { .. }
                | LatticeFitError::TooScattered { .. }
                | LatticeFitError::NoBonds { .. }
        ),
        "{error}"
    );
    let few = [[0.0, 0.0], [2.46e-10, 0.0]];
    assert!(matches!(
        fit_lattice(&graphite, &[&few], &LatticeFitOptions::default()),
        Err(LatticeFitError::TooFewPoints { .. })
    ));
    let bad = [[f64::NAN, 0.0]; 10];
    assert!(matches!(
        fit_lattice(&graphite, &[&bad], &LatticeFitOptions::default()),
        Err(LatticeFitError::NotFinite { .. })
    ));
}

#[test]
fn a_lattice_scattered_past_a_quarter_of_its_spacing_is_refused_naming_the_rms() {
    // Uniform jitter of rms 0.3 nn along each axis: most features still lie within half a
    // lattice constant of a site, but together they are no affine lattice.
    let graphite = Hexagonal::graphite();
    let nn = graphite.nearest_neighbour_distance();
    let (scattered, _) = points(&graphite, 6e-9, 0.3, [1.0, 1.0], [0.0, 0.0], 0.2 * nn);
    let error = fit_lattice(&graphite, &[&scattered], &LatticeFitOptions::default()).unwrap_err();
    match error {
        LatticeFitError::TooScattered {
            fraction_ok,
            rms_percent,
            limit_percent,
            ..
        } => {
            assert!(fraction_ok >= 80.0, "{error}");
            assert!(rms_percent > limit_percent, "{error}");
            assert!(error.to_string().contains("rms"), "{error}");
        }
        other => panic!("{other}"),
    }
    // A tenth of that is a lattice.
    let (tight, _) = points(&graphite, 6e-9, 0.3, [1.0, 1.0], [0.0, 0.0], 0.02 * nn);
    assert!(fit_lattice(&graphite, &[&tight], &LatticeFitOptions::default()).is_ok());
}

#[test]
fn noisy_positions_at_the_lattice_scale_are_indexed_from_its_constant() {
    // A small frame (ten periods) whose features scatter by 0.15 of the neighbour
    // distance per axis, as around a defect: each feature's nearest neighbour is the
    // shortest of about six noisy bonds, so the features' median nearest-neighbour distance
    // is about a tenth short, and the indexing started there diverges (measured: from
    // 0.14 of the distance up, at 8-14 periods; the start at the constant indexes them all).
    let graphite = Hexagonal::graphite();
    let nn = graphite.nearest_neighbour_distance();
    let (pts, truth) = points(&graphite, 10.0 * nn, 0.2, [1.0, 1.0], [0.0, 0.0], 0.15 * nn);
    let adf = angular_distribution(&graphite, &pts, 0.35, 180).unwrap();
    assert!(
        adf.median_nn_m < 0.92 * nn,
        "median NN {} of {nn}",
        adf.median_nn_m
    );
    let fit = fit_calibrated_lattice(&graphite, &[&pts], &LatticeFitOptions::default()).unwrap();
    for scale in fit.scale {
        assert!((scale - 1.0).abs() < 0.02, "scale {:?}", fit.scale);
    }
    let fitted: Vec<_> = fit.points[0].iter().map(|p| (p.n, p.m, p.site)).collect();
    assert_consistent_indices(&fitted, &truth);
}
