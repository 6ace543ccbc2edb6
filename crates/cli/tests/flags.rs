//! The flags the command line adds to the library's warnings exist.

use std::process::Command;

use dhct_app::flags::{ALL_INPUTS, flag};

#[test]
fn every_input_a_warning_names_is_an_option_of_correct() {
    let help = Command::new(env!("CARGO_BIN_EXE_dhct"))
        .args(["correct", "--help"])
        .output()
        .expect("dhct runs");
    let help = String::from_utf8_lossy(&help.stdout);
    for input in ALL_INPUTS {
        let long = flag(input);
        assert!(
            help.split(|c: char| c.is_whitespace() || c == ',' || c == '=' || c == '<')
                .any(|word| word == long),
            "{input:?}: {long} is not in `dhct correct --help`"
        );
    }
}
