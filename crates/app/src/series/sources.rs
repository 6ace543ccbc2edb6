//! The frames a series is made of: each file, or each frame of a file that holds several
//! recorded one after another (a SPECS `.mul` or `.flm` film, an Omicron MATRIX file with
//! its upward and downward frames), told apart by [`dhct_scan::ScanGeometry::frame`].

use std::fmt;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use dhct_scan::{ScanFile, ScanPair};

use super::SeriesRequest;
use crate::setup::CorrectConfig;

/// One frame of a series: a file, or one frame of a file of several.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FrameSource {
    /// Its file.
    pub path: PathBuf,
    /// Which of the file's frames (`None`: the file holds one).
    pub frame: Option<usize>,
}

impl fmt::Display for FrameSource {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.frame {
            None => write!(f, "{}", self.path.display()),
            Some(k) => write!(f, "{} (frame {} of the file)", self.path.display(), k + 1),
        }
    }
}

impl FrameSource {
    /// Its scan pair: the config's channel (or the topography) among the pairs of its
    /// frame, with the config's geometry overrides.
    pub fn read(&self, config: &CorrectConfig) -> Result<ScanPair> {
        let Some(frame) = self.frame else {
            return crate::setup::read_pair(
                &self.path,
                None,
                &config.geometry,
                config.channel.as_deref(),
            );
        };
        let file = read_file(&self.path, config)?;
        let pairs = frame_pairs(file, frame);
        pairs
            .channel_or_topography(config.channel.as_deref())
            .cloned()
            .with_context(|| self.to_string())
    }
}

fn read_file(path: &Path, config: &CorrectConfig) -> Result<ScanFile> {
    dhct_sm4_io::read_path_with_limits(path, &config.geometry, &crate::read_limits::get())
        .with_context(|| format!("cannot read {}", path.display()))
}

/// `file` with the pairs of frame `frame` only.
fn frame_pairs(file: ScanFile, frame: usize) -> ScanFile {
    ScanFile {
        pairs: file
            .pairs
            .into_iter()
            .filter(|p| p.geometry().frame() == frame)
            .collect(),
        ..file
    }
}

/// The frames `request`'s inputs hold (folders, globs and files as `dhct batch` finds
/// them; each file, or each frame of a file of several), at least two; the inputs skipped
/// are noted on stderr.
pub fn find_frames(request: &SeriesRequest) -> Result<Vec<FrameSource>> {
    let found = crate::batch::inputs::find(request.inputs, request.output)?;
    for s in &found.skipped {
        eprintln!("note: skipping {}: {}", s.path.display(), s.note);
    }
    let paths: Vec<PathBuf> = found.scans.iter().map(|s| s.path.clone()).collect();
    let sources = expand(&paths, &request.config)?;
    if sources.len() < 2 {
        bail!(
            "a series needs at least two frames, {} found in {}: one frame is corrected by \
             `dhct correct`",
            sources.len(),
            request.inputs.join(", ")
        );
    }
    Ok(sources)
}

/// Every frame of `paths` in order: a file of one frame as itself, a file of several as
/// each of its frames that holds the config's channel (or a topography), in file order.
fn expand(paths: &[PathBuf], config: &CorrectConfig) -> Result<Vec<FrameSource>> {
    let mut sources = Vec::new();
    for path in paths {
        let file = read_file(path, config)?;
        let mut frames: Vec<usize> = file.pairs.iter().map(|p| p.geometry().frame()).collect();
        frames.sort_unstable();
        frames.dedup();
        if frames.len() <= 1 {
            sources.push(FrameSource {
                path: path.clone(),
                frame: None,
            });
            continue;
        }
        for frame in frames {
            let pairs = frame_pairs(file.clone(), frame);
            if pairs
                .channel_or_topography(config.channel.as_deref())
                .is_ok()
            {
                sources.push(FrameSource {
                    path: path.clone(),
                    frame: Some(frame),
                });
            }
        }
    }
    Ok(sources)
}
