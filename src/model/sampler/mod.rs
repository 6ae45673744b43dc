//! Reverse diffusion (paper IV.B "sampling"): one trait, one implementation per file — ancestral DDPM
//! ([`ddpm::Ddpm`], the paper's 250 steps) and DDIM ([`ddim::Ddim`], fewer steps, η-controlled noise). Both follow
//! diffusers' `DDPMScheduler.step` / `DDIMScheduler.step` (ε- or v-prediction, x0 clipped to [-1, 1]) operation by
//! operation in f32; the tests compare them with diffusers' outputs.

pub mod ddim;
pub mod ddpm;

use std::sync::Arc;

use serde::{Deserialize, Serialize};

use super::config::PredictionType;
use super::schedule::NoiseSchedule;
use super::ModelError;

/// Which reverse process to run.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum SamplerKind {
    /// Ancestral DDPM over all T steps (`fixed_small` variance).
    Ddpm,
    /// DDIM over `steps` evenly spaced steps ("leading" spacing); `eta` = 0 is deterministic, 1 is DDPM-like.
    Ddim { steps: usize, eta: f64 },
}

/// One reverse process over a fixed timestep sequence.
pub trait Sampler: Send + Sync {
    /// The timesteps to visit, descending.
    fn timesteps(&self) -> &[usize];
    /// Whether the step at `t` adds fresh noise (then `noise` must be given to [`Sampler::step`]).
    fn needs_noise(&self, t: usize) -> bool;
    /// x_{t'} from x_t (`x`) and the network output `model_output` (ε or v, same length), with `noise` ~ N(0, 1)
    /// when needed.
    fn step(
        &self,
        model_output: &[f32],
        t: usize,
        x: &[f32],
        noise: Option<&[f32]>,
    ) -> Result<Vec<f32>, ModelError>;
}

/// Build the sampler of `kind` over `schedule` for a network that predicts `prediction`.
pub fn make(
    kind: SamplerKind,
    schedule: Arc<NoiseSchedule>,
    prediction: PredictionType,
) -> Result<Box<dyn Sampler>, ModelError> {
    Ok(match kind {
        SamplerKind::Ddpm => Box::new(ddpm::Ddpm::new(schedule, prediction)),
        SamplerKind::Ddim { steps, eta } => {
            Box::new(ddim::Ddim::new(schedule, steps, eta, prediction)?)
        }
    })
}

pub(crate) fn check_lengths(
    model_output: &[f32],
    x: &[f32],
    noise: Option<&[f32]>,
) -> Result<(), ModelError> {
    if model_output.len() != x.len() || noise.is_some_and(|n| n.len() != x.len()) {
        return Err(ModelError::Input(format!(
            "sampler step: model output {} / x {} / noise {:?} values differ",
            model_output.len(),
            x.len(),
            noise.map(<[f32]>::len)
        )));
    }
    Ok(())
}
