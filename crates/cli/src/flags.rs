//! How the command line spells the inputs the library's warnings and errors refer to
//! ([`UserInput`]): the library names quantities, the command line adds its flags.

use dhct_pipeline::{UserInput, Warning};

/// The command-line flag that gives `input` (every one is an option of `dhct correct`;
/// `crates/cli/tests/flags.rs` checks that against `--help`).
pub fn flag(input: UserInput) -> &'static str {
    match input {
        UserInput::Lattice => "--lattice",
        UserInput::NearestNeighbourDistance => "--nn",
        UserInput::LineTime => "--line-time",
        UserInput::PixelPeriod => "--pixel-period",
        UserInput::PixelSize => "--pitch",
        UserInput::Turnaround => "--turnaround",
        UserInput::ScanDirections => "--fast",
        UserInput::Mask => "--mask",
        UserInput::Polarity => "--polarity",
        UserInput::CalibratePixelSize => "--calibrate",
        UserInput::TrustInputs => "--trust-inputs",
    }
}

/// The warning as one line for stderr, with the flags its advice refers to.
pub fn warning_line(warning: &Warning) -> String {
    if warning.inputs.is_empty() {
        return warning.to_string();
    }
    let flags: Vec<&str> = warning.inputs.iter().map(|i| flag(*i)).collect();
    format!("{warning} [options: {}]", flags.join(", "))
}

/// Every input, for front ends that list them.
pub const ALL_INPUTS: [UserInput; 11] = [
    UserInput::Lattice,
    UserInput::NearestNeighbourDistance,
    UserInput::LineTime,
    UserInput::PixelPeriod,
    UserInput::PixelSize,
    UserInput::Turnaround,
    UserInput::ScanDirections,
    UserInput::Mask,
    UserInput::Polarity,
    UserInput::CalibratePixelSize,
    UserInput::TrustInputs,
];
