//! Choosing one channel of a file by name.

use thiserror::Error;

use crate::{ScanFile, ScanPair};

/// The file holds no channel of the name asked for (or, when none was named, no image).
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[error(
    "{}",
    match .wanted {
        Some(wanted) => format!("no channel '{wanted}' in the file; it holds {}", list(.available)),
        None => "the file holds no image".to_string(),
    }
)]
pub struct NoSuchChannel {
    /// The name asked for (`None`: the topography was asked for).
    pub wanted: Option<String>,
    /// The names of the file's channels, in file order.
    pub available: Vec<String>,
}

fn list(names: &[String]) -> String {
    if names.is_empty() {
        return "no channel".to_string();
    }
    names
        .iter()
        .map(|n| format!("'{n}'"))
        .collect::<Vec<_>>()
        .join(", ")
}

impl ScanFile {
    /// The channel called `name`: compared case-insensitively, a channel whose whole name
    /// matches first, else the first channel whose name contains `name`.
    pub fn channel(&self, name: &str) -> Result<&ScanPair, NoSuchChannel> {
        let wanted = name.to_lowercase();
        let lower = |p: &&ScanPair| p.name().to_lowercase();
        self.pairs
            .iter()
            .find(|p| lower(p) == wanted)
            .or_else(|| self.pairs.iter().find(|p| lower(p).contains(&wanted)))
            .ok_or_else(|| self.no_such_channel(Some(name)))
    }

    /// [`ScanFile::channel`] for `Some(name)`, the [`ScanFile::topography`] for `None`.
    pub fn channel_or_topography(&self, name: Option<&str>) -> Result<&ScanPair, NoSuchChannel> {
        match name {
            Some(name) => self.channel(name),
            None => self.topography().ok_or_else(|| self.no_such_channel(None)),
        }
    }

    fn no_such_channel(&self, wanted: Option<&str>) -> NoSuchChannel {
        NoSuchChannel {
            wanted: wanted.map(str::to_string),
            available: self.pairs.iter().map(|p| p.name().to_string()).collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{FileFormat, ImageChannel, ScanDirection, ScanGeometry};
    use ndarray::Array2;

    fn file(names: &[&str]) -> ScanFile {
        let geometry = ScanGeometry::new(
            2,
            2,
            1e-10,
            1e-10,
            1e-3,
            ScanDirection::Right,
            ScanDirection::Down,
        )
        .unwrap();
        let pairs = names
            .iter()
            .map(|n| {
                let image = ImageChannel::new(*n, "m", Array2::zeros((2, 2)));
                ScanPair::new(geometry.clone(), image, None).unwrap()
            })
            .collect();
        ScanFile {
            format: FileFormat::Npy,
            pairs,
            metadata: Default::default(),
        }
    }

    #[test]
    fn whole_names_win_over_parts_and_case_is_ignored() {
        let f = file(&["Current", "Z", "Z down", "LIA Current"]);
        assert_eq!(f.channel("z").unwrap().name(), "Z");
        assert_eq!(f.channel("DOWN").unwrap().name(), "Z down");
        assert_eq!(f.channel("current").unwrap().name(), "Current");
        assert_eq!(f.channel("lia").unwrap().name(), "LIA Current");
        assert_eq!(f.channel_or_topography(None).unwrap().name(), "Z");
    }

    #[test]
    fn an_unknown_name_lists_the_channels() {
        let f = file(&["Z", "Current"]);
        let error = f.channel("phase").unwrap_err();
        assert_eq!(error.available, ["Z", "Current"]);
        assert_eq!(
            error.to_string(),
            "no channel 'phase' in the file; it holds 'Z', 'Current'"
        );
        let empty = file(&[]);
        assert_eq!(
            empty.channel_or_topography(None).unwrap_err().to_string(),
            "the file holds no image"
        );
    }
}
