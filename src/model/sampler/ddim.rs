//! DDIM sampling (Song et al.; paper V.B uses fewer steps for speed): diffusers `DDIMScheduler.step` with
//! `timestep_spacing` "leading" or "trailing", `steps_offset=0`, `set_alpha_to_one=True`, `clip_sample=True`,
//! `prediction_type` "epsilon" or "v_prediction", `use_clipped_model_output=False`.

use std::sync::Arc;

use super::{check_lengths, Sampler, TimestepSpacing};
use crate::model::config::PredictionType;
use crate::model::schedule::NoiseSchedule;
use crate::model::ModelError;

/// DDIM over `steps` timesteps placed by a [`TimestepSpacing`]; each step goes from `t` to `t − r`,
/// `r = T / steps` (integer division; ᾱ = 1 below 0), as diffusers' `step` does for either spacing.
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

impl Sampler for Ddim {
    fn timesteps(&self) -> &[usize] {
        &self.timesteps
    }

    fn needs_noise(&self, _t: usize) -> bool {
        self.eta > 0.0
    }

    fn step(
        &self,
        model_output: &[f32],
        t: usize,
        x: &[f32],
        noise: Option<&[f32]>,
    ) -> Result<Vec<f32>, ModelError> {
        check_lengths(model_output, x, noise)?;
        let a_t = self.schedule.alpha_bar(t as i64);
        let a_prev = self.schedule.alpha_bar(t as i64 - self.ratio as i64);
        let beta_t = 1.0 - a_t;
        let beta_prev = 1.0 - a_prev;
        let variance = (beta_prev / beta_t) * (1.0 - a_t / a_prev);
        let std = self.eta * variance.sqrt();
        let (sb, sa, sa_prev) = (beta_t.sqrt(), a_t.sqrt(), a_prev.sqrt());
        let c_dir = (1.0 - a_prev - std * std).sqrt();
        let mut out: Vec<f32> = model_output
            .iter()
            .zip(x)
            .map(|(&o, &xt)| {
                let (x0, e) = self.prediction.x0_eps(o, xt, sa, sb);
                sa_prev * x0.clamp(-1.0, 1.0) + c_dir * e
            })
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
