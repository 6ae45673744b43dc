//! Spatial self-attention of Ho et al.'s U-Net at the coarse levels (paper IV.B): diffusers `Attention` as built by
//! `AttnDownBlock2D` / `UNetMidBlock2D` (`_from_deprecated_attn_block=True`, `residual_connection=True`), run by
//! `AttnProcessor2_0` (`diffusers/models/attention_processor.py`).

use candle_core::{CpuStorage, CustomOp1, Layout, Module, Result, Shape, Tensor};
use candle_nn::{linear, Linear, VarBuilder};
use rayon::prelude::*;

use super::group_norm::{exp_f32, group_norm, simd_level, GroupNorm};

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
    /// Use candle's softmax instead of the fused CPU op (always on devices other than the CPU).
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
        let split = |t: Tensor| -> Result<Tensor> {
            t.reshape((b, n, heads, d))?.transpose(1, 2)?.contiguous() // [B, heads, N, d]
        };
        let q = split(self.to_q.forward(&tokens)?)?;
        let k = split(self.to_k.forward(&tokens)?)?;
        let v = split(self.to_v.forward(&tokens)?)?;
        let scores = q.matmul(&k.t()?)?;
        let scale = 1.0 / (d as f32).sqrt();
        let attn = if self.portable || !x.device().is_cpu() {
            candle_nn::ops::softmax(
                &scores.affine(f64::from(scale), 0.0)?,
                candle_core::D::Minus1,
            )?
        } else {
            scaled_softmax(&scores, scale)?
        };
        let o = attn.matmul(&v)?.transpose(1, 2)?.reshape((b, n, c))?; // [B, N, C]
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

/// `softmax(scale · x)` over the last dimension as one op (candle-nn's differentiable softmax is five tensor ops
/// plus the scaling, each a pass over the `[B, heads, N, N]` scores forward and backward). Backward:
/// `dx = scale · y ⊙ (dy − Σ dy ⊙ y)`.
pub fn scaled_softmax(x: &Tensor, scale: f32) -> Result<Tensor> {
    x.contiguous()?.apply_op1(ScaledSoftmax { scale })
}

#[derive(Clone, Copy, Debug)]
struct ScaledSoftmax {
    scale: f32,
}

/// Backward of [`ScaledSoftmax`] on `(y, dy)` packed as `[2, …]`.
#[derive(Clone, Copy, Debug)]
struct ScaledSoftmaxBackward {
    scale: f32,
}

impl CustomOp1 for ScaledSoftmax {
    fn name(&self) -> &'static str {
        "scaled-softmax"
    }

    fn cpu_fwd(&self, s: &CpuStorage, l: &Layout) -> Result<(CpuStorage, Shape)> {
        let x = super::contiguous_f32(s, l, "softmax: input")?;
        let n = l.shape().dims().last().copied().unwrap_or(1).max(1);
        // SAFETY: every row is written by softmax_rows.
        let mut y = unsafe { super::kernels::alloc::output_vec(x.len()) };
        let (scale, level) = (self.scale, simd_level());
        // Rows in blocks of ~16 K values per task (one row of N ≤ 4096 scores is too little work to schedule).
        let rows = (16384 / n).max(1) * n;
        y.par_chunks_mut(rows)
            .zip(x.par_chunks(rows))
            .for_each(|(yr, xr)| match level {
                #[cfg(target_arch = "x86_64")]
                // SAFETY: the CPU has these features (simd_level).
                2 => unsafe { simd::softmax_rows_avx512(xr, yr, n, scale) },
                #[cfg(target_arch = "x86_64")]
                // SAFETY: as above.
                1 => unsafe { simd::softmax_rows_avx2(xr, yr, n, scale) },
                _ => softmax_rows(xr, yr, n, scale),
            });
        Ok((CpuStorage::F32(y), l.shape().clone()))
    }

    fn bwd(&self, _x: &Tensor, y: &Tensor, dy: &Tensor) -> Result<Option<Tensor>> {
        let packed = Tensor::stack(&[y, &dy.contiguous()?], 0)?;
        let dx = packed.apply_op1_no_bwd(&ScaledSoftmaxBackward { scale: self.scale })?;
        Ok(Some(dx.reshape(y.shape())?))
    }
}

