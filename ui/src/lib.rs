//! The workbench crate: an eframe/egui app over the headless `tactile_derender` core.
//!
//! Architecture: a serde [`state::State`] (the only thing saved), user intent as [`command::Command`]s applied in one
//! function, heavy work on [`worker`] threads reporting through one message enum, one file per panel under
//! [`panels`], and a [`view3d`] drawn by a wgpu paint callback or, without wgpu, on the CPU.

pub mod analysis_runs;
pub mod analysis_settings;
pub mod app;
pub mod colormap;
pub mod command;
pub mod dataset_view;
pub mod derender;
pub mod dialogs;
pub mod history;
pub mod images;
pub mod measured;
pub mod panels;
pub mod pose_job;
pub mod pose_view;
pub mod recording_view;
pub mod sensor_calibration;
pub mod session;
pub mod shortcuts;
pub mod state;
pub mod timings;
pub mod track_view;
pub mod view3d;
pub mod worker;
