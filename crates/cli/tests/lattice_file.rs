//! A lattice file as a user writes it: vectors rounded to 4 decimals work (the shells are
//! clustered within the precision the file gives, the cell is made exact for its plane
//! group); a file whose vectors or motif disagree with its plane group stops the run with
//! an error naming what disagrees.

mod common;

use std::path::{Path, PathBuf};

use common::correct;
use serde_json::Value;

fn example() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/data/simulated_graphite.sm4")
}

/// Graphite's imaged lattice with `a2` as given, in Å.
fn graphite_file(dir: &Path, a2: &str, group: &str) -> PathBuf {
    let path = dir.join(format!("graphite-{group}-{}.toml", a2.len()));
    let text = format!(
        "name = \"graphite by hand\"\nlength_unit = \"A\"\na1 = [2.4600, 0.0000]\n\
         a2 = {a2}\nplane_group = \"{group}\"\n\n[[motif]]\nfractional = [0.0, 0.0]\n"
    );
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn a_lattice_file_with_four_decimal_vectors_corrects_like_the_preset() {
    let dir = tempfile::tempdir().unwrap();
    // √3/2 · 2.46 = 2.130422…: written as 2.1304, |a2| ≠ |a1| by 1e-5.
    let file = graphite_file(dir.path(), "[1.2300, 2.1304]", "p3m1");
    let out = dir.path().join("out");
    let output = correct(&example(), &["--lattice", file.to_str().unwrap()], &out);
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let model: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("model.json")).unwrap()).unwrap();
    let region = &model["regions"][0];
    for k in 0..2 {
        let a = region["lattice_constant_m"][k].as_f64().unwrap();
        assert!((a - 2.46e-10).abs() < 0.005 * 2.46e-10, "a[{k}] = {a}");
    }
}

#[test]
fn a_lattice_file_that_disagrees_with_its_plane_group_names_the_problem() {
    let dir = tempfile::tempdir().unwrap();
    // |a2| = 2.4749 Å: 0.6 % longer than a1, far beyond the file's 4-decimal precision.
    let file = graphite_file(dir.path(), "[1.2500, 2.1400]", "p6mm");
    let output = correct(
        &example(),
        &["--lattice", file.to_str().unwrap()],
        &dir.path().join("out"),
    );
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        !output.status.success() && !stderr.contains("panicked"),
        "{stderr}"
    );
    assert!(
        stderr.contains("p6mm needs |a1| = |a2| at 60° or 120°") && stderr.contains("2.47"),
        "{stderr}"
    );
    // A honeycomb declared p6mm about an atom: the six-fold rotation does not hold there.
    let honeycomb = dir.path().join("honeycomb.toml");
    std::fs::write(
        &honeycomb,
        "name = \"graphene\"\nlength_unit = \"A\"\na1 = [2.46, 0.0]\na2 = [1.23, 2.1304]\n\
         plane_group = \"p6mm\"\nmotif = [{ fractional = [0.0, 0.0] }, \
         { fractional = [0.3333, 0.3333] }]\n",
    )
    .unwrap();
    let output = correct(
        &example(),
        &["--lattice", honeycomb.to_str().unwrap()],
        &dir.path().join("out2"),
    );
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success(), "{stderr}");
    assert!(
        stderr.contains("6-fold rotation") && stderr.contains("symmetry_origin"),
        "{stderr}"
    );
}

/// `dhct lattice check FILE`: a file that keeps the contract is described; one that breaks
/// a rule stops with exit 1 naming it.
#[test]
fn lattice_check_describes_a_good_file_and_names_a_broken_rule() {
    let dir = tempfile::tempdir().unwrap();
    let check = |file: &Path| {
        common::dhct()
            .args(["lattice", "check", file.to_str().unwrap()])
            .output()
            .unwrap()
    };
    let good = check(&graphite_file(dir.path(), "[1.2300, 2.1304]", "p3m1"));
    let text = String::from_utf8_lossy(&good.stdout);
    assert!(
        good.status.success(),
        "{}",
        String::from_utf8_lossy(&good.stderr)
    );
    assert!(
        text.contains("contract holds") && text.contains("2.4600 Å") && text.contains("[6]"),
        "{text}"
    );
    let broken = check(&graphite_file(dir.path(), "[1.2500, 2.1400]", "p6mm"));
    let stderr = String::from_utf8_lossy(&broken.stderr);
    assert_eq!(broken.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("p6mm") && stderr.contains("|a1| = |a2|"),
        "{stderr}"
    );
}

/// Five lattice files, each breaking one rule of the contract: `dhct lattice check` stops
/// with exit 1 and names that rule.
#[test]
fn lattice_check_names_the_rule_each_broken_file_breaks() {
    let dir = tempfile::tempdir().unwrap();
    let head = "name = \"broken\"\nlength_unit = \"A\"\n";
    let cases = [
        (
            "metric",
            "a1 = [2.46, 0.0]\na2 = [1.25, 2.14]\nplane_group = \"p6mm\"\n\
             [[motif]]\nfractional = [0.0, 0.0]\n",
            "needs |a1| = |a2|",
        ),
        (
            "symmetry",
            "a1 = [2.46, 0.0]\na2 = [1.23, 2.130422]\nplane_group = \"p6mm\"\n\
             [[motif]]\nfractional = [0.0, 0.0]\n[[motif]]\nfractional = [0.333333, 0.333333]\n",
            "does not have plane group p6mm about the symmetry origin",
        ),
        (
            "coincident",
            "a1 = [3.0, 0.0]\na2 = [0.0, 3.0]\nplane_group = \"p1\"\n\
             [[motif]]\nfractional = [0.0, 0.0]\n[[motif]]\nfractional = [1.0, 1.0]\n",
            "coincide",
        ),
        (
            "parallel",
            "a1 = [3.0, 0.0]\na2 = [3.0, 0.01]\nplane_group = \"p1\"\n\
             [[motif]]\nfractional = [0.0, 0.0]\n",
            "nearly parallel",
        ),
        (
            "empty",
            "a1 = [3.0, 0.0]\na2 = [0.0, 3.0]\nplane_group = \"p1\"\nmotif = []\n",
            "the motif is empty",
        ),
    ];
    for (name, body, rule) in cases {
        let path = dir.path().join(format!("{name}.toml"));
        std::fs::write(&path, format!("{head}{body}")).unwrap();
        let output = common::dhct()
            .args(["lattice", "check", path.to_str().unwrap()])
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert_eq!(output.status.code(), Some(1), "{name}: {stderr}");
        assert!(stderr.contains(rule), "{name}: {stderr}");
    }
}
