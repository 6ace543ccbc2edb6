use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::ScanPair;

/// The file formats dhct reads or writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum FileFormat {
    /// RHK Technology SM4 (binary, little-endian).
    RhkSm4,
    /// RHK Technology SM3 (the older "STiMage 004" format; read only).
    RhkSm3,
    /// Nanonis SXM (text header + big-endian float32).
    NanonisSxm,
    /// ISO 28600 SPM data transfer format (text).
    Iso28600,
    /// Gwyddion Simple Field (.gsf).
    Gsf,
    /// NumPy array (.npy).
    Npy,
    /// Float or integer TIFF.
    Tiff,
    /// PNG image.
    Png,
    /// Gwyddion native file (.gwy, serialized GwyContainer).
    Gwyddion,
    /// Nanosurf NID (INI-like text header + integer data).
    NanosurfNid,
    /// Bruker/Veeco Nanoscope (.spm, .001, ...: text header + integer data).
    Nanoscope,
    /// Createc `.dat` (text header + zlib-compressed float32).
    CreatecDat,
    /// Omicron MATRIX `.*_mtrx` data file with its `_0001.mtrx` parameter file.
    OmicronMatrix,
    /// WSxM image (`.top`, `.stp`; text header + binary).
    Wsxm,
    /// SPECS/Aarhus `.mul` (several images per file) and its index-less `.flm` film variant.
    AarhusMul,
    /// JPK Instruments image (`.jpk`, `.jpk-qi-image`: a TIFF with JPK's own tags).
    Jpk,
}

impl FileFormat {
    /// Every format, in the order `dhct --help` and the README list them.
    pub const ALL: [FileFormat; 16] = [
        FileFormat::RhkSm4,
        FileFormat::RhkSm3,
        FileFormat::NanonisSxm,
        FileFormat::Iso28600,
        FileFormat::Gsf,
        FileFormat::Npy,
        FileFormat::Tiff,
        FileFormat::Gwyddion,
        FileFormat::NanosurfNid,
        FileFormat::Nanoscope,
        FileFormat::CreatecDat,
        FileFormat::OmicronMatrix,
        FileFormat::Wsxm,
        FileFormat::AarhusMul,
        FileFormat::Jpk,
        FileFormat::Png,
    ];

    /// Whether dhct reads files of this format (every one but PNG, which holds no
    /// physical heights).
    pub fn is_read(self) -> bool {
        self != FileFormat::Png
    }

    /// Whether dhct writes files of this format.
    pub fn is_written(self) -> bool {
        matches!(
            self,
            FileFormat::RhkSm4
                | FileFormat::Gsf
                | FileFormat::Npy
                | FileFormat::Tiff
                | FileFormat::Png
        )
    }

    /// The names of the formats dhct reads, comma-separated, in [`FileFormat::ALL`]'s order.
    pub fn read_list() -> String {
        let read = FileFormat::ALL.into_iter().filter(|f| f.is_read());
        read.map(FileFormat::name).collect::<Vec<_>>().join(", ")
    }

    /// A short human-readable name.
    pub fn name(self) -> &'static str {
        match self {
            FileFormat::RhkSm4 => "RHK SM4",
            FileFormat::RhkSm3 => "RHK SM3",
            FileFormat::NanonisSxm => "Nanonis SXM",
            FileFormat::Iso28600 => "ISO 28600",
            FileFormat::Gsf => "Gwyddion Simple Field",
            FileFormat::Npy => "NumPy NPY",
            FileFormat::Tiff => "TIFF",
            FileFormat::Png => "PNG",
            FileFormat::Gwyddion => "Gwyddion GWY",
            FileFormat::NanosurfNid => "Nanosurf NID",
            FileFormat::Nanoscope => "Bruker Nanoscope",
            FileFormat::CreatecDat => "Createc DAT",
            FileFormat::OmicronMatrix => "Omicron MATRIX",
            FileFormat::Wsxm => "WSxM",
            FileFormat::AarhusMul => "Aarhus MUL",
            FileFormat::Jpk => "JPK",
        }
    }
}

/// Everything a reader found in one file: one [`ScanPair`] per channel, plus header metadata.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ScanFile {
    /// The format the file was read as.
    pub format: FileFormat,
    /// One entry per channel (topography, current, ...), in file order.
    pub pairs: Vec<ScanPair>,
    /// Header fields worth showing a user (free-form key → value, e.g. "date", "bias").
    pub metadata: BTreeMap<String, String>,
}

impl ScanFile {
    /// The topography channel: the first channel whose name contains "topo" or "height"
    /// or "z" as a whole word (case-insensitive), else the first channel in metres, else
    /// the first channel.
    pub fn topography(&self) -> Option<&ScanPair> {
        let named = |pair: &&ScanPair| {
            let name = pair.name().to_ascii_lowercase();
            name.contains("topo")
                || name.contains("height")
                || name
                    .split(|c: char| !c.is_ascii_alphanumeric())
                    .any(|w| w == "z")
        };
        let in_metres = |pair: &&ScanPair| pair.images().any(|(_, c)| c.unit == "m");
        self.pairs
            .iter()
            .find(named)
            .or_else(|| self.pairs.iter().find(in_metres))
            .or_else(|| self.pairs.first())
    }
}
