//! Mutation fuzzing of workbench session files (`sessions/*.json`, opened with *Open…*, `--session` or drag and
//! drop): seeds in `tests/fixtures/fuzz/session/`, the same driver as the core loaders (`tests/fuzz_common`). Every
//! input must be read or refused with an error — never a panic or a hang.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use crate::fuzz_common;

#[test]
fn session_files() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("s.json");
    fuzz_common::fuzz("session", &|b| {
        std::fs::write(&path, b).unwrap();
        tnd_workbench::session::read(&path).is_ok()
    });
}
