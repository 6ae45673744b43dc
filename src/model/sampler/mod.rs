//! Reverse diffusion (paper IV.B "sampling"): one trait, one implementation per file — ancestral DDPM
//! ([`ddpm::Ddpm`], the paper's 250 steps) and DDIM ([`ddim::Ddim`], fewer steps, η-controlled noise). Both follow
//! diffusers' `DDPMScheduler.step` / `DDIMScheduler.step` (ε- or v-prediction, x0 clipped to [-1, 1]) operation by
//! operation in f32; the tests compare them with diffusers' outputs.

pub mod ddim;
pub mod ddpm;

use crate::error::InvalidSetting;
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

/// The reverse process by name (the `--sampler` value).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum SamplerName {
    /// Ancestral DDPM over all T training steps (the paper's sampler).
    Ddpm,
    /// DDIM over `steps` steps.
    Ddim,
}

/// Which sampler runs and how: the one definition behind `tnd sample`, `tnd eval` and `tnd pose` (flattened into
/// their arguments) and the workbench's De-render tab (stored in its session), with one set of defaults: DDIM, 25
/// steps, η = 0, trailing spacing (within 5 % of DDPM-250 on the depth metrics at a tenth of the time; see
/// `docs/experiments/2026-11-24-v-prediction-model.md`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, clap::Args)]
#[serde(default)]
pub struct SamplerConfig {
    /// Sampler: ddpm (all training steps, the paper's) or ddim (--steps steps, noise η = --eta).
    #[arg(long = "sampler", value_enum, default_value_t = SamplerConfig::default().kind)]
    #[serde(rename = "sampler")]
    pub kind: SamplerName,
    /// DDIM steps, 1 up to the model's training steps (250 for the shipped model).
    #[arg(long, default_value_t = SamplerConfig::default().steps)]
    #[serde(alias = "ddim_steps")]
    pub steps: usize,
    /// DDIM η: 0 is deterministic, 1 adds DDPM-like noise (dimensionless).
    #[arg(long, default_value_t = SamplerConfig::default().eta)]
    pub eta: f64,
    /// DDIM timestep spacing: trailing (starts at t = T−1, like DDPM) or leading (diffusers' default).
    #[arg(long, default_value_t = SamplerConfig::default().spacing)]
    pub spacing: TimestepSpacing,
}

impl Default for SamplerConfig {
    fn default() -> Self {
        Self {
            kind: SamplerName::Ddim,
            steps: 25,
            eta: 0.0,
            spacing: TimestepSpacing::Trailing,
        }
    }
}

impl SamplerConfig {
    /// The sampler to run.
    pub fn sampler_kind(&self) -> SamplerKind {
        match self.kind {
            SamplerName::Ddpm => SamplerKind::Ddpm,
            SamplerName::Ddim => SamplerKind::Ddim {
                steps: self.steps,
                eta: self.eta,
                spacing: self.spacing,
            },
        }
    }

