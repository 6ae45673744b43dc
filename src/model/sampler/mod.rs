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
    /// DDIM over `steps` evenly spaced steps placed by `spacing`; `eta` = 0 is deterministic, 1 is DDPM-like.
    Ddim {
        steps: usize,
        eta: f64,
        /// Older sessions have no spacing saved: they keep diffusers' default, "leading".
        #[serde(default = "TimestepSpacing::leading")]
        spacing: TimestepSpacing,
    },
}

/// Where DDIM's `K` timesteps sit among the `T` training steps (diffusers' `timestep_spacing`), with `r = T / K`
/// (integer division) and `T = 250, K = 25` as example.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TimestepSpacing {
    /// `(K−1)·r, …, r, 0` (240, 230, …, 0): diffusers' default. The first step treats pure noise as x_240,
    /// which still holds √ᾱ = 6 % of the signal under the cosine schedule.
    Leading,
    /// `T−1, T−1−r, …` (249, 239, …, 9; Lin et al. 2024, "Common diffusion noise schedules and sample steps are
    /// flawed"): the first step starts from pure noise at the last training step, as DDPM-250 does. Our default.
    #[default]
    Trailing,
}

impl TimestepSpacing {
    fn leading() -> Self {
        Self::Leading
    }

    /// The `steps` timesteps, descending, among `t` training steps (`1 ≤ steps ≤ t`).
    pub fn timesteps(self, t: usize, steps: usize) -> Vec<usize> {
        match self {
            Self::Leading => {
                let r = t / steps;
                (0..steps).rev().map(|i| i * r).collect()
            }
            // diffusers: round(arange(T, 0, −T/K)) − 1, in f64 like numpy.
            Self::Trailing => {
                let r = t as f64 / steps as f64;
                (0..steps)
                    .map(|i| (t as f64 - i as f64 * r).round_ties_even() as usize - 1)
                    .collect()
            }
        }
    }
}

impl std::str::FromStr for TimestepSpacing {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "leading" => Ok(Self::Leading),
            "trailing" => Ok(Self::Trailing),
            _ => Err(format!(
                "timestep spacing must be leading or trailing, got '{s}'"
            )),
        }
    }
}

impl std::fmt::Display for TimestepSpacing {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Leading => "leading",
            Self::Trailing => "trailing",
        })
    }
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
        SamplerKind::Ddim {
            steps,
            eta,
            spacing,
        } => Box::new(ddim::Ddim::new(schedule, steps, eta, spacing, prediction)?),
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
