//! Diffusion-time embedding (paper IV.B, Ho et al.'s sinusoidal position embedding of t): diffusers `Timesteps`
//! (`get_timestep_embedding`) and `TimestepEmbedding` (`diffusers/models/embeddings.py`).

use candle_core::{Device, Module, Result, Tensor};
use candle_nn::{linear, Linear, VarBuilder};

/// diffusers `get_timestep_embedding(t, dim, flip_sin_to_cos, downscale_freq_shift, scale=1, max_period=10000)`,
/// computed in f32 like PyTorch: row `b` is `[sin(t_b f_k), cos(t_b f_k)]` (cos first when `flip_sin_to_cos`), with
/// `f_k = exp(-ln(10000) k / (dim/2 - shift))`; an odd `dim` is zero-padded.
pub fn timestep_embedding(
    timesteps: &[f32],
    dim: usize,
    flip_sin_to_cos: bool,
    freq_shift: f64,
    device: &Device,
) -> Result<Tensor> {
    let half = dim / 2;
    let ln_max = -(10000f64.ln() as f32);
    let denom = (half as f64 - freq_shift) as f32;
    let freqs: Vec<f32> = (0..half)
        .map(|k| (ln_max * k as f32 / denom).exp())
        .collect();
    let mut data = Vec::with_capacity(timesteps.len() * dim);
    for &t in timesteps {
        let args = freqs.iter().map(|&f| t * f);
        let (sin, cos): (Vec<f32>, Vec<f32>) = args.map(|a| (a.sin(), a.cos())).unzip();
        if flip_sin_to_cos {
            data.extend(cos);
            data.extend(sin);
        } else {
            data.extend(sin);
            data.extend(cos);
        }
        if dim % 2 == 1 {
            data.push(0.0);
        }
    }
    Tensor::from_vec(data, (timesteps.len(), dim), device)
}

/// diffusers `TimestepEmbedding`: `linear_2(silu(linear_1(x)))`; keys `time_embedding.linear_1`, `.linear_2`.
#[derive(Clone, Debug)]
pub struct TimestepEmbedding {
    pub linear_1: Linear,
    pub linear_2: Linear,
}

impl TimestepEmbedding {
    pub fn new(vb: VarBuilder, in_dim: usize, time_embed_dim: usize) -> Result<Self> {
        Ok(Self {
            linear_1: linear(in_dim, time_embed_dim, vb.pp("linear_1"))?,
            linear_2: linear(time_embed_dim, time_embed_dim, vb.pp("linear_2"))?,
        })
    }
}

impl Module for TimestepEmbedding {
    fn forward(&self, x: &Tensor) -> Result<Tensor> {
        self.linear_2.forward(&self.linear_1.forward(x)?.silu()?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn embedding_matches_formula() -> Result<()> {
        // t = 0: sin = 0, cos = 1; flip puts the cosines first.
        let e = timestep_embedding(&[0.0, 3.0], 8, true, 0.0, &Device::Cpu)?.to_vec2::<f32>()?;
        assert_eq!(&e[0][..4], &[1.0; 4]);
        assert_eq!(&e[0][4..], &[0.0; 4]);
        // k = 1 with half = 4, shift 1: f = exp(-ln(1e4) / 3) = 1e4^(-1/3).
        let e = timestep_embedding(&[3.0], 8, false, 1.0, &Device::Cpu)?.to_vec2::<f32>()?;
        let f = 1e4f64.powf(-1.0 / 3.0);
        assert!((f64::from(e[0][1]) - (3.0 * f).sin()).abs() < 1e-6);
        assert!((f64::from(e[0][5]) - (3.0 * f).cos()).abs() < 1e-6);
        Ok(())
    }
}
