//! The plots of the fitted model: RDF, ADF, hysteresis, drift and creep, and the
//! deviations from the fitted lattice with their confidence ellipses (equal aspect).

use dhct_distortion::HysteresisLaw;
use dhct_pipeline::{Analysis, RegionFit};
use dhct_scan::{ScanGeometry, ScanPass};
use dhct_unitcell::ConfidenceEllipse;

use super::figures::Figure;
use super::plots::{BLUE, GREEN, INK, ORANGE, Plot, Series, Style, VERMILION, thin};
use super::scatter::{Curve, EqualAspectPlot};
use crate::units::{angstrom, degrees};

/// g(r) of raw (dashed) and corrected (solid) features, trace blue and retrace vermilion.
pub fn rdf_plot(analysis: &Analysis) -> Figure {
    let mut plot = Plot::new("Radial distribution function", "r (Å)", "g(r)");
    let mut caption = String::from(
        "g(r) of the raw (controller-frame, dashed) and corrected (sample-frame, solid) \
         features; grey lines: the fitted shell positions of the raw RDF.",
    );
    let to_angstrom = |r: &[f64], g: &[f64]| -> Vec<(f64, f64)> {
        r.iter().zip(g).map(|(r, g)| (r * 1e10, *g)).collect()
    };
    for (k, pass) in analysis.passes.iter().enumerate() {
        let Some(raw) = analysis.dhct.passes.iter().find(|p| p.pass == pass.pass) else {
            continue;
        };
        let colour = if pass.pass == ScanPass::Trace {
            BLUE
        } else {
            VERMILION
        };
        let rdf = &raw.selection.rdf;
        plot = plot.with(Series::new(
            format!("{} raw", pass.pass),
            to_angstrom(&rdf.r_m, &rdf.g),
            Style::Dashed,
            colour,
        ));
        if let Some(after) = &pass.rdf_corrected {
            plot = plot.with(Series::new(
                format!("{} corrected", pass.pass),
                to_angstrom(&after.r_m, &after.g),
                Style::Line,
                colour,
            ));
        }
        if k == 0 {
            let fit = &raw.selection.rdf_fit;
            plot.vertical_lines = fit.shells_m.iter().map(|r| r * 1e10).collect();
            caption.push_str(&format!(
                " First shell (raw {}): {}, FWHM {}.",
                pass.pass,
                angstrom(fit.nn_distance_m, 3),
                angstrom(fit.fwhm_m.first().copied().unwrap_or(f64::NAN), 3)
            ));
        }
    }
    Figure::plot(
        "rdf",
        "Radial distribution function (paper Fig. 6)",
        caption,
        &plot,
    )
}

/// The directions of the nearest-neighbour bonds of region 0.
pub fn adf_plot(analysis: &Analysis) -> Option<Figure> {
    let adf = analysis.regions.first()?.adf.as_ref()?;
    let points = adf
        .angles_rad
        .iter()
        .zip(&adf.counts)
        .map(|(a, &c)| (a.to_degrees(), c as f64))
        .collect();
    let plot = Plot::new(
        "Angular distribution of NN bonds",
        "bond angle (°)",
        "bonds",
    )
    .with(Series::new("corrected", points, Style::Bars, BLUE));
    Some(Figure::plot(
        "adf",
        "Angular distribution (ADF, paper Fig. S2)",
        format!(
            "Directions of the {} nearest-neighbour bonds of the corrected features; lattice \
             angle {}.",
            adf.bonds,
            degrees(adf.lattice_angle_rad.to_degrees(), 2)
        ),
        &plot,
    ))
}

