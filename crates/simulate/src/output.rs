//! What a simulation produces, and writing it to a directory. Every file is written
//! atomically (temporary file, then rename), so a crash never leaves a half-written file.

use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};

use dhct_scan::{FileFormat, ImageChannel, ScanFile, ScanPair, ScanPass};
use dhct_sm4_io::png_file::Colormap;
use dhct_sm4_io::{WriteError, gsf, npy, png_file, sm4, write_atomically};

use crate::config::OutputFormat;
use crate::{GroundTruth, SimulationError};

/// File name of the ground truth.
pub const GROUND_TRUTH_FILE: &str = "ground_truth.json";

/// File name of the SM4 file.
pub const SM4_FILE: &str = "simulation.sm4";

/// The result of [`crate::Simulation::run`].
#[derive(Debug, Clone, PartialEq)]
pub struct SimulationOutput {
    /// The simulated trace and retrace topography (metres), display orientation.
    pub pair: ScanPair,
    /// Everything known about how they were made.
    pub truth: GroundTruth,
}

impl SimulationOutput {
    /// The pair as a [`ScanFile`] (format SM4) with the simulation named in the metadata.
    pub fn scan_file(&self) -> ScanFile {
        let mut metadata = BTreeMap::new();
        metadata.insert("generator".to_string(), self.truth.generator.clone());
        metadata.insert("simulation".to_string(), self.truth.config.name.clone());
        metadata.insert("seed".to_string(), self.truth.config.seed.to_string());
        ScanFile {
            format: FileFormat::RhkSm4,
            pairs: vec![self.pair.clone()],
            metadata,
        }
    }

    /// Writes into `dir` (created if missing) the images in the config's output formats
    /// (`simulation.sm4`; `trace.gsf`/`retrace.gsf`; `trace.npy`/`retrace.npy`;
    /// `trace.png`/`retrace.png`), the ground truth `ground_truth.json`, and the true
    /// displacement fields `displacement_{trace,retrace}_{dx,dy}.npy` (metres, float64,
    /// shape rows × columns). Returns the paths written.
    pub fn write(&self, dir: &Path) -> Result<Vec<PathBuf>, SimulationError> {
        let mut written = self.write_images(dir, None)?;
        for field in &self.truth.displacement {
            for (component, channel) in [("dx", &field.dx), ("dy", &field.dy)] {
                let path = dir.join(format!(
                    "displacement_{}_{component}.npy",
                    field.pass.name()
                ));
                write_atomically(&path, |w| npy::write(channel, w))?;
                written.push(path);
            }
        }
        let path = dir.join(GROUND_TRUTH_FILE);
        write_json(&path, &self.truth)?;
        written.push(path);
        Ok(written)
    }

    /// Writes into `dir` (created if missing) the images in the config's output formats.
    /// Without a `prefix`: `simulation.sm4`, `trace.gsf`/`retrace.gsf`,
    /// `trace.npy`/`retrace.npy` (with `trace.json`/`retrace.json` sidecars),
    /// `trace.png`/`retrace.png`; with prefix `P`: `P.sm4`, `P_trace.gsf`, … Returns the
    /// paths written.
    pub fn write_images(
        &self,
        dir: &Path,
        prefix: Option<&str>,
    ) -> Result<Vec<PathBuf>, SimulationError> {
        std::fs::create_dir_all(dir).map_err(|source| WriteError::Io {
            path: dir.to_path_buf(),
            source,
        })?;
        let name = |pass: ScanPass, extension: &str| match prefix {
            Some(prefix) => format!("{prefix}_{}.{extension}", pass.name()),
            None => format!("{}.{extension}", pass.name()),
        };
        let mut written = Vec::new();
        let mut formats = self.truth.config.output.formats.clone();
        formats.dedup();
        for format in formats {
            match format {
                OutputFormat::Sm4 => {
                    let path =
                        dir.join(prefix.map_or(SM4_FILE.to_string(), |p| format!("{p}.sm4")));
                    let file = self.scan_file();
                    write_atomically(&path, |w| sm4::write(&file, w))?;
                    written.push(path);
                }
                OutputFormat::Gsf => {
                    for (pass, image) in self.pair.images() {
                        let path = dir.join(name(pass, "gsf"));
                        write_atomically(&path, |w| {
                            gsf::write_pass(image, self.pair.geometry(), pass, w)
                        })?;
                        written.push(path);
                    }
                }
                OutputFormat::Npy => {
                    for (pass, image) in self.pair.images() {
                        let path = dir.join(name(pass, "npy"));
                        write_atomically(&path, |w| npy::write(image, w))?;
                        written.push(path);
                        // NPY has no place for the pixel size, unit and directions.
                        let sidecar =
                            npy::Sidecar::new(image, self.pair.geometry(), pass, Vec::new());
                        let path = dir.join(name(pass, "json"));
                        write_json(&path, &sidecar)?;
                        written.push(path);
                    }
                }
                OutputFormat::Png => {
                    for (pass, image) in self.pair.images() {
                        let path = dir.join(name(pass, "png"));
                        write_png(&path, image)?;
                        written.push(path);
                    }
                }
            }
        }
        Ok(written)
    }
}

/// Writes a colour-mapped (gold) preview of `image`.
pub fn write_png(path: &Path, image: &ImageChannel) -> Result<(), SimulationError> {
    write_atomically(path, |w| {
        png_file::write_colormap(image, Colormap::Gold, w).map(|_| ())
    })?;
    Ok(())
}

/// Writes `value` as pretty JSON with a final newline, atomically.
pub(crate) fn write_json<T: serde::Serialize>(
    path: &Path,
    value: &T,
) -> Result<(), SimulationError> {
    write_atomically(path, |w| {
        serde_json::to_writer_pretty(&mut *w, value)
            .map_err(|e| WriteError::Stream(std::io::Error::other(e)))?;
        w.write_all(b"\n")?;
        Ok(())
    })?;
    Ok(())
}
