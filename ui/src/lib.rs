//! The workbench crate: an egui app over the headless `tactile_derender` core.

pub mod app;
pub mod colormap;
