//! The forward-process noise schedule (paper IV.B): Nichol & Dhariwal's cosine schedule with T = 250, as diffusers
//! `DDPMScheduler(num_train_timesteps=250, beta_schedule="squaredcos_cap_v2")` computes it
//! (`betas_for_alpha_bar`: ᾱ(t) = cos²((t + 0.008) / 1.008 · π/2), β_i = min(1 − ᾱ((i+1)/T) / ᾱ(i/T), 0.999),
//! evaluated in f64 then stored as f32; ᾱ_t is the running product of the f32 α = 1 − β accumulated in f64, as `torch.cumprod` does on the CPU).

use candle_core::Tensor;

use super::ModelError;

/// β_t, α_t and ᾱ_t for t = 0..T−1, in f32 like diffusers.
#[derive(Clone, Debug, PartialEq)]
pub struct NoiseSchedule {
    pub betas: Vec<f32>,
    pub alphas: Vec<f32>,
    pub alphas_cumprod: Vec<f32>,
}

impl NoiseSchedule {
    /// The cosine schedule (`squaredcos_cap_v2`) with `steps` steps (s = 0.008, β ≤ 0.999).
    pub fn cosine(steps: usize) -> Self {
        let alpha_bar = |t: f64| {
            ((t + 0.008) / 1.008 * std::f64::consts::PI / 2.0)
                .cos()
                .powi(2)
        };
        let betas: Vec<f32> = (0..steps)
            .map(|i| {
                let (t1, t2) = (i as f64 / steps as f64, (i + 1) as f64 / steps as f64);
                (1.0 - alpha_bar(t2) / alpha_bar(t1)).min(0.999) as f32
            })
            .collect();
        let alphas: Vec<f32> = betas.iter().map(|&b| 1.0 - b).collect();
        // torch's CPU cumprod accumulates f32 inputs in f64 (`acc_type`) and rounds each output to f32.
        let mut acc = 1.0f64;
        let alphas_cumprod = alphas
            .iter()
            .map(|&a| {
                acc *= f64::from(a);
                acc as f32
            })
            .collect();
        Self {
            betas,
            alphas,
            alphas_cumprod,
        }
    }

    /// Number of diffusion steps T.
    pub fn len(&self) -> usize {
        self.betas.len()
    }

    /// Always false for a constructed schedule.
    pub fn is_empty(&self) -> bool {
        self.betas.is_empty()
    }

    /// ᾱ at `t`, or 1 for `t < 0` (diffusers' `one` / `final_alpha_cumprod` with `set_alpha_to_one`).
    pub fn alpha_bar(&self, t: i64) -> f32 {
        if t < 0 {
            1.0
        } else {
            self.alphas_cumprod[t as usize]
        }
    }

    /// The forward process q(x_t | x_0): `√ᾱ_t x0 + √(1−ᾱ_t) ε` for per-sample timesteps `t` (`x0`, `noise`
    /// `[B, C, H, W]`), as diffusers `add_noise`.
    pub fn add_noise(
        &self,
        x0: &Tensor,
        noise: &Tensor,
        t: &[usize],
    ) -> Result<Tensor, ModelError> {
        let (sa, sb) = self.coefficients(x0, t)?;
        Ok((x0.broadcast_mul(&sa)? + noise.broadcast_mul(&sb)?)?)
    }

    /// The v-prediction target `√ᾱ_t ε − √(1−ᾱ_t) x0` (Salimans & Ho), as diffusers `get_velocity`.
    pub fn velocity(&self, x0: &Tensor, noise: &Tensor, t: &[usize]) -> Result<Tensor, ModelError> {
        let (sa, sb) = self.coefficients(x0, t)?;
        Ok((noise.broadcast_mul(&sa)? - x0.broadcast_mul(&sb)?)?)
    }

    /// `(√ᾱ_t, √(1−ᾱ_t))` per sample as `[B, 1, 1, 1]` tensors.
    fn coefficients(&self, x0: &Tensor, t: &[usize]) -> Result<(Tensor, Tensor), ModelError> {
        let b = x0.dim(0)?;
        if t.len() != b {
            return Err(ModelError::Input(format!(
                "{} timesteps for a batch of {b}",
                t.len()
            )));
        }
        let sa: Vec<f32> = t.iter().map(|&t| self.alphas_cumprod[t].sqrt()).collect();
        let sb: Vec<f32> = t
            .iter()
            .map(|&t| (1.0 - self.alphas_cumprod[t]).sqrt())
            .collect();
        let dev = x0.device();
        Ok((
            Tensor::from_vec(sa, (b, 1, 1, 1), dev)?,
            Tensor::from_vec(sb, (b, 1, 1, 1), dev)?,
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cosine_schedule_invariants() {
        let s = NoiseSchedule::cosine(250);
        assert_eq!(s.len(), 250);
        assert!(s.betas.iter().all(|&b| b > 0.0 && b <= 0.999));
        assert!(s.betas.windows(2).all(|w| w[1] >= w[0]), "β increases");
        // ᾱ(1/T)/ᾱ(0) from the closed form.
        let ab = |t: f64| {
            ((t + 0.008) / 1.008 * std::f64::consts::FRAC_PI_2)
                .cos()
                .powi(2)
        };
        assert!((f64::from(s.alphas_cumprod[0]) - ab(1.0 / 250.0) / ab(0.0)).abs() < 1e-7);
        assert_eq!(*s.betas.last().unwrap_or(&0.0), 0.999);
    }
}