/// Local fast-axis scale against time since line start, with the fitted law.
pub fn hysteresis_plot(geometry: &ScanGeometry, analysis: &Analysis) -> Figure {
    let mut plot = Plot::new(
        "Fast-scan hysteresis",
        "time since line start τ (ms)",
        "local scale S",
    );
    for (pass, colour) in [(ScanPass::Trace, BLUE), (ScanPass::Retrace, ORANGE)] {
        let points: Vec<(f64, f64)> =
            local_points(analysis, pass, |l| (l.line_time_s * 1e3, l.scale));
        if !points.is_empty() {
            plot = plot.with(Series::new(
                format!("{pass} (local)"),
                thin(points, SHOWN_PER_PASS),
                Style::Points,
                colour,
            ));
        }
    }
    let law = &analysis.dhct.model.hysteresis;
    let t_line = geometry.line_scan_time();
    let curve = (0..=200)
        .map(|i| {
            let tau = t_line * (i as f64 + 0.5) / 201.0;
            (tau * 1e3, law.scale(tau))
        })
        .collect();
    plot = plot.with(Series::new("fitted law", curve, Style::Line, INK));
    Figure::plot(
        "hysteresis",
        "Hysteresis fit (paper Fig. 8)",
        format!(
            "Local fast-axis scale S of the selected features against their time since the \
             start of their line, trace (blue) and retrace (orange) pooled{}; black: the \
             fitted law {}.",
            shown_note(analysis),
            describe_law(law)
        ),
        &plot,
    )
}

/// Local measurements drawn per pass at most (evenly spaced in time): a plot of 2 × 1,500
/// points shows the cloud and stays a few hundred kilobytes in the report.
const SHOWN_PER_PASS: usize = 1500;

/// " (N of M shown, ...)" when the passes have more local measurements than are drawn.
fn shown_note(analysis: &Analysis) -> String {
    let total: usize = analysis.dhct.passes.iter().map(|p| p.local.len()).sum();
    let shown: usize = analysis
        .dhct
        .passes
        .iter()
        .map(|p| p.local.len().min(SHOWN_PER_PASS))
        .sum();
    if shown < total {
        format!(" ({shown} of {total} shown, evenly spaced in time)")
    } else {
        String::new()
    }
}

/// `f` of every local distortion measurement of `pass`.
fn local_points(
    analysis: &Analysis,
    pass: ScanPass,
    f: impl Fn(&dhct_distortion::LocalDistortion) -> (f64, f64),
) -> Vec<(f64, f64)> {
    analysis
        .dhct
        .passes
        .iter()
        .filter(|p| p.pass == pass)
        .flat_map(|p| p.local.iter().map(&f))
        .collect()
}

/// The fitted hysteresis law in words and symbols.
fn describe_law(law: &HysteresisLaw) -> String {
    match law {
        HysteresisLaw::Power { k, n } => format!("S = k·τⁿ with k = {k:.4} s⁻ⁿ, n = {n:.4}"),
        HysteresisLaw::Exponential {
            amplitude,
            time_constant_s,
        } => format!(
            "S = 1 + A·exp(−τ/τh) with A = {amplitude:.4}, τh = {:.3} ms",
            time_constant_s * 1e3
        ),
        HysteresisLaw::Quartic {
            coefficients,
            time_scale_s,
        } => {
            let c: Vec<String> = coefficients.iter().map(|c| format!("{c:.4}")).collect();
            format!(
                "S = 1 + Σ cₖ (τ/τs)ᵏ with c = ({}), τs = {:.3} ms",
                c.join(", "),
                time_scale_s * 1e3
            )
        }
    }
}

/// Drift velocity along x and along y against acquisition time, with the fitted curve.
pub fn drift_plots(analysis: &Analysis) -> Vec<Figure> {
    let t_max = analysis
        .dhct
        .passes
        .iter()
        .flat_map(|p| p.local.iter().map(|l| l.time_s))
        .fold(0.0, f64::max);
    (0..2)
        .map(|axis| drift_plot(analysis, axis, t_max))
        .collect()
}

