//! # Conditional DDPM (paper IV.B, V.B)
//!
//! A denoising diffusion model generates the in-contact depth X0 conditioned on the imprint Y, which is concatenated
//! to the noisy sample as an input channel. The ε-predictor is Ho et al.'s U-Net in diffusers' `UNet2DModel` layout
//! ([`unet`], with its blocks in [`resnet`], [`attention`], [`unet_blocks`], [`embeddings`] and a fast CPU
//! convolution in [`conv`]); the noise schedule is the cosine schedule of Nichol & Dhariwal with 250 steps
//! ([`schedule`]); DDPM and DDIM reverse processes are [`sampler`]s. [`checkpoint`] reads and writes safetensors
//! files interchangeable with diffusers, [`diffusion`] is the sampling API ([`DiffusionModel`]) and [`train`] the
//! ε-prediction training loop (Adam, EMA, resumable).

pub mod adam;
pub mod attention;
pub mod checkpoint;
pub mod config;
pub mod conv;
pub mod device;
pub mod diagnose;
pub mod diffusers_folder;
pub mod diffusion;
pub mod embeddings;
pub mod group_norm;
pub mod guidance;
pub mod init;
pub mod kernels;
pub mod normalise;
pub mod resnet;
pub mod sampler;
pub mod schedule;
pub mod train;
pub mod train_config;
pub mod train_data;
pub mod unet;
pub mod unet_blocks;

use std::path::PathBuf;

pub(crate) use kernels::simd::contiguous_f32;

pub use config::{PredictionType, TactileConfig, UNet2DConfig};
pub use diffusion::DiffusionModel;
pub use guidance::{Cloak, GuidanceConfig, ImprintGuidance};
pub use normalise::Normalisation;
pub use sampler::{SamplerConfig, SamplerKind, SamplerName, TimestepSpacing};
pub use schedule::NoiseSchedule;
pub use unet::UNet2DModel;

/// Errors of the diffusion model stage; each says what to fix and names the file where there is one.
#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    #[error("{}: cannot read model weights: {error}", path.display())]
    MissingWeights {
        path: PathBuf,
        error: std::io::Error,
    },
    #[error("{}: not a valid safetensors file: {message}", path.display())]
    BadFile { path: PathBuf, message: String },
    #[error("{source_name}: {message}")]
    Config {
        source_name: String,
        message: String,
    },
    #[error("{}: tensor '{key}' has shape {found:?}, the config needs {expected:?}", path.display())]
    Shape {
        path: PathBuf,
        key: String,
        expected: Vec<usize>,
        found: Vec<usize>,
    },
    #[error("{}: tensor '{key}' is missing (the checkpoint does not match the config)", path.display())]
    MissingTensor { path: PathBuf, key: String },
    #[error("{}: unexpected tensor '{key}' (the checkpoint does not match the config)", path.display())]
    UnexpectedTensor { path: PathBuf, key: String },
    #[error("{what} contains NaN or infinite values{}", at_step.map(|s| format!(" at step {s}")).unwrap_or_default())]
    NonFinite { what: String, at_step: Option<u64> },
    #[error("input has the wrong shape: {0}")]
    Input(String),
    /// A `tnd train` run directory given where a model is expected.
    #[error("{}: a training run, not a model; its model is {}", run.display(), run.join("model.safetensors").display())]
    TrainingRun { run: PathBuf },
    #[error("cancelled")]
    Cancelled,
    #[error("{message}")]
    Device { spec: String, message: String },
    #[error("{}", crate::error::with_path(path, error))]
    Io {
        path: PathBuf,
        error: std::io::Error,
    },
    #[error("training data: {0}")]
    Data(String),
    #[error("training data: {0}")]
    Dataset(#[from] crate::dataset::DatasetError),
    #[error("cannot encode JSON: {0}")]
    Json(#[from] serde_json::Error),
    #[error("tensor computation failed: {0}")]
    Candle(#[from] candle_core::Error),
}
