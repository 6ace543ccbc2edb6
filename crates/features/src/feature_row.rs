//! One feature as a row of `features.csv`: the single list of its columns, used by every
//! writer of the table (this crate's [`crate::FeatureSet::write_csv`], the application's
//! `features.csv` and Python's `Result.features`).

use serde::ser::{Serialize, SerializeStruct, Serializer};
use serde::{Deserialize, Serialize as DeriveSerialize};

use std::io::Write;

use crate::{Feature, FeatureSet};

/// A feature's lattice site and its deviation from it (sample frame), once the lattice has
/// been fitted and the feature indexed.
#[derive(Debug, Clone, Copy, PartialEq, DeriveSerialize, Deserialize)]
pub struct FeatureIndex {
    /// Region of the lattice fit (domain number, largest first).
    pub region: usize,
    /// Cell index along a1.
    pub n: i64,
    /// Cell index along a2.
    pub m: i64,
    /// Motif site.
    pub site: usize,
    /// Corrected position − fitted site, metres.
    pub deviation_m: [f64; 2],
}

/// Where a feature ended up after the distortion correction and the lattice fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FeaturePlacement {
    /// Position in the sample frame, metres `[x, y]`.
    pub corrected_m: [f64; 2],
    /// Its lattice site, when indexed.
    pub index: Option<FeatureIndex>,
}

/// One value of a [`FeatureRow`]; `None` is an empty cell (a quantity not known here).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Cell<'a> {
    /// A count or an index.
    Int(Option<i64>),
    /// A measured quantity (NaN stays NaN: a quantity that could not be measured).
    Float(Option<f64>),
    /// A name (`trace`, `ok`, ...).
    Text(&'a str),
}

/// One feature as a row of `features.csv`. Positions are in the controller frame of the
/// feature's image (x = column, y = row, metres = px · pitch) unless named `corrected_`;
/// z values are in the channel's unit (metres for topography). The correction and
/// lattice columns are empty when the features were not placed (the features stage used
/// alone) or not indexed. The fitted Gaussian's magnitude is `|height|`.
#[derive(Debug, Clone, Copy)]
pub struct FeatureRow<'a> {
    /// The fitted feature.
    pub feature: &'a Feature,
    /// Where it ended up, when the whole pipeline ran.
    pub placement: Option<FeaturePlacement>,
}

impl<'a> FeatureRow<'a> {
    /// The row of a feature found by this crate alone.
    pub fn of(feature: &'a Feature) -> Self {
        Self {
            feature,
            placement: None,
        }
    }

    /// Every column in order: name and value.
    pub fn cells(&self) -> [(&'static str, Cell<'a>); 29] {
        use Cell::{Float, Int, Text};
        let f = self.feature;
        let count = |v: usize| Int(Some(v as i64));
        let corrected = self.placement.map(|p| p.corrected_m);
        let index = self.placement.and_then(|p| p.index);
        [
            ("id", count(f.id)),
            ("pass", Text(f.pass.name())),
            ("x_px", Float(Some(f.x_px))),
            ("y_px", Float(Some(f.y_px))),
            ("x_m", Float(Some(f.x_m))),
            ("y_m", Float(Some(f.y_m))),
            ("x_sigma_px", Float(Some(f.x_sigma_px))),
            ("y_sigma_px", Float(Some(f.y_sigma_px))),
            ("sigma_major_px", Float(Some(f.sigma_major_px))),
            ("sigma_minor_px", Float(Some(f.sigma_minor_px))),
            ("theta_rad", Float(Some(f.theta_rad))),
            ("height", Float(Some(f.height))),
            ("z0", Float(Some(f.z0))),
            ("removed_level", Float(Some(f.removed_level))),
            ("residual_rms", Float(Some(f.residual_rms))),
            ("pixel_count", count(f.pixel_count)),
            ("ncc_peak", Float(Some(f.ncc_peak))),
            ("status", Text(f.status.name())),
            ("fit_iterations", count(f.fit_iterations)),
            ("time_s", Float(Some(f.time_s))),
            ("line_time_s", Float(Some(f.line_time_s))),
            ("corrected_x_m", Float(corrected.map(|c| c[0]))),
            ("corrected_y_m", Float(corrected.map(|c| c[1]))),
            ("region", Int(index.map(|i| i.region as i64))),
            ("n", Int(index.map(|i| i.n))),
            ("m", Int(index.map(|i| i.m))),
            ("site", Int(index.map(|i| i.site as i64))),
            ("deviation_x_m", Float(index.map(|i| i.deviation_m[0]))),
            ("deviation_y_m", Float(index.map(|i| i.deviation_m[1]))),
        ]
    }
}

