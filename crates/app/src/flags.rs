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
    let mut line = warning.to_string();
    if !warning.inputs.is_empty() {
        let flags: Vec<&str> = warning.inputs.iter().map(|i| flag(*i)).collect();
        line.push_str(&format!(" [options: {}]", flags.join(", ")));
    }
    if warning.suggests_diagnosis {
        line.push_str(" [diagnose: dhct diagnose FILE -o DIR, or dhct correct --diagnose]");
    }
    line
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

#[cfg(test)]
mod tests {
    use super::*;
    use dhct_pipeline::WarningCode;

    #[test]
    fn a_warning_line_names_the_flags_and_the_diagnosis_it_advises() {
        let warning = Warning {
            code: WarningCode::LargeDeviation,
            message: "features deviate".into(),
            what_to_do: "diagnose the gap".into(),
            inputs: vec![UserInput::Mask],
            suggests_diagnosis: true,
        };
        let line = warning_line(&warning);
        assert!(line.contains("[options: --mask]"), "{line}");
        assert!(line.contains("dhct diagnose"), "{line}");
        let plain = Warning {
            inputs: Vec::new(),
            suggests_diagnosis: false,
            ..warning
        };
        assert_eq!(warning_line(&plain), plain.to_string());
    }
}
