use serde::{Deserialize, Serialize};

/// One imaged feature of the unit cell.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MotifSite {
    /// Position as fractions of the primitive vectors `(f1, f2)`: `f1·a1 + f2·a2`.
    pub fractional: [f64; 2],
    /// Apparent height relative to the brightest site (1 = brightest), for simulation and
    /// for telling sites apart.
    #[serde(default = "unit_height")]
    pub relative_height: f64,
    /// A label, e.g. "A" and "B" for the graphene sublattices.
    #[serde(default)]
    pub label: String,
}

fn unit_height() -> f64 {
    1.0
}

impl MotifSite {
    /// A site at fractional position `(f1, f2)` with relative height 1.
    pub fn new(f1: f64, f2: f64, label: impl Into<String>) -> MotifSite {
        MotifSite {
            fractional: [f1, f2],
            relative_height: 1.0,
            label: label.into(),
        }
    }
}