impl CustomOp1 for ScaledSoftmaxBackward {
    fn name(&self) -> &'static str {
        "scaled-softmax-backward"
    }

    fn cpu_fwd(&self, s: &CpuStorage, l: &Layout) -> Result<(CpuStorage, Shape)> {
        let both = super::contiguous_f32(s, l, "softmax: input")?;
        let dims = &l.shape().dims()[1..];
        let n = dims.last().copied().unwrap_or(1).max(1);
        let (y, dy) = both.split_at(both.len() / 2);
        // SAFETY: every element is written below.
        let mut dx = unsafe { super::kernels::alloc::output_vec(y.len()) };
        dx.par_chunks_mut(n)
            .zip(y.par_chunks(n).zip(dy.par_chunks(n)))
            .for_each(|(dxr, (yr, dyr))| {
                let dot = dot_lanes(yr, dyr);
                for ((o, &yv), &g) in dxr.iter_mut().zip(yr).zip(dyr) {
                    *o = self.scale * yv * (g - dot);
                }
            });
        Ok((CpuStorage::F32(dx), Shape::from(dims)))
    }
}

/// Lanes of the row loops: 16 independent maxima and partial sums, so the loops vectorise (a single running
/// `max`/`sum` is a serial dependency LLVM must keep scalar, and with it the `exp` of every score: a third of the
/// peer config's forward in `perf`).
const LANES: usize = 16;

/// `softmax(scale · x)` of every row of `n` values of `xr` into `yr`.
#[inline(always)]
fn softmax_rows(xr: &[f32], yr: &mut [f32], n: usize, scale: f32) {
    for (yrow, xrow) in yr.chunks_mut(n).zip(xr.chunks(n)) {
        let mut m = [f32::NEG_INFINITY; LANES];
        let xc = xrow.chunks_exact(LANES);
        for &v in xc.remainder() {
            m[0] = if v > m[0] { v } else { m[0] };
        }
        for c in xc {
            for l in 0..LANES {
                m[l] = if c[l] > m[l] { c[l] } else { m[l] };
            }
        }
        let max = m
            .iter()
            .fold(f32::NEG_INFINITY, |a, &b| if b > a { b } else { a });
        let mut s = [0f32; LANES];
        let mut yc = yrow.chunks_exact_mut(LANES);
        let mut xc = xrow.chunks_exact(LANES);
        for (yo, xi) in (&mut yc).zip(&mut xc) {
            for l in 0..LANES {
                let e = exp_f32((xi[l] - max) * scale);
                yo[l] = e;
                s[l] += e;
            }
        }
        for (o, &v) in yc.into_remainder().iter_mut().zip(xc.remainder()) {
            *o = exp_f32((v - max) * scale);
            s[0] += *o;
        }
        let inv = 1.0 / s.iter().sum::<f32>();
        yrow.iter_mut().for_each(|o| *o *= inv);
    }
}

/// `Σ a·b` over [`LANES`] interleaved partial sums.
fn dot_lanes(a: &[f32], b: &[f32]) -> f32 {
    let mut s = [0f32; LANES];
    let (ac, bc) = (a.chunks_exact(LANES), b.chunks_exact(LANES));
    for (x, y) in ac.remainder().iter().zip(bc.remainder()) {
        s[0] += x * y;
    }
    for (x, y) in ac.zip(bc) {
        for l in 0..LANES {
            s[l] += x[l] * y[l];
        }
    }
    s.iter().sum()
}

/// [`softmax_rows`] compiled for AVX-512 and for AVX2 + FMA, chosen at run time.
#[cfg(target_arch = "x86_64")]
mod simd {
    #[target_feature(enable = "avx512f,avx512vl,avx2,fma")]
    pub(super) unsafe fn softmax_rows_avx512(xr: &[f32], yr: &mut [f32], n: usize, scale: f32) {
        super::softmax_rows(xr, yr, n, scale)
    }

    #[target_feature(enable = "avx2,fma")]
    pub(super) unsafe fn softmax_rows_avx2(xr: &[f32], yr: &mut [f32], n: usize, scale: f32) {
        super::softmax_rows(xr, yr, n, scale)
    }
}
