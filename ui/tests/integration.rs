//! The workbench's integration tests, one module per file beside this one, built as one test binary (see the core's
//! `tests/integration.rs`). `cargo test -p tnd-workbench --test integration recording::` runs one file's tests.

#![allow(clippy::unwrap_used, clippy::expect_used)]

#[path = "../../tests/fuzz_common/mod.rs"]
mod fuzz_common;
mod support;

mod analysis;
mod cli_parity;
mod desktop;
mod fuzz_session;
mod layers;
mod pose_tab;
mod recording;
mod workbench;
