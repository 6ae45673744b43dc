//! Helpers of the tests that run the `tnd` binary as a user would: a command in a directory, and its stderr.

#![allow(dead_code, clippy::expect_used)]

use std::path::Path;
use std::process::{Command, Output};

/// `tnd ARGS` run in `dir`.
pub fn tnd_in(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_tnd"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("run tnd")
}

/// A run's stderr as text.
pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}
