//! The formats dhct reads are listed from one table in the code (`FileFormat::ALL`):
//! `dhct --help` prints it, and the README's reader row names every entry.

use std::process::Command;

use dhct_scan::FileFormat;

#[test]
fn help_and_readme_list_every_format_read() {
    let output = Command::new(env!("CARGO_BIN_EXE_dhct"))
        .arg("--help")
        .output()
        .expect("dhct runs");
    let help = String::from_utf8_lossy(&output.stdout);
    let formats = help
        .lines()
        .find(|l| l.starts_with("Formats read"))
        .expect("--help lists the formats read");
    let readme = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../README.md"),
    )
    .expect("README.md");
    let readers = readme
        .lines()
        .find(|l| l.starts_with("| `crates/sm4-io`"))
        .expect("the README's sm4-io row");
    for format in FileFormat::ALL.into_iter().filter(|f| f.is_read()) {
        assert!(
            formats.contains(format.name()),
            "--help omits {}",
            format.name()
        );
        assert!(
            readers.contains(format.name()),
            "README omits {}",
            format.name()
        );
    }
    assert!(
        !formats.contains(FileFormat::Png.name()),
        "PNG is written, not read"
    );
}