impl FeatureSet {
    /// Writes the features as CSV, one [`FeatureRow`] each, with a header line (the
    /// correction and lattice columns empty: this crate does not place features).
    pub fn write_csv<W: Write>(&self, w: W) -> std::io::Result<()> {
        let mut writer = csv::Writer::from_writer(w);
        for f in &self.features {
            writer
                .serialize(FeatureRow::of(f))
                .map_err(std::io::Error::other)?;
        }
        writer.flush()
    }
}

impl Serialize for Cell<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match *self {
            Cell::Int(Some(v)) => s.serialize_i64(v),
            Cell::Float(Some(v)) => s.serialize_f64(v),
            Cell::Text(v) => s.serialize_str(v),
            Cell::Int(None) | Cell::Float(None) => s.serialize_none(),
        }
    }
}

/// Serialised as a flat record of [`FeatureRow::cells`] (what the `csv` crate writes).
impl Serialize for FeatureRow<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let cells = self.cells();
        let mut row = s.serialize_struct("FeatureRow", cells.len())?;
        for (name, cell) in cells {
            row.serialize_field(name, &cell)?;
        }
        row.end()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::FitStatus;
    use dhct_scan::ScanPass;

    fn feature() -> Feature {
        Feature {
            id: 7,
            pass: ScanPass::Retrace,
            x_px: 1.5,
            y_px: 2.5,
            x_m: 1.5e-11,
            y_m: 2.5e-11,
            x_sigma_px: 0.1,
            y_sigma_px: 0.2,
            sigma_major_px: 3.0,
            sigma_minor_px: 2.0,
            theta_rad: 0.25,
            amplitude: 1e-11,
            height: -1e-11,
            z0: 0.0,
            removed_level: 0.0,
            residual_rms: 1e-12,
            pixel_count: 40,
            ncc_peak: 0.9,
            status: FitStatus::IterationLimit,
            fit_iterations: 12,
            time_s: 3.0,
            line_time_s: 0.01,
        }
    }

    fn csv_of(row: FeatureRow) -> String {
        let mut w = csv::Writer::from_writer(Vec::new());
        w.serialize(row).unwrap();
        String::from_utf8(w.into_inner().unwrap()).unwrap()
    }

    #[test]
    fn status_names_are_the_serde_names() {
        for status in [
            FitStatus::Converged,
            FitStatus::IterationLimit,
            FitStatus::CentreOnBound,
            FitStatus::BadShape,
            FitStatus::Failed,
            FitStatus::ConvergedCircular,
        ] {
            assert_eq!(serde_json::to_value(status).unwrap(), status.name());
        }
    }

    #[test]
    fn an_unplaced_feature_leaves_the_pipeline_columns_empty() {
        let f = feature();
        let text = csv_of(FeatureRow::of(&f));
        let mut lines = text.lines();
        assert!(lines.next().unwrap().starts_with("id,pass,x_px,"));
        let row: Vec<&str> = lines.next().unwrap().split(',').collect();
        assert_eq!(&row[..3], ["7", "retrace", "1.5"]);
        assert_eq!(row[17], "iteration-limit");
        assert!(row[21..].iter().all(|c| c.is_empty()), "{row:?}");
    }

    #[test]
    fn a_placed_feature_fills_them() {
        let f = feature();
        let index = FeatureIndex {
            region: 0,
            n: -3,
            m: 4,
            site: 1,
            deviation_m: [1e-12, -2e-12],
        };
        let placed = |index| FeatureRow {
            feature: &f,
            placement: Some(FeaturePlacement {
                corrected_m: [2e-11, 3e-11],
                index,
            }),
        };
        let text = csv_of(placed(Some(index)));
        let row = text.lines().nth(1).unwrap();
        assert!(row.ends_with(",2e-11,3e-11,0,-3,4,1,1e-12,-2e-12"), "{row}");
        let text = csv_of(placed(None));
        assert!(text.lines().nth(1).unwrap().ends_with(",2e-11,3e-11,,,,,,"));
    }
}
