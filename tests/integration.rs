//! The core's integration tests, one module per file beside this one, built as one test binary: one link and the
//! library's code instantiated once, instead of a binary per file (CI builds everything from scratch on 2 cores).
//! `cargo test --test integration eval_loop::` runs one file's tests.

#![allow(clippy::unwrap_used, clippy::expect_used)]

mod cli_common;
mod dataset_common;
mod fuzz_common;

mod architecture;
mod camera_path;
mod dataset;
mod dataset_camera;
mod dataset_import;
mod dataset_objects;
mod dataset_training;
mod eval_loop;
mod eval_metrics;
mod eval_pose_stage;
mod fuzz_loaders;
mod grad_accumulation;
mod light_press;
mod mesh_io;
mod missing_returns;
mod model_auto;
mod model_cli;
mod model_config_checks;
mod model_schedule;
mod model_train;
mod model_unet;
mod one_writer;
mod output_ownership;
mod pose_register;
mod posterior;
mod recording;
mod recording_calibrate;
mod recording_cli;
mod signature_check;
mod simulator;
mod small_cases;
