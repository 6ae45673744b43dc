//! Spatial self-attention of Ho et al.'s U-Net at the coarse levels (paper IV.B): diffusers `Attention` as built by
//! `AttnDownBlock2D` / `UNetMidBlock2D` (`_from_deprecated_attn_block=True`, `residual_connection=True`), run by
//! `AttnProcessor2_0` (`diffusers/models/attention_processor.py`).

use std::sync::Arc;

use candle_core::{Module, Result, Tensor};
use candle_nn::{linear, Linear, VarBuilder};

use super::conv::{conv2d, pack_weight, ConvBackend, ConvGeom};
use super::group_norm::{group_norm, GroupNorm};
use super::kernels::attention::fused_attention;
use super::kernels::sgemm::PackedA;

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
    /// The q/k/v and `to_out` projection weights packed once for inference ([`Attention::freeze`]).
    pub frozen: Option<(Arc<PackedA>, Arc<PackedA>)>,
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
            frozen: None,
        })
    }
}

impl Attention {
    /// The q, k, v projections as one 1 × 1 convolution: weight `[3C, C, 1, 1]` (to_q's rows, then to_k's, then
    /// to_v's) and bias `[3C]`.
    fn qkv_conv(&self) -> Result<(Tensor, Tensor)> {
        let (q, k, v) = (&self.to_q, &self.to_k, &self.to_v);
        let w = Tensor::cat(&[q.weight(), k.weight(), v.weight()], 0)?;
        let b = match (q.bias(), k.bias(), v.bias()) {
            (Some(bq), Some(bk), Some(bv)) => Tensor::cat(&[bq, bk, bv], 0)?,
            _ => candle_core::bail!("attention: the q, k and v projections need biases"),
        };
        let (c3, c) = w.dims2()?;
        Ok((w.reshape((c3, c, 1, 1))?, b))
    }

    /// `to_out` as a 1 × 1 convolution: weight `[C, C, 1, 1]`, bias `[C]`.
    fn out_conv(&self) -> Result<(Tensor, Tensor)> {
        let w = self.to_out.weight();
        let (co, c) = w.dims2()?;
        let Some(b) = self.to_out.bias() else {
            candle_core::bail!("attention: to_out needs a bias")
        };
        Ok((w.reshape((co, c, 1, 1))?, b.clone()))
    }

    /// Packs the projection weights once for inference (as [`super::conv::Conv2d::freeze`]).
    pub fn freeze(&mut self) -> Result<()> {
        let qkv = pack_weight(&self.qkv_conv()?.0)?;
        let out = pack_weight(&self.out_conv()?.0)?;
        self.frozen = qkv.zip(out);
        Ok(())
    }

    /// Drops what [`Attention::freeze`] packed.
    pub fn thaw(&mut self) {
        self.frozen = None;
    }

    /// The fused CPU path: q, k, v by one 1 × 1 convolution of the normalised image (channel-major `[B, 3C, N]`,
    /// no token transpose), the fused attention op, `to_out` as a 1 × 1 convolution back to `[B, C, H, W]`.
    fn forward_fused(&self, x: &Tensor) -> Result<Tensor> {
        let (b, c, h, w) = x.dims4()?;
        let d = c / self.heads.max(1);
        let one = ConvGeom {
            kernel: 1,
            stride: 1,
            pad_begin: 0,
            pad_end: 0,
        };
        let frozen = self.frozen.as_ref();
        let (w_qkv, b_qkv) = self.qkv_conv()?;
        let hn = self.group_norm.forward(x)?;
        let qkv = conv2d(
            &hn,
            &w_qkv,
            Some(&b_qkv),
            one,
            ConvBackend::Direct,
            frozen.map(|f| &f.0),
        )?;
        let o = fused_attention(
            &qkv.reshape((b, 3 * c, h * w))?,
            self.heads,
            1.0 / (d as f32).sqrt(),
        )?;
        let (w_out, b_out) = self.out_conv()?;
        conv2d(
            &o.reshape((b, c, h, w))?,
            &w_out,
            Some(&b_out),
            one,
            ConvBackend::Direct,
            frozen.map(|f| &f.1),
        )
    }

    /// candle's own ops (what devices other than the CPU run): token-major q, k, v by `Linear`, matmul and softmax.
    fn forward_portable(&self, x: &Tensor) -> Result<Tensor> {
        let (b, c, h, w) = x.dims4()?;
        let (n, heads) = (h * w, self.heads);
        let d = c / heads;
        let tokens = self
            .group_norm
            .forward(x)?
            .reshape((b, c, n))?
            .transpose(1, 2)?
            .contiguous()?; // [B, N, C]
        let scale = 1.0 / (d as f64).sqrt();
        let split = |t: Tensor| -> Result<Tensor> {
            t.reshape((b, n, heads, d))?.transpose(1, 2)?.contiguous() // [B, heads, N, d]
        };
        let q = split(self.to_q.forward(&tokens)?)?;
        let k = split(self.to_k.forward(&tokens)?)?;
        let v = split(self.to_v.forward(&tokens)?)?;
        let scores = q.matmul(&k.t()?)?.affine(scale, 0.0)?;
        let attn = candle_nn::ops::softmax(&scores, candle_core::D::Minus1)?;
        let o = attn.matmul(&v)?.transpose(1, 2)?.reshape((b, n, c))?; // [B, N, C]
        self.to_out
            .forward(&o)?
            .transpose(1, 2)?
            .reshape((b, c, h, w))
    }
}

impl Module for Attention {
    fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let o = if self.portable || !x.device().is_cpu() {
            self.forward_portable(x)?
        } else {
            self.forward_fused(x)?
        };
        let out = (o + x)?;
        if self.rescale_output_factor == 1.0 {
            Ok(out)
        } else {
            out.affine(1.0 / self.rescale_output_factor, 0.0)
        }
    }
}