    /// Check the numbers (sessions and command lines may carry anything); `train_steps` is the model's T when
    /// known.
    pub fn validate(&self, train_steps: Option<usize>) -> Result<(), InvalidSetting> {
        if self.kind == SamplerName::Ddim {
            let max = train_steps.unwrap_or(usize::MAX);
            if self.steps == 0 || self.steps > max {
                let message = match train_steps {
                    Some(t) => format!(
                        "DDIM steps must be 1..={t} (the model's training steps), got {}",
                        self.steps
                    ),
                    None => format!("DDIM steps must be at least 1, got {}", self.steps),
                };
                return Err(InvalidSetting::new("sampler.steps", message));
            }
        }
        if !(self.eta.is_finite() && (0.0..=1.0).contains(&self.eta)) {
            return Err(InvalidSetting::new(
                "sampler.eta",
                format!("DDIM eta must be in [0, 1], got {}", self.eta),
            ));
        }
        Ok(())
    }
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
    type Err = crate::error::InvalidSetting;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        crate::error::InvalidSetting::wrap("sampler.spacing", || match s {
            "leading" => Ok(Self::Leading),
            "trailing" => Ok(Self::Trailing),
            _ => Err(format!(
                "timestep spacing must be leading or trailing, got '{s}'"
            )),
        })
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

/// One reverse process over a fixed timestep sequence. A step is [`Sampler::predict`] (the network output as a
/// clipped x̂0 and its ε̂) then [`Sampler::advance`] (x_{t'} from them); [`Sampler::step`] does both. Between the two
/// a caller may correct x̂0 ([`crate::model::guidance`]) and the step keeps the network's ε̂.
pub trait Sampler: Send + Sync {
    /// The timesteps to visit, descending.
    fn timesteps(&self) -> &[usize];
    /// Whether the step at `t` adds fresh noise (then `noise` must be given to [`Sampler::advance`]).
    fn needs_noise(&self, t: usize) -> bool;
    /// The network output at `t` (ε or v, same length as `x`) as (x̂0 clipped to [-1, 1], ε̂), in model units.
    fn predict(
        &self,
        model_output: &[f32],
        t: usize,
        x: &[f32],
    ) -> Result<(Vec<f32>, Vec<f32>), ModelError>;
    /// x_{t'} from x_t (`x`) and a prediction (`x0`, `eps`) of [`Sampler::predict`], with `noise` ~ N(0, 1) when
    /// needed.
    fn advance(
        &self,
        x0: &[f32],
        eps: &[f32],
        t: usize,
        x: &[f32],
        noise: Option<&[f32]>,
    ) -> Result<Vec<f32>, ModelError>;
    /// x_{t'} from x_t (`x`) and the network output `model_output` (ε or v, same length), with `noise` ~ N(0, 1)
    /// when needed.
    fn step(
        &self,
        model_output: &[f32],
        t: usize,
        x: &[f32],
        noise: Option<&[f32]>,
    ) -> Result<Vec<f32>, ModelError> {
        let (x0, eps) = self.predict(model_output, t, x)?;
        self.advance(&x0, &eps, t, x, noise)
    }
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

/// The network output at `t` as (x̂0 clipped to [-1, 1], ε̂): what DDPM and DDIM alike take from it.
pub(crate) fn predict_x0_eps(
    schedule: &NoiseSchedule,
    prediction: PredictionType,
    model_output: &[f32],
    t: usize,
    x: &[f32],
) -> Result<(Vec<f32>, Vec<f32>), ModelError> {
    check_lengths(model_output, x, None)?;
    let a_t = schedule.alpha_bar(t as i64);
    let (sb, sa) = ((1.0 - a_t).sqrt(), a_t.sqrt());
    Ok(model_output
        .iter()
        .zip(x)
        .map(|(&o, &xt)| {
            let (x0, e) = prediction.x0_eps(o, xt, sa, sb);
            (x0.clamp(-1.0, 1.0), e)
        })
        .unzip())
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

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        sampler: SamplerConfig,
    }

    #[test]
    fn command_line_defaults_are_the_config_defaults() {
        let none = Cli::try_parse_from(["tnd"]).unwrap();
        assert_eq!(none.sampler, SamplerConfig::default());
        let some = Cli::try_parse_from([
            "tnd",
            "--sampler",
            "ddpm",
            "--steps",
            "10",
            "--eta",
            "1",
            "--spacing",
            "leading",
        ])
        .unwrap();
        assert_eq!(some.sampler.sampler_kind(), SamplerKind::Ddpm);
        assert_eq!(
            (some.sampler.steps, some.sampler.eta, some.sampler.spacing),
            (10, 1.0, TimestepSpacing::Leading)
        );
        assert!(Cli::try_parse_from(["tnd", "--sampler", "euler"]).is_err());
    }

    #[test]
    fn validation_names_the_bad_setting() {
        let bad_steps = SamplerConfig {
            steps: 300,
            ..SamplerConfig::default()
        };
        assert!(bad_steps
            .validate(Some(250))
            .unwrap_err()
            .message
            .contains("1..=250"));
        assert!(bad_steps.validate(None).is_ok());
        let bad_eta = SamplerConfig {
            eta: 1.5,
            ..SamplerConfig::default()
        };
        assert_eq!(bad_eta.validate(None).unwrap_err().setting, "sampler.eta");
        // DDPM ignores the DDIM settings.
        let ddpm = SamplerConfig {
            kind: SamplerName::Ddpm,
            steps: 0,
            ..SamplerConfig::default()
        };
        assert!(ddpm.validate(Some(250)).is_ok());
    }
}
