//! Helpers of the tests that run the `tnd` binary as a user would: a command in a directory, and its stderr.

#![allow(dead_code, clippy::expect_used)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// `tnd ARGS` run in `dir`.
pub fn tnd_in(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_tnd"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("run tnd")
}

/// `tnd ARGS` run in `dir`, which must succeed (else the assertion names the arguments and stderr): the JSON of its
/// last stdout line, where every command writes its result.
pub fn tnd_json(dir: &Path, args: &[&str]) -> serde_json::Value {
    let out = tnd_in(dir, args);
    assert!(out.status.success(), "tnd {args:?}: {}", stderr(&out));
    let stdout = String::from_utf8(out.stdout).expect("utf-8 stdout");
    serde_json::from_str(stdout.lines().last().expect("a line on stdout")).expect("JSON")
}

/// A run's stderr as text.
pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Every file under `dir` (relative path → bytes).
pub fn tree(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    fn walk(root: &Path, dir: &Path, out: &mut Vec<(PathBuf, Vec<u8>)>) {
        for e in std::fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                walk(root, &p, out);
            } else {
                out.push((
                    p.strip_prefix(root).unwrap().to_path_buf(),
                    std::fs::read(&p).unwrap(),
                ));
            }
        }
    }
    let mut out = Vec::new();
    walk(dir, dir, &mut out);
    out.sort();
    out
}
