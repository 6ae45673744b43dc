//! DDIM sampling (Song et al.; paper V.B uses fewer steps for speed): diffusers `DDIMScheduler.step` with
//! `timestep_spacing` "leading" or "trailing", `steps_offset=0`, `set_alpha_to_one=True`, `clip_sample=True`,
//! `prediction_type` "epsilon" or "v_prediction", `use_clipped_model_output=False`; except that a step lands on the
//! next timestep of the sequence, which diffusers' does only when the step count divides T.

use std::sync::Arc;

use super::{check_lengths, predict_x0_eps, Sampler, TimestepSpacing};
use crate::model::config::PredictionType;
use crate::model::schedule::NoiseSchedule;
use crate::model::ModelError;

/// DDIM over `steps` timesteps placed by a [`TimestepSpacing`]; each step goes from one timestep to the next
/// (ᾱ = 1 after the last), which is diffusers' `t − T / steps` whenever `steps` divides T ([`Ddim::prev_timestep`]).
#[derive(Clone, Debug)]
pub struct Ddim {
    schedule: Arc<NoiseSchedule>,
    timesteps: Vec<usize>,
    ratio: usize,
    eta: f32,
    prediction: PredictionType,
}

impl Ddim {
    pub fn new(
        schedule: Arc<NoiseSchedule>,
        steps: usize,
        eta: f64,
        spacing: TimestepSpacing,
        prediction: PredictionType,
    ) -> Result<Self, ModelError> {
        let t = schedule.len();
        if steps == 0 || steps > t {
            return Err(ModelError::Input(format!(
                "DDIM steps must be in 1..={t}, found {steps}"
            )));
        }
        if !(0.0..=1.0).contains(&eta) {
            return Err(ModelError::Input(format!(
                "DDIM eta must be in [0, 1], found {eta}"
            )));
        }
        let ratio = t / steps;
        Ok(Self {
            schedule,
            timesteps: spacing.timesteps(t, steps),
            ratio,
            eta: eta as f32,
            prediction,
        })
    }
}

impl Ddim {
    /// Where the step from `t` lands: the next timestep of the sequence (−1, i.e. ᾱ = 1, after the last).
    ///
    /// diffusers lands on `t − T / K` (integer division) instead. That is the next timestep whenever K divides T
    /// (K = 25 or 50 of T = 250: the same numbers), but not otherwise: with K = 100 its trailing timesteps are
    /// 2.5 apart on average while every step lands 2 below, so half the steps hand the next one an image that is
    /// less noisy than its timestep says (on 40 real-mesh validation pairs, SSIM 0.705 against DDIM-25's 0.790).
    /// Steps called at a `t` outside the sequence land `T / K` below it, as diffusers' do.
    pub fn prev_timestep(&self, t: usize) -> i64 {
        match self.timesteps.iter().position(|&s| s == t) {
            Some(i) => self.timesteps.get(i + 1).map_or(-1, |&s| s as i64),
            None => t as i64 - self.ratio as i64,
        }
    }
}

impl Sampler for Ddim {
    fn timesteps(&self) -> &[usize] {
        &self.timesteps
    }

    fn needs_noise(&self, _t: usize) -> bool {
        self.eta > 0.0
    }

    fn predict(
        &self,
        model_output: &[f32],
        t: usize,
        x: &[f32],
    ) -> Result<(Vec<f32>, Vec<f32>), ModelError> {
        predict_x0_eps(&self.schedule, self.prediction, model_output, t, x)
    }

    fn advance(
        &self,
        x0: &[f32],
        eps: &[f32],
        t: usize,
        x: &[f32],
        noise: Option<&[f32]>,
    ) -> Result<Vec<f32>, ModelError> {
        check_lengths(x0, x, noise)?;
        check_lengths(eps, x, None)?;
        let a_t = self.schedule.alpha_bar(t as i64);
        let a_prev = self.schedule.alpha_bar(self.prev_timestep(t));
        let beta_t = 1.0 - a_t;
        let beta_prev = 1.0 - a_prev;
        let variance = (beta_prev / beta_t) * (1.0 - a_t / a_prev);
        let std = self.eta * variance.sqrt();
        let sa_prev = a_prev.sqrt();
        let c_dir = (1.0 - a_prev - std * std).sqrt();
        let mut out: Vec<f32> = x0
            .iter()
            .zip(eps)
            .map(|(&x0, &e)| sa_prev * x0 + c_dir * e)
            .collect();
        if self.eta > 0.0 {
            let noise = noise
                .ok_or_else(|| ModelError::Input("DDIM step with eta > 0 needs noise".into()))?;
            for (o, &n) in out.iter_mut().zip(noise) {
                *o += std * n;
            }
        }
        Ok(out)
    }
}
