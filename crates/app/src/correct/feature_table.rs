//! `features.csv`: one [`FeatureRow`] per feature of every image (the columns are
//! dhct-features' single list, documented in docs/outputs.md), written with the `csv`
//! crate.

use std::path::Path;

use anyhow::Result;
use dhct_features::{FeaturePlacement, FeatureRow};
use dhct_pipeline::{Analysis, PassOutput};
use dhct_sm4_io::{WriteError, write_atomically};

/// File name in the output directory.
pub const FEATURES_CSV: &str = "features.csv";

/// The row of feature `k` of `pass`: the feature, where the correction put it and its
/// lattice site.
pub fn feature_row(pass: &PassOutput, k: usize) -> FeatureRow<'_> {
    FeatureRow {
        feature: &pass.features.features[k],
        placement: pass.corrected.get(k).map(|c| FeaturePlacement {
            corrected_m: [c.x_m, c.y_m],
            index: pass.indices.get(k).copied().flatten(),
        }),
    }
}

/// Writes `features.csv` into `dir`; returns its name.
pub fn write_features_csv(dir: &Path, analysis: &Analysis) -> Result<String> {
    write_atomically(&dir.join(FEATURES_CSV), |w| {
        let mut writer = csv::Writer::from_writer(w);
        for pass in &analysis.passes {
            for k in 0..pass.features.features.len() {
                writer
                    .serialize(feature_row(pass, k))
                    .map_err(|e| WriteError::from(std::io::Error::other(e)))?;
            }
        }
        writer.flush()?;
        Ok(())
    })?;
    Ok(FEATURES_CSV.to_string())
}
