//! What the command-line tests share: running the built `dhct`.

use std::path::Path;
use std::process::{Command, Output};

/// The built `dhct` binary.
pub fn dhct() -> Command {
    Command::new(env!("CARGO_BIN_EXE_dhct"))
}

/// `dhct correct INPUT -o OUT --quiet ARGS…`.
pub fn correct(input: &Path, args: &[&str], out: &Path) -> Output {
    dhct()
        .arg("correct")
        .arg(input)
        .arg("-o")
        .arg(out)
        .arg("--quiet")
        .args(args)
        .output()
        .expect("dhct runs")
}
