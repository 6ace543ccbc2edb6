//! Gwyddion, an independent maintained reader, against dhct's Nanosurf, Nanoscope and
//! SPECS/Aarhus readers: when the `gwyddion` program is installed (Debian package
//! `gwyddion`), each real file is converted with `gwyddion --convert-to-gwy` and the `.gwy`,
//! read by dhct's GWY reader, must hold the same images, in display orientation, with the same physical size
//! and units. Without `gwyddion` the test prints a note and passes.

use std::path::{Path, PathBuf};
use std::process::Command;

use dhct_scan::ScanFile;
use dhct_sm4_io::read_path;
use ndarray::Array2;

fn real(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/data/real")
        .join(name)
}

/// Every image of the file in order (trace before retrace), with its unit and the frame
/// size of its channel.
fn images(file: &ScanFile) -> Vec<(&Array2<f64>, &str, (f64, f64))> {
    file.pairs
        .iter()
        .flat_map(|pair| {
            let size = (pair.geometry().width(), pair.geometry().height());
            pair.images()
                .map(move |(_, image)| (&image.z, image.unit.as_str(), size))
        })
        .collect()
}

fn gwyddion_is_installed() -> bool {
    Command::new("gwyddion")
        .arg("--version")
        .output()
        .is_ok_and(|out| out.status.success())
}

#[test]
fn gwyddion_reads_the_same_images() {
    if !gwyddion_is_installed() {
        eprintln!("note: gwyddion is not installed; the Gwyddion cross-check was not run");
        return;
    }
    let mut files: Vec<PathBuf> = [
        "nanosurf_afm_7um.nid",
        "nanosurf_grid_3um.nid",
        "bruker_example_40um.spm",
        "nanoscope_d3100_2um.000",
        "specs_aarhus_100nm.mul",
    ]
    .iter()
    .map(|n| real(n))
    .collect();
    if let Some(dir) = std::env::var_os("DHCT_REAL_DATA") {
        for name in ["stm-nanosurf-nid.nid", "stm-aarhus-mul-b.mul"] {
            let file = Path::new(&dir).join(name);
            if file.is_file() {
                files.push(file);
            }
        }
    }
    let dir = tempfile::tempdir().unwrap();
    for (k, path) in files.iter().enumerate() {
        let converted = dir.path().join(format!("{k}.gwy"));
        let status = Command::new("gwyddion")
            .arg(format!("--convert-to-gwy={}", converted.display()))
            .arg(path)
            .status()
            .unwrap();
        assert!(status.success(), "gwyddion failed on {}", path.display());
        let ours = read_path(path).unwrap();
        let theirs = read_path(&converted).unwrap();
        let (a, b) = (images(&ours), images(&theirs));
        assert_eq!(a.len(), b.len(), "{}: number of images", path.display());
        for (i, ((za, ua, sa), (zb, ub, sb))) in a.iter().zip(&b).enumerate() {
            let what = format!("{} image {i}", path.display());
            assert_eq!(za.dim(), zb.dim(), "{what}: shape");
            assert_eq!(ua, ub, "{what}: unit");
            assert!(
                (sa.0 / sb.0 - 1.0).abs() < 1e-6,
                "{what}: width {sa:?} vs {sb:?}"
            );
            assert!(
                (sa.1 / sb.1 - 1.0).abs() < 1e-6,
                "{what}: height {sa:?} vs {sb:?}"
            );
            let scale = zb.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            let worst = za
                .iter()
                .zip(zb.iter())
                .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
            assert!(
                worst <= 1e-9 * scale,
                "{what}: differs by {worst} (scale {scale})"
            );
        }
        eprintln!("{}: {} images agree with Gwyddion", path.display(), a.len());
    }
}
