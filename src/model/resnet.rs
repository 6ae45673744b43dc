//! ResNet blocks and resampling of Ho et al.'s U-Net (paper IV.B): diffusers `ResnetBlock2D`, `Downsample2D` and
//! `Upsample2D` (`diffusers/models/resnet.py`, `downsampling.py`, `upsampling.py`).

use candle_core::{Module, Result, Tensor};
use candle_nn::{linear, Linear, VarBuilder};

use super::group_norm::{group_norm, GroupNorm};

use super::conv::{Conv2d, ConvGeom};

/// diffusers `ResnetBlock2D` (pre-norm, `time_embedding_norm="default"`):
/// `out = (shortcut(x) + conv2(drop(silu(norm2(conv1(silu(norm1(x))) + proj(silu(temb))))))) / output_scale_factor`.
#[derive(Clone, Debug)]
pub struct ResnetBlock2D {
    pub norm1: GroupNorm,
    pub conv1: Conv2d,
    pub time_emb_proj: Linear,
    pub norm2: GroupNorm,
    pub conv2: Conv2d,
    /// 1 × 1 convolution when the channel count changes.
    pub conv_shortcut: Option<Conv2d>,
    pub output_scale_factor: f64,
    /// Dropout probability (training only).
    pub dropout: f32,
}

/// Settings shared by all ResNet blocks of a model.
#[derive(Clone, Copy, Debug)]
pub struct ResnetCfg {
    pub temb_channels: usize,
    pub groups: usize,
    pub eps: f64,
    pub output_scale_factor: f64,
    pub dropout: f32,
}

impl ResnetBlock2D {
    pub fn new(vb: VarBuilder, c_in: usize, c_out: usize, cfg: ResnetCfg) -> Result<Self> {
        let conv_shortcut = if c_in != c_out {
            Some(Conv2d::new(
                vb.pp("conv_shortcut"),
                c_in,
                c_out,
                1,
                1,
                0,
                true,
            )?)
        } else {
            None
        };
        Ok(Self {
            norm1: group_norm(cfg.groups, c_in, cfg.eps, vb.pp("norm1"))?,
            conv1: Conv2d::new(vb.pp("conv1"), c_in, c_out, 3, 1, 1, true)?,
            time_emb_proj: linear(cfg.temb_channels, c_out, vb.pp("time_emb_proj"))?,
            norm2: group_norm(cfg.groups, c_out, cfg.eps, vb.pp("norm2"))?,
            conv2: Conv2d::new(vb.pp("conv2"), c_out, c_out, 3, 1, 1, true)?,
            conv_shortcut,
            output_scale_factor: cfg.output_scale_factor,
            dropout: cfg.dropout,
        })
    }

    /// `x` `[B, Cin, H, W]`, `temb` `[B, T]` -> `[B, Cout, H, W]`; dropout only when `train`.
    pub fn forward(&self, x: &Tensor, temb: &Tensor, train: bool) -> Result<Tensor> {
        let h = self.conv1.forward(&self.norm1.forward_silu(x)?)?;
        let t = self
            .time_emb_proj
            .forward(&temb.silu()?)?
            .unsqueeze(2)?
            .unsqueeze(3)?;
        let h = self.norm2.forward_silu(&h.broadcast_add(&t)?)?;
        let h = if train && self.dropout > 0.0 {
            candle_nn::ops::dropout(&h, self.dropout)?
        } else {
            h
        };
        let h = self.conv2.forward(&h)?;
        let shortcut = match &self.conv_shortcut {
            Some(c) => c.forward(x)?,
            None => x.clone(),
        };
        let out = (shortcut + h)?;
        if self.output_scale_factor == 1.0 {
            Ok(out)
        } else {
            out.affine(1.0 / self.output_scale_factor, 0.0)
        }
    }
}

/// diffusers `Downsample2D(use_conv=True)`: a 3 × 3 stride-2 convolution, key `conv`. With `padding = 0` diffusers
/// pads one zero row/column at the bottom/right first, which [`ConvGeom`] expresses directly.
#[derive(Clone, Debug)]
pub struct Downsample2D {
    pub conv: Conv2d,
}

impl Downsample2D {
    pub fn new(vb: VarBuilder, channels: usize, padding: usize) -> Result<Self> {
        let mut conv = Conv2d::new(vb.pp("conv"), channels, channels, 3, 2, padding, true)?;
        if padding == 0 {
            conv.geom = ConvGeom {
                kernel: 3,
                stride: 2,
                pad_begin: 0,
                pad_end: 1,
            };
        }
        Ok(Self { conv })
    }
}

impl Module for Downsample2D {
    fn forward(&self, x: &Tensor) -> Result<Tensor> {
        self.conv.forward(x)
    }
}

/// diffusers `Upsample2D(use_conv=True)`: nearest-neighbour × 2 (`F.interpolate(mode="nearest")`), then a 3 × 3
/// convolution, key `conv`.
#[derive(Clone, Debug)]
pub struct Upsample2D {
    pub conv: Conv2d,
}

impl Upsample2D {
    pub fn new(vb: VarBuilder, channels: usize) -> Result<Self> {
        Ok(Self {
            conv: Conv2d::new(vb.pp("conv"), channels, channels, 3, 1, 1, true)?,
        })
    }
}

/// Nearest-neighbour × 2 up-sampling built from broadcast + reshape (differentiable: the backward sums 2 × 2 cells).
pub fn upsample_nearest_x2(x: &Tensor) -> Result<Tensor> {
    let (b, c, h, w) = x.dims4()?;
    x.reshape((b, c, h, 1, w, 1))?
        .broadcast_as((b, c, h, 2, w, 2))?
        .reshape((b, c, 2 * h, 2 * w))
}

impl Module for Upsample2D {
    fn forward(&self, x: &Tensor) -> Result<Tensor> {
        self.conv.forward(&upsample_nearest_x2(x)?)
    }
}
