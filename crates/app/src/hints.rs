//! What to change when the pipeline stops, in the user's own terms: the library's errors
//! are typed and name quantities ([`UserInput`]); a front end renders the hint with its
//! own spelling of each input ([`Spelling::CommandLine`] flags, [`Spelling::Python`]
//! keyword arguments).

use dhct_calibrate::{CalibrationError, length};
use dhct_features::{FeatureError, Polarity};
use dhct_pipeline::{PipelineError, UserInput};

use crate::flags::flag;
use crate::setup::LatticeChoiceError;

/// How a front end spells the inputs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Spelling {
    /// `dhct` flags: `--nn 2.46Å`, `--calibrate`.
    CommandLine,
    /// `dhct.correct` keyword arguments: `nn="2.46Å"`, `calibrate=True`.
    Python,
}

impl Spelling {
    /// The name of `input` alone: `--nn`, or `nn`.
    pub fn name(self, input: UserInput) -> &'static str {
        match self {
            Spelling::CommandLine => flag(input),
            Spelling::Python => keyword(input),
        }
    }

    /// `input` set to `value` (text): `--nn 2.46Å`, or `nn="2.46Å"`.
    pub fn set(self, input: UserInput, value: &str) -> String {
        match self {
            Spelling::CommandLine => format!("{} {value}", flag(input)),
            Spelling::Python => format!("{}=\"{value}\"", keyword(input)),
        }
    }

    /// A switch turned on: `--calibrate`, or `calibrate=True`.
    pub fn switch(self, input: UserInput) -> String {
        match self {
            Spelling::CommandLine => flag(input).to_string(),
            Spelling::Python => format!("{}=True", keyword(input)),
        }
    }

    /// Names of several inputs: "--lattice and --nn", or "lattice= and nn=".
    fn names(self, inputs: &[UserInput]) -> String {
        let names: Vec<String> = inputs
            .iter()
            .map(|&i| match self {
                Spelling::CommandLine => flag(i).to_string(),
                Spelling::Python => format!("{}=", keyword(i)),
            })
            .collect();
        match names.as_slice() {
            [] => String::new(),
            [one] => one.clone(),
            [rest @ .., last] => format!("{} and {last}", rest.join(", ")),
        }
    }
}

/// The keyword argument of `dhct.correct` that gives `input`.
pub fn keyword(input: UserInput) -> &'static str {
    match input {
        UserInput::Lattice => "lattice",
        UserInput::NearestNeighbourDistance => "nn",
        UserInput::LineTime => "line_time",
        UserInput::PixelPeriod => "pixel_period",
        UserInput::PixelSize => "pitch",
        UserInput::Turnaround => "turnaround",
        UserInput::ScanDirections => "fast",
        UserInput::Mask => "mask",
        UserInput::Polarity => "polarity",
        UserInput::CalibratePixelSize => "calibrate",
        UserInput::TrustInputs => "trust_inputs",
    }
}

/// The pipeline's error with what to change, in `spelling`.
pub fn explain(error: &PipelineError, spelling: Spelling) -> String {
    use UserInput::{Lattice, Mask, NearestNeighbourDistance as Nn, PixelSize, Polarity as Pol};
    let hint = match error {
        PipelineError::Calibration(e) => return explain_calibration(e, spelling),
        PipelineError::TooFewFeatures {
            opposite_polarity: Some((polarity, _)),
            ..
        } => format!(
            "add {}, or check {} against the image",
            spelling.set(Pol, polarity_name(*polarity)),
            spelling.names(&[Lattice, Nn])
        ),
        PipelineError::TooFewFeatures { .. } | PipelineError::LatticeMismatch { .. } => format!(
            "check {} against the image, {}, and that the mask covers the atomically \
             resolved part",
            spelling.names(&[Lattice, Nn]),
            spelling.name(Pol)
        ),
        PipelineError::LatticeFit(_) => format!(
            "check {} against the image, or give {} over one domain",
            spelling.names(&[Lattice, Nn]),
            spelling.name(Mask)
        ),
        PipelineError::CorrectedScale {
            given_nn_m, scale, ..
        } => format!(
            "if the file's pixel size is right, use {} (or {}); if {} is right, the file's \
             pixel size is off: give it with {}",
            spelling.set(Nn, &length(given_nn_m * scale).replace(' ', "")),
            spelling.set(Nn, "auto"),
            length(*given_nn_m),
            spelling.name(PixelSize)
        ),
        PipelineError::Features(FeatureError::ImageTooSmall { .. }) => format!(
            "check {} and the pixel size ({})",
            spelling.name(Nn),
            spelling.name(PixelSize)
        ),
        _ => return error.to_string(),
    };
    format!("{error}\nhint: {hint}")
}

/// An options error (a config, lattice or mask that cannot be resolved), with the
/// options it is about named in `spelling`.
pub fn explain_options(error: &anyhow::Error, spelling: Spelling) -> String {
    use UserInput::{Lattice, NearestNeighbourDistance as Nn};
    match error.downcast_ref::<LatticeChoiceError>() {
        Some(LatticeChoiceError::NeedsConstant { name }) => format!(
            "{} needs {} (its nearest-neighbour distance, or auto)",
            spelling.set(Lattice, name),
            spelling.names(&[Nn])
        ),
        Some(e @ LatticeChoiceError::ImplausibleNn { .. }) => {
            format!("{}: {e}", spelling.names(&[Nn]))
        }
        Some(LatticeChoiceError::FileRescaled) => format!(
            "{} cannot rescale a lattice file; edit its vectors instead",
            spelling.names(&[Nn])
        ),
        None => format!("{error:#}"),
    }
}

/// The calibration's refusal with what to change, in `spelling`.
pub fn explain_calibration(error: &CalibrationError, spelling: Spelling) -> String {
    use UserInput::{CalibratePixelSize, Lattice, NearestNeighbourDistance as Nn, TrustInputs};
    let hint = match error {
        CalibrationError::WrongScale {
            given_nn_m,
            measured_nn_m,
            ..
        } => format!(
            "if the file's pixel size is right, use {} (or {}); if {} is right and the file's \
             pixel size is wrong, add {}; {} skips this check",
            spelling.set(Nn, &length(*measured_nn_m).replace(' ', "")),
            spelling.set(Nn, "auto"),
            length(*given_nn_m),
            spelling.switch(CalibratePixelSize),
            spelling.switch(TrustInputs)
        ),
        CalibrationError::WrongLatticeType { .. } => format!(
            "choose the lattice the image shows with {} ({} or a lattice file); {} skips this \
             check",
            spelling.name(Lattice),
            dhct_lattice::catalogue::names(),
            spelling.switch(TrustInputs)
        ),
        _ => return error.to_string(),
    };
    format!("{error}\nhint: {hint}")
}

fn polarity_name(polarity: Polarity) -> &'static str {
    match polarity {
        Polarity::Dark => "dark",
        Polarity::Bright => "bright",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_hint_is_spelled_for_each_front_end() {
        let error = PipelineError::TooFewFeatures {
            pass: "trace".into(),
            found: 29,
            needed: 30,
            opposite_polarity: Some((Polarity::Dark, 41)),
        };
        let cli = explain(&error, Spelling::CommandLine);
        assert!(
            cli.contains("hint: add --polarity dark, or check --lattice and --nn"),
            "{cli}"
        );
        let python = explain(&error, Spelling::Python);
        assert!(
            python.contains("hint: add polarity=\"dark\", or check lattice= and nn="),
            "{python}"
        );
        assert!(!python.contains("--"), "{python}");
    }
}
