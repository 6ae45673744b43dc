//! Spatial self-attention of Ho et al.'s U-Net at the coarse levels (paper IV.B): diffusers `Attention` as built by
//! `AttnDownBlock2D` / `UNetMidBlock2D` (`_from_deprecated_attn_block=True`, `residual_connection=True`), run by
//! `AttnProcessor2_0` (`diffusers/models/attention_processor.py`).

use candle_core::{Module, Result, Tensor};
use candle_nn::{linear, Linear, VarBuilder};

use super::group_norm::{group_norm, GroupNorm};
use super::kernels::attention::fused_attention;

/// Keys `group_norm`, `to_q`, `to_k`, `to_v`, `to_out.0`:
/// `out = (x + to_out(softmax(q kᵀ / √d) v)) / rescale_output_factor` over the H·W tokens, `heads` heads of `d`.
#[derive(Clone, Debug)]
pub struct Attention {
    pub group_norm: GroupNorm,
    pub to_q: Linear,
    pub to_k: Linear,
    pub to_v: Linear,
    /// `to_out.0` (`to_out.1` is dropout).
    pub to_out: Linear,
    pub heads: usize,
    pub rescale_output_factor: f64,
    /// Use candle's matmul and softmax instead of the fused CPU attention op (always on devices other than the CPU).
    pub portable: bool,
}

impl Attention {
    /// `head_dim = None` means one head over all channels.
    pub fn new(
        vb: VarBuilder,
        channels: usize,
        head_dim: Option<usize>,
        groups: usize,
        eps: f64,
        rescale_output_factor: f64,
    ) -> Result<Self> {
        let d = head_dim.unwrap_or(channels);
        Ok(Self {
            group_norm: group_norm(groups, channels, eps, vb.pp("group_norm"))?,
            to_q: linear(channels, channels, vb.pp("to_q"))?,
            to_k: linear(channels, channels, vb.pp("to_k"))?,
            to_v: linear(channels, channels, vb.pp("to_v"))?,
            to_out: linear(channels, channels, vb.pp("to_out").pp("0"))?,
            heads: channels / d.max(1),
            rescale_output_factor,
            portable: false,
        })
    }
}

impl Module for Attention {
    fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let (b, c, h, w) = x.dims4()?;
        let (n, heads) = (h * w, self.heads);
        let d = c / heads;
        let tokens = self
            .group_norm
            .forward(x)?
            .reshape((b, c, n))?
            .transpose(1, 2)?
            .contiguous()?; // [B, N, C]
        let scale = 1.0 / (d as f32).sqrt();
        let o = if self.portable || !x.device().is_cpu() {
            let split = |t: Tensor| -> Result<Tensor> {
                t.reshape((b, n, heads, d))?.transpose(1, 2)?.contiguous() // [B, heads, N, d]
            };
            let q = split(self.to_q.forward(&tokens)?)?;
            let k = split(self.to_k.forward(&tokens)?)?;
            let v = split(self.to_v.forward(&tokens)?)?;
            let scores = q.matmul(&k.t()?)?.affine(f64::from(scale), 0.0)?;
            let attn = candle_nn::ops::softmax(&scores, candle_core::D::Minus1)?;
            attn.matmul(&v)?.transpose(1, 2)?.reshape((b, n, c))? // [B, N, C]
        } else {
            // One projection to [B, N, 3C] (q, k, v side by side), then the fused op.
            let (q, k, v) = (&self.to_q, &self.to_k, &self.to_v);
            let w_qkv = Tensor::cat(&[q.weight(), k.weight(), v.weight()], 0)?;
            let b_qkv = match (q.bias(), k.bias(), v.bias()) {
                (Some(bq), Some(bk), Some(bv)) => Tensor::cat(&[bq, bk, bv], 0)?,
                _ => candle_core::bail!("attention: the q, k and v projections need biases"),
            };
            let qkv = Linear::new(w_qkv, Some(b_qkv)).forward(&tokens)?;
            fused_attention(&qkv, heads, scale)?
        };
        let o = self
            .to_out
            .forward(&o)?
            .transpose(1, 2)?
            .reshape((b, c, h, w))?;
        let out = (o + x)?;
        if self.rescale_output_factor == 1.0 {
            Ok(out)
        } else {
            out.affine(1.0 / self.rescale_output_factor, 0.0)
        }
    }
}
