//! Ancestral DDPM sampling (Ho et al.; paper IV.B with T = 250): diffusers `DDPMScheduler.step` with
//! `variance_type="fixed_small"`, `clip_sample=True` (range 1), `prediction_type` "epsilon" or "v_prediction".

use std::sync::Arc;

use super::{check_lengths, predict_x0_eps, Sampler};
use crate::model::config::PredictionType;
use crate::model::schedule::NoiseSchedule;
use crate::model::ModelError;

/// DDPM over every training timestep T−1, …, 0.
#[derive(Clone, Debug)]
pub struct Ddpm {
    schedule: Arc<NoiseSchedule>,
    timesteps: Vec<usize>,
    prediction: PredictionType,
}

impl Ddpm {
    pub fn new(schedule: Arc<NoiseSchedule>, prediction: PredictionType) -> Self {
        let timesteps = (0..schedule.len()).rev().collect();
        Self {
            schedule,
            timesteps,
            prediction,
        }
    }

    /// `fixed_small` variance β̃_t = (1 − ᾱ_{t−1}) / (1 − ᾱ_t) · β_t, clamped at 1e-20 (diffusers `_get_variance`).
    pub fn variance(&self, t: usize) -> f32 {
        let a_t = self.schedule.alpha_bar(t as i64);
        let a_prev = self.schedule.alpha_bar(t as i64 - 1);
        let beta_t = 1.0 - a_t / a_prev;
        ((1.0 - a_prev) / (1.0 - a_t) * beta_t).max(1e-20)
    }
}

impl Sampler for Ddpm {
    fn timesteps(&self) -> &[usize] {
        &self.timesteps
    }

    fn needs_noise(&self, t: usize) -> bool {
        t > 0
    }

    fn predict(
        &self,
        model_output: &[f32],
        t: usize,
        x: &[f32],
    ) -> Result<(Vec<f32>, Vec<f32>), ModelError> {
        predict_x0_eps(&self.schedule, self.prediction, model_output, t, x)
    }

    /// The posterior mean of x_{t−1} given x̂0 and x_t (ε̂ is not used: a corrected x̂0 moves the mean directly).
    fn advance(
        &self,
        x0: &[f32],
        _eps: &[f32],
        t: usize,
        x: &[f32],
        noise: Option<&[f32]>,
    ) -> Result<Vec<f32>, ModelError> {
        check_lengths(x0, x, noise)?;
        let a_t = self.schedule.alpha_bar(t as i64);
        let a_prev = self.schedule.alpha_bar(t as i64 - 1);
        let beta_t = 1.0 - a_t;
        let beta_prev = 1.0 - a_prev;
        let cur_alpha = a_t / a_prev;
        let cur_beta = 1.0 - cur_alpha;
        let c_x0 = a_prev.sqrt() * cur_beta / beta_t;
        let c_xt = cur_alpha.sqrt() * beta_prev / beta_t;
        let mut out: Vec<f32> = x0
            .iter()
            .zip(x)
            .map(|(&x0, &xt)| c_x0 * x0 + c_xt * xt)
            .collect();
        if t > 0 {
            let noise = noise
                .ok_or_else(|| ModelError::Input(format!("DDPM step at t = {t} needs noise")))?;
            let sd = self.variance(t).sqrt();
            for (o, &n) in out.iter_mut().zip(noise) {
                *o += sd * n;
            }
        }
        Ok(out)
    }
}
