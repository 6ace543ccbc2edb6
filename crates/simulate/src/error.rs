//! The simulator's error type and the validation helpers that produce it.

use std::path::PathBuf;

use dhct_lattice::LatticeError;
use dhct_scan::GeometryError;
use dhct_sm4_io::WriteError;
use thiserror::Error;

/// Why a simulation could not be configured, run or written.
#[derive(Debug, Error)]
pub enum SimulationError {
    /// A configuration value is out of range; `field` is its path in the config file,
    /// e.g. `scan.width_m` or `effects[2].t0_s`.
    #[error("invalid simulation config: {field}: {reason}")]
    InvalidConfig {
        /// The value's path in the config file.
        field: String,
        /// What is wrong with it.
        reason: String,
    },
    /// The config text is not valid TOML/JSON or does not match the schema (unknown effect
    /// kind, misspelt field, wrong type, negative integer size ...).
    #[error("cannot parse simulation config{}: {message}", path_suffix(.path))]
    Parse {
        /// The config file, when it was read from a path.
        path: Option<PathBuf>,
        /// The parser's message.
        message: String,
    },
    /// The config file could not be read.
    #[error("cannot read simulation config {path}")]
    Io {
        /// The file that could not be read.
        path: PathBuf,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
    /// No built-in preset has this name.
    #[error("unknown preset '{name}' (known presets: {known})")]
    UnknownPreset {
        /// The name asked for.
        name: String,
        /// The known preset names, comma-separated.
        known: String,
    },
    /// The configured scan geometry is invalid.
    #[error("invalid scan geometry")]
    Geometry(#[from] GeometryError),
    /// The configured lattice is invalid.
    #[error("invalid lattice")]
    Lattice(#[from] LatticeError),
    /// Writing the simulated image or its ground truth failed.
    #[error("cannot write simulation output")]
    Write(#[from] WriteError),
    /// [`crate::Effect::with_parameters`] got a parameter vector of the wrong length.
    #[error("effect {effect} takes {expected} parameters, got {got}")]
    ParameterCount {
        /// The effect's name.
        effect: &'static str,
        /// Parameters the effect takes.
        expected: usize,
        /// Parameters given.
        got: usize,
    },
}

fn path_suffix(path: &Option<PathBuf>) -> String {
    path.as_ref()
        .map(|p| format!(" {}", p.display()))
        .unwrap_or_default()
}

pub(crate) fn invalid(field: impl Into<String>, reason: impl Into<String>) -> SimulationError {
    SimulationError::InvalidConfig {
        field: field.into(),
        reason: reason.into(),
    }
}

/// `value` must be finite.
pub(crate) fn finite(field: &str, value: f64) -> Result<(), SimulationError> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(invalid(field, format!("must be finite, got {value}")))
    }
}

/// Both components must be finite.
pub(crate) fn finite2(field: &str, value: [f64; 2]) -> Result<(), SimulationError> {
    if value.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(invalid(field, format!("must be finite, got {value:?}")))
    }
}

/// `value` must be finite and > 0.
pub(crate) fn positive(field: &str, value: f64) -> Result<(), SimulationError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(invalid(
            field,
            format!("must be finite and positive, got {value}"),
        ))
    }
}

/// `value` must be finite and ≥ 0.
pub(crate) fn non_negative(field: &str, value: f64) -> Result<(), SimulationError> {
    if value.is_finite() && value >= 0.0 {
        Ok(())
    } else {
        Err(invalid(
            field,
            format!("must be finite and non-negative, got {value}"),
        ))
    }
}

/// `value` must lie in `[0, 1]`.
pub(crate) fn fraction(field: &str, value: f64) -> Result<(), SimulationError> {
    if (0.0..=1.0).contains(&value) {
        Ok(())
    } else {
        Err(invalid(field, format!("must lie in [0, 1], got {value}")))
    }
}

/// Checks a parameter vector's length for [`crate::Effect::with_parameters`].
pub(crate) fn parameter_count(
    effect: &'static str,
    parameters: &[f64],
    expected: usize,
) -> Result<(), SimulationError> {
    if parameters.len() == expected {
        Ok(())
    } else {
        Err(SimulationError::ParameterCount {
            effect,
            expected,
            got: parameters.len(),
        })
    }
}
