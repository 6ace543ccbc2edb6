//! The raster scan: per-pixel acquisition times from [`ScanGeometry::acquisition_time`], the
//! summed tip displacement, and the height sampled at the displaced tip position.
//! Rows are processed in parallel with rayon; nothing depends on the scheduling.

use dhct_scan::{ScanGeometry, ScanPass};
use nalgebra::Vector2;
use ndarray::Array2;
use rayon::prelude::*;

use crate::effects::{AcquisitionContext, Effect, HeightEffect};
use crate::noise::{CorrelatedNoise, NoiseModel};
use crate::surface::{SampleArea, Surface, Terrace};

/// Sums the effects' displacements at a controller position.
///
/// Height-independent effects are summed first; if any effect reads the surface height,
/// the terrace height is taken at the tip position those give, and the height-dependent
/// effects are added with it.
#[derive(Debug, Clone, Copy)]
pub struct Displacer<'a> {
    geometry: &'a ScanGeometry,
    effects: &'a [Box<dyn Effect>],
    terrace: &'a Terrace,
    any_height_dependent: bool,
}

impl<'a> Displacer<'a> {
    /// A displacer for `effects` on `geometry` over a sample with `terrace`.
    pub fn new(
        geometry: &'a ScanGeometry,
        effects: &'a [Box<dyn Effect>],
        terrace: &'a Terrace,
    ) -> Displacer<'a> {
        Displacer {
            geometry,
            effects,
            terrace,
            any_height_dependent: effects.iter().any(|e| e.uses_surface_height()),
        }
    }

    /// The scan geometry.
    pub fn geometry(&self) -> &'a ScanGeometry {
        self.geometry
    }

    /// Total tip displacement (metres, display frame) with the controller at pixel
    /// position `(x, y)` (column, row; sub-pixel allowed) during `pass`.
    #[inline]
    pub fn displacement(&self, pass: ScanPass, x: f64, y: f64) -> Vector2<f64> {
        let mut at = AcquisitionContext::at_pixel(self.geometry, pass, x, y, 0.0);
        let mut d = Vector2::zeros();
        for effect in self.effects {
            if !effect.uses_surface_height() {
                d += effect.displacement(&at);
            }
        }
        if self.any_height_dependent {
            at.surface_height = self.terrace.height(at.controller + d);
            for effect in self.effects {
                if effect.uses_surface_height() {
                    d += effect.displacement(&at);
                }
            }
        }
        d
    }
}

/// The displacement field of one pass on the pixel grid: `dx`, `dy` (metres), shape
/// `(rows, columns)`, display orientation.
pub(crate) fn displacement_field(
    displacer: &Displacer,
    pass: ScanPass,
) -> (Array2<f64>, Array2<f64>) {
    let geometry = displacer.geometry();
    let (rows, columns) = (geometry.rows(), geometry.columns());
    let mut dx = vec![0.0; rows * columns];
    let mut dy = vec![0.0; rows * columns];
    dx.par_chunks_mut(columns)
        .zip(dy.par_chunks_mut(columns))
        .enumerate()
        .for_each(|(row, (dx_row, dy_row))| {
            for column in 0..columns {
                let d = displacer.displacement(pass, column as f64, row as f64);
                dx_row[column] = d.x;
                dy_row[column] = d.y;
            }
        });
    (to_array(rows, columns, dx), to_array(rows, columns, dy))
}

fn to_array(rows: usize, columns: usize, values: Vec<f64>) -> Array2<f64> {
    Array2::from_shape_vec((rows, columns), values)
        .unwrap_or_else(|_| unreachable!("the buffer has rows × columns values"))
}

/// The sample-frame bounding box of every pixel's tip position over the given fields.
pub(crate) fn visited_area(
    geometry: &ScanGeometry,
    fields: &[(Array2<f64>, Array2<f64>)],
) -> SampleArea {
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for (dx, dy) in fields {
        for ((row, column), &x) in dx.indexed_iter() {
            let px = column as f64 * geometry.pitch_x() + x;
            let py = row as f64 * geometry.pitch_y() + dy[[row, column]];
            lo = [lo[0].min(px), lo[1].min(py)];
            hi = [hi[0].max(px), hi[1].max(py)];
        }
    }
    SampleArea {
        min_m: lo,
        max_m: hi,
    }
}

/// Everything [`render`] needs for one pass.
pub(crate) struct RenderInput<'a> {
    pub geometry: &'a ScanGeometry,
    pub pass: ScanPass,
    pub surface: &'a Surface,
    pub dx: &'a Array2<f64>,
    pub dy: &'a Array2<f64>,
    pub height_effects: &'a [Box<dyn HeightEffect>],
    pub noise: &'a NoiseModel,
    pub correlated: &'a CorrelatedNoise,
}

/// The measured image of one pass (metres): the surface height at each pixel's displaced
/// tip position, then height effects, then noise.
pub(crate) fn render(input: &RenderInput) -> Array2<f64> {
    let geometry = input.geometry;
    let (rows, columns) = (geometry.rows(), geometry.columns());
    let (pitch_x, pitch_y) = (geometry.pitch_x(), geometry.pitch_y());
    let mut z = vec![0.0; rows * columns];
    z.par_chunks_mut(columns)
        .enumerate()
        .for_each(|(row, z_row)| {
            let dx = input.dx.row(row);
            let dy = input.dy.row(row);
            for (column, value) in z_row.iter_mut().enumerate() {
                let tip = Vector2::new(
                    column as f64 * pitch_x + dx[column],
                    row as f64 * pitch_y + dy[column],
                );
                let mut height = input.surface.height(tip);
                if !input.height_effects.is_empty() {
                    let at = AcquisitionContext::at_pixel(
                        geometry,
                        input.pass,
                        column as f64,
                        row as f64,
                        input.surface.terrace().height(tip),
                    );
                    for effect in input.height_effects {
                        height = effect.apply(height, &at);
                    }
                }
                *value = height;
            }
            input
                .noise
                .add_to_row(geometry, input.pass, row, z_row, input.correlated);
        });
    to_array(rows, columns, z)
}
