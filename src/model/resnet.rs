//! ResNet blocks and resampling of Ho et al.'s U-Net (paper IV.B): diffusers `ResnetBlock2D`, `Downsample2D` and
//! `Upsample2D` (`diffusers/models/resnet.py`, `downsampling.py`, `upsampling.py`).

use candle_core::{CpuStorage, CustomOp1, Layout, Module, Result, Shape, Tensor};
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
    /// Every GroupNorm of the block.
    pub(crate) fn norms_mut(&mut self) -> [&mut super::group_norm::GroupNorm; 2] {
        [&mut self.norm1, &mut self.norm2]
    }

    /// Every convolution of the block.
    pub(crate) fn convs_mut(&mut self) -> impl Iterator<Item = &mut Conv2d> {
        [&mut self.conv1, &mut self.conv2]
            .into_iter()
            .chain(self.conv_shortcut.as_mut())
    }

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
        let t = self.time_emb_proj.forward(&temb.silu()?)?;
        let h = self.norm2.forward_shift_silu(&h, &t)?;
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
    /// Use candle's nearest-neighbour up-sampling instead of the CPU op (always on devices other than the CPU).
    pub portable: bool,
}

impl Upsample2D {
    pub fn new(vb: VarBuilder, channels: usize) -> Result<Self> {
        Ok(Self {
            conv: Conv2d::new(vb.pp("conv"), channels, channels, 3, 1, 1, true)?,
            portable: false,
        })
    }
}

/// Nearest-neighbour × 2 up-sampling `[B, C, H, W]` -> `[B, C, 2H, 2W]` (`F.interpolate(scale_factor=2,
/// mode="nearest")`) as one op whose backward sums each 2 × 2 cell (candle's broadcast + reshape version copies a
/// strided view forward and reduces a 6-D strided gradient backward).
pub fn upsample_nearest_x2(x: &Tensor) -> Result<Tensor> {
    x.dims4()?;
    x.contiguous()?.apply_op1(UpsampleX2)
}

#[derive(Clone, Copy, Debug)]
struct UpsampleX2;

/// The adjoint of [`UpsampleX2`]: `[B, C, 2H, 2W]` -> `[B, C, H, W]`, each output the sum of its 2 × 2 cell.
#[derive(Clone, Copy, Debug)]
struct SumPoolX2;

impl CustomOp1 for UpsampleX2 {
    fn name(&self) -> &'static str {
        "upsample-nearest-x2"
    }

    fn cpu_fwd(&self, s: &CpuStorage, l: &Layout) -> Result<(CpuStorage, Shape)> {
        let x = super::contiguous_f32(s, l, "upsample: input")?;
        let (b, c, h, w) = l.shape().dims4()?;
        let mut y = vec![0f32; 4 * x.len()];
        for (src, dst) in x.chunks(w).zip(y.chunks_mut(4 * w)) {
            let (top, bottom) = dst.split_at_mut(2 * w);
            for (pair, &v) in top.chunks_exact_mut(2).zip(src) {
                pair[0] = v;
                pair[1] = v;
            }
            bottom.copy_from_slice(top);
        }
        Ok((CpuStorage::F32(y), Shape::from((b, c, 2 * h, 2 * w))))
    }

    fn bwd(&self, _arg: &Tensor, _res: &Tensor, grad: &Tensor) -> Result<Option<Tensor>> {
        Ok(Some(grad.contiguous()?.apply_op1_no_bwd(&SumPoolX2)?))
    }
}

impl CustomOp1 for SumPoolX2 {
    fn name(&self) -> &'static str {
        "sum-pool-x2"
    }

    fn cpu_fwd(&self, s: &CpuStorage, l: &Layout) -> Result<(CpuStorage, Shape)> {
        let g = super::contiguous_f32(s, l, "upsample: input")?;
        let (b, c, h2, w2) = l.shape().dims4()?;
        let (h, w) = (h2 / 2, w2 / 2);
        let mut x = vec![0f32; b * c * h * w];
        for (dst, src) in x.chunks_mut(w).zip(g.chunks(4 * w)) {
            let (top, bottom) = src.split_at(2 * w);
            for ((o, t), u) in dst
                .iter_mut()
                .zip(top.chunks_exact(2))
                .zip(bottom.chunks_exact(2))
            {
                *o = (t[0] + t[1]) + (u[0] + u[1]);
            }
        }
        Ok((CpuStorage::F32(x), Shape::from((b, c, h, w))))
    }
}

impl Module for Upsample2D {
    fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let up = if self.portable || !x.device().is_cpu() {
            let (_, _, h, w) = x.dims4()?;
            x.upsample_nearest2d(2 * h, 2 * w)?
        } else {
            upsample_nearest_x2(x)?
        };
        self.conv.forward(&up)
    }
}