fn drift_plot(analysis: &Analysis, axis: usize, t_max: f64) -> Figure {
    let drift = &analysis.dhct.model.drift;
    let name = ["x", "y"][axis];
    let mut plot = Plot::new(
        &format!("Drift + creep, D{name}"),
        "time since frame start t (s)",
        &format!("D{name} (pm/s)"),
    );
    for (pass, colour) in [(ScanPass::Trace, BLUE), (ScanPass::Retrace, ORANGE)] {
        let points = local_points(analysis, pass, |l| (l.time_s, l.drift_m_per_s[axis] * 1e12));
        if !points.is_empty() {
            plot = plot.with(Series::new(
                format!("{pass} (local)"),
                thin(points, SHOWN_PER_PASS),
                Style::Points,
                colour,
            ));
        }
    }
    let curve = (0..=200)
        .map(|i| {
            let t = t_max * i as f64 / 200.0;
            (t, drift.velocity(t)[axis] * 1e12)
        })
        .collect();
    plot = plot.with(Series::new(
        "fitted v + a·t + C/(t + t0)",
        curve,
        Style::Line,
        INK,
    ));
    Figure::plot(
        &format!("drift_{name}"),
        &format!("Drift and creep along {name} (paper Fig. 9)"),
        format!(
            "Local drift velocity D{name} of the selected features against acquisition time, \
             trace (blue) and retrace (orange){}; black: the fitted drift + creep velocity \
             (v = {:.2} pm/s, a = {:.3} pm/s², C = {:.1} pm, t0 = {:.1} s).",
            shown_note(analysis),
            drift.velocity_m_per_s[axis] * 1e12,
            drift.acceleration_m_per_s2[axis] * 1e12,
            drift.creep_m[axis] * 1e12,
            drift.t0_s
        ),
        &plot,
    )
}

/// The outline of `e` scaled to `k`σ, picometres, closed.
fn ellipse_pm(e: &ConfidenceEllipse, k: f64) -> Vec<(f64, f64)> {
    let mut outline: Vec<(f64, f64)> = e
        .outline(e.mean_m, k, 120)
        .into_iter()
        .map(|[x, y]| (x * 1e12, y * 1e12))
        .collect();
    if let Some(&first) = outline.first() {
        outline.push(first);
    }
    outline
}

/// Deviations of region 0's trace features from their lattice sites with the 1σ and 2σ
/// ellipses, drawn at equal aspect (a round cloud looks round).
pub fn deviation_scatter(region: &RegionFit) -> Figure {
    let e = &region.whole_ellipse;
    let mut curves = vec![
        Curve {
            label: "1σ".into(),
            points: ellipse_pm(e, 1.0),
            colour: VERMILION,
            dashed: false,
        },
        Curve {
            label: "2σ".into(),
            points: ellipse_pm(e, 2.0),
            colour: VERMILION,
            dashed: true,
        },
    ];
    if let Some(local) = &region.local_ellipse {
        curves.push(Curve {
            label: "1σ local cells".into(),
            points: ellipse_pm(local, 1.0),
            colour: GREEN,
            dashed: false,
        });
    }
    let plot = EqualAspectPlot {
        title: "Deviations from the fitted lattice".into(),
        x_label: "Δx (pm)".into(),
        y_label: "Δy (pm, down as in the images)".into(),
        points_label: "features (trace)".into(),
        points: thin(
            region.fit.points[0]
                .iter()
                .map(|p| (p.deviation_m[0] * 1e12, p.deviation_m[1] * 1e12))
                .collect(),
            2 * SHOWN_PER_PASS,
        ),
        points_colour: BLUE,
        curves,
    };
    let local = region
        .local_ellipse
        .as_ref()
        .map(|l| {
            format!(
                "; local-cell 1σ ellipse {:.1} × {:.1} pm",
                l.sigma_major_m * 1e12,
                l.sigma_minor_m * 1e12
            )
        })
        .unwrap_or_default();
    let sigma_z = e
        .sigma_z_m
        .map(|z| format!("; σz {:.1} pm", z * 1e12))
        .unwrap_or_default();
    Figure::equal_aspect(
        "deviation_scatter",
        "Confidence ellipses",
        format!(
            "Deviation of each corrected feature from its fitted lattice site (region 0), \
             drawn at equal scale along Δx and Δy with +Δy down, as in the images. Whole-image 1σ ellipse {:.1} × {:.1} pm at \
             {}{local}{sigma_z}.",
            e.sigma_major_m * 1e12,
            e.sigma_minor_m * 1e12,
            degrees(e.angle_rad.to_degrees(), 1),
        ),
        &plot,
    )
}
