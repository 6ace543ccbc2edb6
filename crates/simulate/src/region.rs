//! Regions of the sample (second domain, upper terrace of a step, strained area).

use nalgebra::Vector2;
use serde::{Deserialize, Serialize};

use crate::SimulationError;
use crate::error::{finite2, invalid, positive};

/// An area of the sample, in the sample frame (metres; x right, y down, origin at the
/// centre of pixel (0, 0) — the controller frame when nothing is displaced).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "shape", rename_all = "kebab-case", deny_unknown_fields)]
pub enum Region {
    /// Everything on the side of the line through `point_m` that `normal` points to.
    HalfPlane {
        /// A point on the boundary, metres.
        point_m: [f64; 2],
        /// Direction pointing into the region (any length ≠ 0).
        normal: [f64; 2],
    },
    /// The axis-aligned rectangle `min_m ≤ p ≤ max_m`.
    Rectangle {
        /// Lower corner `[x, y]`, metres.
        min_m: [f64; 2],
        /// Upper corner `[x, y]`, metres.
        max_m: [f64; 2],
    },
    /// The disc of radius `radius_m` around `centre_m`.
    Circle {
        /// Centre `[x, y]`, metres.
        centre_m: [f64; 2],
        /// Radius, metres (> 0).
        radius_m: f64,
    },
}

impl Region {
    /// Checks the shape is well defined.
    pub fn validate(&self, field: &str) -> Result<(), SimulationError> {
        match self {
            Region::HalfPlane { point_m, normal } => {
                finite2(&format!("{field}.point_m"), *point_m)?;
                finite2(&format!("{field}.normal"), *normal)?;
                if normal[0] == 0.0 && normal[1] == 0.0 {
                    return Err(invalid(format!("{field}.normal"), "must not be zero"));
                }
                Ok(())
            }
            Region::Rectangle { min_m, max_m } => {
                finite2(&format!("{field}.min_m"), *min_m)?;
                finite2(&format!("{field}.max_m"), *max_m)?;
                if min_m[0] >= max_m[0] || min_m[1] >= max_m[1] {
                    return Err(invalid(
                        format!("{field}.max_m"),
                        format!("must exceed min_m {min_m:?} in x and y, got {max_m:?}"),
                    ));
                }
                Ok(())
            }
            Region::Circle { centre_m, radius_m } => {
                finite2(&format!("{field}.centre_m"), *centre_m)?;
                positive(&format!("{field}.radius_m"), *radius_m)
            }
        }
    }

    /// Signed distance (metres) from `p` to the boundary: positive inside, negative
    /// outside (for a rectangle, exact outside and the distance to the nearest side inside).
    pub fn signed_distance(&self, p: Vector2<f64>) -> f64 {
        match self {
            Region::HalfPlane { point_m, normal } => {
                let n = Vector2::new(normal[0], normal[1]);
                (p - Vector2::new(point_m[0], point_m[1])).dot(&n) / n.norm()
            }
            Region::Rectangle { min_m, max_m } => {
                let inside_x = (p.x - min_m[0]).min(max_m[0] - p.x);
                let inside_y = (p.y - min_m[1]).min(max_m[1] - p.y);
                if inside_x >= 0.0 && inside_y >= 0.0 {
                    inside_x.min(inside_y)
                } else {
                    let ox = inside_x.min(0.0);
                    let oy = inside_y.min(0.0);
                    -(ox * ox + oy * oy).sqrt()
                }
            }
            Region::Circle { centre_m, radius_m } => {
                radius_m - (p - Vector2::new(centre_m[0], centre_m[1])).norm()
            }
        }
    }

    /// True if `p` lies in the region (boundary included).
    pub fn contains(&self, p: Vector2<f64>) -> bool {
        self.signed_distance(p) >= 0.0
    }
}
