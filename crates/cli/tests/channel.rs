//! Choosing a channel: `dhct info` lists them, `--channel NAME` picks one for `correct`,
//! `diagnose` and `batch`, and an unknown name exits 1 listing what the file holds.

mod common;

use std::path::PathBuf;

use common::dhct;

fn createc() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/data/real/createc_atomic_11nm.dat")
}

#[test]
fn info_lists_every_channel_with_unit_directions_and_size() {
    let output = dhct().arg("info").arg(createc()).output().unwrap();
    assert!(output.status.success());
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        stdout.contains("channels (2; pick one with --channel NAME):"),
        "{stdout}"
    );
    for name in ["Z        [m]", "Current  [A]"] {
        let line = stdout
            .lines()
            .find(|l| l.trim_start().starts_with(name))
            .unwrap_or_else(|| panic!("no line for {name}: {stdout}"));
        assert!(
            line.contains("trace right + retrace left, slow down")
                && line.contains("512 x 512 px, 11.2503 nm x 11.2503 nm"),
            "{line}"
        );
    }
}

#[test]
fn an_unknown_channel_exits_1_listing_the_channels_in_every_command() {
    let dir = tempfile::tempdir().unwrap();
    let file = createc();
    let correct = common::correct(&file, &["--channel", "phase"], &dir.path().join("c"));
    assert_eq!(correct.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&correct.stderr);
    assert!(
        stderr.contains("no channel 'phase' in the file; it holds 'Z', 'Current'"),
        "{stderr}"
    );
    let runs: [Vec<std::ffi::OsString>; 2] = [
        vec![
            "diagnose".into(),
            file.clone().into(),
            "-o".into(),
            dir.path().join("d").into(),
        ],
        vec![
            "batch".into(),
            file.clone().into(),
            "-o".into(),
            dir.path().join("b").into(),
        ],
    ];
    for args in runs {
        let output = dhct()
            .args(&args)
            .args(["--channel", "phase", "--quiet"])
            .output()
            .unwrap();
        assert_eq!(output.status.code(), Some(1), "{args:?}");
        let mut text = String::from_utf8_lossy(&output.stderr).into_owned();
        if let Ok(summary) = std::fs::read_to_string(dir.path().join("b/summary.csv")) {
            text.push_str(&summary);
        }
        assert!(
            text.contains("no channel 'phase' in the file; it holds 'Z', 'Current'"),
            "{args:?}: {text}"
        );
    }
}

#[test]
fn a_named_channel_is_the_one_analysed() {
    let overrides = dhct_sm4_io::GeometryOverrides::default();
    let file = createc();
    let current = dhct_app::correct::read_pair(&file, None, &overrides, Some("CURRENT")).unwrap();
    assert_eq!(current.name(), "Current");
    assert_eq!(current.trace().unwrap().unit, "A");
    let default = dhct_app::correct::read_pair(&file, None, &overrides, None).unwrap();
    assert_eq!(default.name(), "Z");
    // The retrace file's image comes from the same channel.
    let paired =
        dhct_app::correct::read_pair(&file, Some(&file), &overrides, Some("current")).unwrap();
    assert_eq!(
        paired.retrace().unwrap().z,
        current.retrace().unwrap().z,
        "the second file's retrace of the named channel"
    );
}
