//! # tactile-derender
//!
//! Headless core of Tactile Neural De-rendering for Soft Bubble sensors: the contact-depth simulator (paper IV.A),
//! synthetic tactile signatures (V.A), and later the dataset, diffusion model and SE(2) pose estimation stages.
//!
//! The data path reads top to bottom: [`mesh`] -> [`objects`] -> [`sensor`] -> [`sim`] (depth rendering, contact,
//! tactile shadows, signature) -> [`io`].
//!
//! Units are SI metres everywhere in storage and APIs; millimetres appear only in display code.

pub mod dataset;
pub mod error;
pub mod image;
pub mod io;
pub mod mesh;
pub mod metrics;
pub mod model;
pub mod objects;
pub mod pipeline;
pub mod pose;
pub mod recon;
pub mod recording;
pub mod rrd;
pub mod seed;
pub mod sensor;
pub mod sim;
pub mod uncertainty;
