//! The image view below one feature (issue 17): a 37 Hz vibration of 0.04 a on a 512²
//! graphite image is invisible to the feature positions (every feature spans ~17 line
//! pairs, 4.4 vibration periods apart) but shears every feature line by line; the slices
//! find it. The same scan without the vibration must not get one.

use dhct_diagnose::{SubFeatureView, sub_feature_view_of_pair};
use dhct_features::{FeatureOptions, find_features_in_pair};
use dhct_simulate::{Simulation, SimulationConfig};

mod common;

/// The shared 512² graphite scan (`common::graphite_512`) with `vibration` appended.
fn config(vibration: &str) -> SimulationConfig {
    common::graphite_512("sub-feature", 37, vibration)
}

fn view(config: &SimulationConfig) -> SubFeatureView {
    view_of(config, 2)
}

/// The view from the first `passes` passes (trace first).
fn view_of(config: &SimulationConfig, passes: usize) -> SubFeatureView {
    let output = Simulation::from_config(config).unwrap().run().unwrap();
    let lattice = config.surface.lattice.build().unwrap();
    let options = FeatureOptions::for_neighbour_distance(lattice.nearest_neighbour_distance());
    let sets = find_features_in_pair(&output.pair, &options).unwrap();
    let sets: Vec<_> = sets.iter().take(passes).collect();
    sub_feature_view_of_pair(&output.pair, &sets, &options, None).expect("enough slices")
}

/// 0.04 × the graphite lattice constant (2.46 Å), metres.
const AMPLITUDE_M: f64 = 0.04 * 2.46e-10;

#[test]
fn a_37_hz_vibration_below_one_feature_is_found() {
    let along = view(&config(&format!(
        "[[effects]]\nkind = \"vibration\"\nfrequency_hz = 37.0\n\
         amplitude_m = [{AMPLITUDE_M:e}, 0.0]\nphase_rad = [0.3, 0.0]"
    )));
    println!("{}", along.describe());
    assert!(along.vibration_found, "{along:?}");
    let v = along.strongest.as_ref().unwrap();
    assert!((v.frequency_hz - 37.0).abs() < 0.02 * 37.0, "{v:?}");
    assert!(
        (v.amplitude_along_m / AMPLITUDE_M - 1.0).abs() < 0.2,
        "{v:?}"
    );
    assert!(v.pass_agreement.unwrap() > 0.9, "{v:?}");

    // Across the lines the slices read the displacement from brightness: the frequency
    // is found, the amplitude is only approximate (documented).
    let across = view(&config(&format!(
        "[[effects]]\nkind = \"vibration\"\nfrequency_hz = 37.0\n\
         amplitude_m = [0.0, {AMPLITUDE_M:e}]\nphase_rad = [0.0, 1.0]"
    )));
    println!("{}", across.describe());
    assert!(across.vibration_found, "{across:?}");
    let v = across.strongest.as_ref().unwrap();
    assert!((v.frequency_hz - 37.0).abs() < 0.02 * 37.0, "{v:?}");
}

/// With the trace alone the peak is there but cannot be told from a lattice-locked
/// pattern: significant, not found.
#[test]
fn one_pass_shows_the_peak_but_does_not_name_a_vibration() {
    let one = view_of(
        &config(&format!(
            "[[effects]]\nkind = \"vibration\"\nfrequency_hz = 37.0\n\
             amplitude_m = [{AMPLITUDE_M:e}, 0.0]"
        )),
        1,
    );
    println!("{}", one.describe());
    let v = one.strongest.as_ref().unwrap();
    assert!(v.is_significant() && v.pass_agreement.is_none(), "{v:?}");
    assert!(!one.vibration_found);
    assert!((v.frequency_hz - 37.0).abs() < 0.02 * 37.0, "{v:?}");
}

#[test]
fn without_a_vibration_none_is_reported() {
    let quiet = view(&config(""));
    println!("{}", quiet.describe());
    assert!(!quiet.vibration_found, "{quiet:?}");
    assert!(quiet.spread_over_noise.iter().all(|s| s.is_finite()));
}
