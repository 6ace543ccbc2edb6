//! Step 5: the local cells selected by their corner features, averaged over the corrected
//! images and symmetry-averaged.

use dhct_features::{Feature, FeatureSet};
use dhct_lattice::Lattice;
use dhct_scan::ScanPair;
use dhct_unitcell::{
    AveragedCell, LocalCell, asymmetric_unit, average_unit_cell, operations, symmetrize,
    symmetry_residuals,
};
use ndarray::Array2;

use crate::{CellSelection, PipelineOptions, RegionFit, UnitCellAnalysis};

/// Median and robust standard deviation (1.4826 × MAD).
fn robust_location(values: &[f64]) -> (f64, f64) {
    use dhct_numerics::robust::{finite_median, mad_sigma_about};
    match finite_median(values.iter().copied()) {
        Some(median) => (median, mad_sigma_about(values, median).unwrap_or(f64::NAN)),
        None => (f64::NAN, f64::NAN),
    }
}

/// Whether a cell's corner features pass the selection.
fn keep_cell(
    cell: &LocalCell,
    features: &[Feature],
    members: &[usize],
    selection: &CellSelection,
    height_stats: (f64, f64),
    width_stats: (f64, f64),
) -> bool {
    cell.corners.iter().all(|&corner| {
        let f = &features[members[corner]];
        let in_range =
            |range: Option<[f64; 2]>, v: f64| range.is_none_or(|[lo, hi]| v >= lo && v <= hi);
        let typical = |stats: (f64, f64), v: f64, k: f64| {
            stats.1.is_nan() || stats.1 <= 0.0 || (v - stats.0).abs() <= k * stats.1
        };
        in_range(selection.height_m, f.height)
            && in_range(selection.width_px, f.sigma_major_px)
            && selection.exclude_outliers_sigma.is_none_or(|k| {
                typical(height_stats, f.height, k) && typical(width_stats, f.sigma_major_px, k)
            })
    })
}

/// The averaged and symmetry-averaged unit cell of the corrected images: per image, the
/// local cells of every region that pass the cell selection averaged; the images' averages
/// combined; symmetrised with the plane group (the lattice's unless given). An error
/// (a note for the report) when no cell was selected or a step fails.
pub(crate) fn unit_cell_analysis(
    pair: &ScanPair,
    lattice: &dyn Lattice,
    options: &PipelineOptions,
    sets: &[&FeatureSet],
    regions: &[RegionFit],
    corrected_images: &[&Array2<f64>],
) -> Result<UnitCellAnalysis, String> {
    let geometry = pair.geometry();
    let selection = &options.unit_cell.selection;
    let mut available = 0;
    let mut averages: Vec<AveragedCell> = Vec::new();
    for (slot, set) in sets.iter().enumerate() {
        let heights: Vec<f64> = set.features.iter().map(|f| f.height).collect();
        let widths: Vec<f64> = set.features.iter().map(|f| f.sigma_major_px).collect();
        let (height_stats, width_stats) = (robust_location(&heights), robust_location(&widths));
        let mut kept = Vec::new();
        for region in regions {
            let Some(k) = region.passes.iter().position(|&p| p == set.pass) else {
                continue;
            };
            available += region.local_cells[k].len();
            kept.extend(
                region.local_cells[k]
                    .iter()
                    .filter(|cell| {
                        keep_cell(
                            cell,
                            &set.features,
                            &region.members[k],
                            selection,
                            height_stats,
                            width_stats,
                        )
                    })
                    .cloned(),
            );
        }
        if kept.is_empty() {
            continue;
        }
        match average_unit_cell(
            corrected_images[slot].view(),
            (geometry.pitch_x(), geometry.pitch_y()),
            lattice,
            &kept,
            options.unit_cell.resolution,
        ) {
            Ok(average) => averages.push(average),
            Err(e) => return Err(format!("averaging the {} cells failed: {e}", set.pass)),
        }
    }
    if averages.is_empty() {
        return Err(format!(
            "no local cell was selected ({available} found): every cell needs its four corner \
             features indexed{}",
            if available > 0 {
                "; loosen the cell selection"
            } else {
                ""
            }
        ));
    }
    let averaged = weighted_mean(&averages);
    let cells = averaged.cells;
    let group = options
        .unit_cell
        .plane_group
        .unwrap_or_else(|| lattice.plane_group());
    let ops = operations(group, lattice).map_err(|e| e.to_string())?;
    let symmetrized = symmetrize(&averaged, &ops).map_err(|e| e.to_string())?;
    let residuals = symmetry_residuals(&averaged, lattice).map_err(|e| e.to_string())?;
    let asymmetric_unit = asymmetric_unit(group, lattice).map_err(|e| e.to_string())?;
    Ok(UnitCellAnalysis {
        group,
        averaged,
        symmetrized,
        residuals,
        asymmetric_unit,
        cells_available: available,
        cells_selected: cells,
    })
}

/// Cell-count weighted mean of the per-image averages (`averages` not empty).
fn weighted_mean(averages: &[AveragedCell]) -> AveragedCell {
    let cells: usize = averages.iter().map(|a| a.cells).sum();
    let skipped: usize = averages.iter().map(|a| a.skipped).sum();
    let mut values = Array2::zeros(averages[0].values.dim());
    for a in averages {
        values.scaled_add(a.cells as f64 / cells as f64, &a.values);
    }
    AveragedCell {
        values,
        cells,
        skipped,
    }
}
