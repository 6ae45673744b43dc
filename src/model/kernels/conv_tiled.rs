//! Tiled im2col + GEMM convolution (paper IV.B, speed on the CPU): the default convolution of the U-Net.
//!
//! Measured first: a full im2col of a batch-16 64 × 64 layer is 75–250 MB, written, zeroed and read again, so
//! the plain im2col path ([`super::conv`]) is memory-bound at the U-Net's small channel counts. Here each work item
//! is one sample × one tile of output pixels: its im2col block (`K × T`, ≤ 512 KB) stays in cache and goes straight
//! into a GEMM ([`super::sgemm`]: AVX-512 kernels where the CPU has them, else the `gemm` crate) that writes the
//! NCHW output in place (each row started from its bias, no transpose). The backward, per sample, re-forms each
//! tile's block to accumulate `dWᵀ += cols·dYᵀ` and scatters `Wᵀ·dY` back (col2im). Work is split by
//! sample (and by tile for a single-sample forward) with a fixed summation order, so results are deterministic.

use std::sync::Arc;

use candle_core::{CpuStorage, CustomOp3, Layout, Result, Shape, Tensor};
use rayon::prelude::*;

use super::sgemm::{matmul_nt, GemmBackend, Init, PackedA};
use super::ConvGeom;

/// Forward op on `(x [B,Cin,H,W], w [Cout,Cin,k,k], bias [Cout])`.
#[derive(Clone, Debug)]
pub struct TiledConv {
    pub geom: ConvGeom,
    /// `w` packed once for inference (used when it fits, else `w` is packed per call).
    pub frozen: Option<Arc<PackedA>>,
}

/// Backward op on `(x, w, dy)` returning `[dx…, dw…, db…]` flat.
#[derive(Clone, Copy, Debug)]
struct TiledConvBackward {
    geom: ConvGeom,
}

/// Convolution by the tiled path (differentiable).
pub fn conv2d_tiled(
    x: &Tensor,
    w: &Tensor,
    bias: &Tensor,
    geom: ConvGeom,
    frozen: Option<&Arc<PackedA>>,
) -> Result<Tensor> {
    let op = TiledConv {
        geom,
        frozen: frozen.cloned(),
    };
    x.contiguous()?
        .apply_op3(&w.contiguous()?, &bias.contiguous()?, op)
}

struct Dims {
    b: usize,
    c: usize,
    h: usize,
    w: usize,
    ho: usize,
    wo: usize,
    k: usize,
    tile: usize,
}

impl Dims {
    fn new(x: &[usize], g: ConvGeom) -> Result<Self> {
        let [b, c, h, w] = x else {
            candle_core::bail!("conv: input must be 4-D, found {x:?}")
        };
        let (b, c, h, w) = (*b, *c, *h, *w);
        if h + g.pad_begin + g.pad_end < g.kernel || w + g.pad_begin + g.pad_end < g.kernel {
            candle_core::bail!("conv: input {h}x{w} smaller than the kernel");
        }
        let ho = (h + g.pad_begin + g.pad_end - g.kernel) / g.stride + 1;
        let wo = (w + g.pad_begin + g.pad_end - g.kernel) / g.stride + 1;
        let k = c * g.kernel * g.kernel;
        // A K × T block of at most 128 Ki floats (512 KB).
        let tile = (131072 / k.max(1)).max(32).min(ho * wo);
        Ok(Self {
            b,
            c,
            h,
            w,
            ho,
            wo,
            k,
            tile,
        })
    }
    fn tiles(&self) -> usize {
        (self.ho * self.wo).div_ceil(self.tile)
    }
}

/// im2col of output pixels `p0..p0+t` of one sample `x` `[C, H, W]` into `cols` `[K, t]`.
fn im2col_tile(x: &[f32], d: &Dims, g: ConvGeom, p0: usize, t: usize, cols: &mut [f32]) {
    let (k, s, p) = (g.kernel, g.stride, g.pad_begin as isize);
    for ci in 0..d.c {
        let plane = &x[ci * d.h * d.w..(ci + 1) * d.h * d.w];
        for i in 0..k {
            for j in 0..k {
                let row = &mut cols[((ci * k + i) * k + j) * t..((ci * k + i) * k + j + 1) * t];
                let mut q = 0;
                while q < t {
                    let (oy, ox0) = ((p0 + q) / d.wo, (p0 + q) % d.wo);
                    let run = (d.wo - ox0).min(t - q);
                    let dst = &mut row[q..q + run];
                    let iy = (oy * s + i) as isize - p;
                    if iy < 0 || iy >= d.h as isize {
                        dst.fill(0.0);
                    } else {
                        let src = &plane[iy as usize * d.w..(iy as usize + 1) * d.w];
                        if s == 1 {
                            // ix = ox + shift: zeros, one contiguous copy, zeros.
                            let shift = j as isize - p;
                            let lo = ((-shift - ox0 as isize).max(0) as usize).min(run);
                            let hi = ((d.w as isize - shift - ox0 as isize).max(0) as usize)
                                .min(run)
                                .max(lo);
                            dst[..lo].fill(0.0);
                            let a = (ox0 as isize + lo as isize + shift) as usize;
                            dst[lo..hi].copy_from_slice(&src[a..a + (hi - lo)]);
                            dst[hi..].fill(0.0);
                        } else {
                            for (o, v) in dst.iter_mut().enumerate() {
                                let ix = ((ox0 + o) * s + j) as isize - p;
                                *v = if ix >= 0 && ix < d.w as isize {
                                    src[ix as usize]
                                } else {
                                    0.0
                                };
                            }
                        }
                    }
                    q += run;
                }
            }
        }
    }
}

/// Scatter-add `cols` `[K, t]` of output pixels `p0..p0+t` into one sample's `dx` `[C, H, W]` (adjoint of
/// [`im2col_tile`]).
fn col2im_tile(cols: &[f32], d: &Dims, g: ConvGeom, p0: usize, t: usize, dx: &mut [f32]) {
    let (k, s, p) = (g.kernel, g.stride, g.pad_begin as isize);
    for ci in 0..d.c {
        let plane = &mut dx[ci * d.h * d.w..(ci + 1) * d.h * d.w];
        for i in 0..k {
            for j in 0..k {
                let row = &cols[((ci * k + i) * k + j) * t..((ci * k + i) * k + j + 1) * t];
                let mut q = 0;
                while q < t {
                    let (oy, ox0) = ((p0 + q) / d.wo, (p0 + q) % d.wo);
                    let run = (d.wo - ox0).min(t - q);
                    let iy = (oy * s + i) as isize - p;
                    if iy >= 0 && iy < d.h as isize {
                        let dst = &mut plane[iy as usize * d.w..(iy as usize + 1) * d.w];
                        let src = &row[q..q + run];
                        if s == 1 {
                            let shift = j as isize - p;
                            let lo = ((-shift - ox0 as isize).max(0) as usize).min(run);
                            let hi = ((d.w as isize - shift - ox0 as isize).max(0) as usize)
                                .min(run)
                                .max(lo);
                            let a = (ox0 as isize + lo as isize + shift) as usize;
                            for (o, v) in dst[a..a + (hi - lo)].iter_mut().zip(&src[lo..hi]) {
                                *o += v;
                            }
                        } else {
                            for (o, v) in src.iter().enumerate() {
                                let ix = ((ox0 + o) * s + j) as isize - p;
                                if ix >= 0 && ix < d.w as isize {
                                    dst[ix as usize] += v;
                                }
                            }
                        }
                    }
                    q += run;
                }
            }
        }
    }
}

/// A raw pointer that may cross threads; every use writes a region no other work item touches.
#[derive(Clone, Copy)]
pub(super) struct SendPtr(pub(super) *mut f32);
unsafe impl Send for SendPtr {}
unsafe impl Sync for SendPtr {}

impl SendPtr {
    /// The pointer (a method, so closures capture the whole `Sync` wrapper rather than the raw field).
    pub(super) fn ptr(self) -> *mut f32 {
        self.0
    }
}

impl CustomOp3 for TiledConv {
    fn name(&self) -> &'static str {
        "conv2d-tiled"
    }

    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
        s3: &CpuStorage,
        l3: &Layout,
    ) -> Result<(CpuStorage, Shape)> {
        let g = self.geom;
        let x = super::simd::contiguous_f32(s1, l1, "conv: input")?;
        let w = super::simd::contiguous_f32(s2, l2, "conv: weight")?;
        let bias = super::simd::contiguous_f32(s3, l3, "conv: bias")?;
        let co = l2.shape().dims()[0];
        let d = Dims::new(l1.shape().dims(), g)?;
        if w.len() != co * d.k || bias.len() != co {
            candle_core::bail!(
                "conv: weight {:?} / bias {} do not fit input {:?}",
                l2.shape(),
                bias.len(),
                l1.shape()
            );
        }
        let hw = d.ho * d.wo;
        // The GEMM starts every output row from its bias (no pre-filled output to read back); the tiles cover y.
        // SAFETY: every (sample, tile) item writes all co rows of its columns.
        let mut y = unsafe { super::alloc::output_vec(d.b * co * hw) };
        let yp = SendPtr(y.as_mut_ptr());
        let w_packed =
            PackedA::frozen_or_pack(self.frozen.as_deref(), GemmBackend::detect(), co, d.k, w)?;
        let items: Vec<(usize, usize)> = (0..d.b)
            .flat_map(|b| (0..d.tiles()).map(move |t| (b, t)))
            .collect();
        items.par_iter().try_for_each_init(
            || vec![0f32; d.k * d.tile],
            |cols, &(b, tile)| {
                let p0 = tile * d.tile;
                let t = d.tile.min(hw - p0);
                let xb = &x[b * d.c * d.h * d.w..(b + 1) * d.c * d.h * d.w];
                im2col_tile(xb, &d, g, p0, t, &mut cols[..d.k * t]);
                // SAFETY: C is columns p0..p0+t of sample b's [Cout, HW] block of `y` (row stride hw), inside `y`
                // and disjoint across work items.
                unsafe {
                    w_packed.matmul_raw(
                        t,
                        &cols[..d.k * t],
                        t,
                        yp.ptr().add(b * co * hw + p0),
                        hw,
                        Init::RowBias(bias),
                    )
                }
            },
        )?;
        Ok((CpuStorage::F32(y), Shape::from((d.b, co, d.ho, d.wo))))
    }

    fn bwd(
        &self,
        x: &Tensor,
        w: &Tensor,
        _bias: &Tensor,
        _res: &Tensor,
        grad: &Tensor,
    ) -> Result<(Option<Tensor>, Option<Tensor>, Option<Tensor>)> {
        super::conv_direct::conv_grads(x, w, grad, &TiledConvBackward { geom: self.geom })
    }
}

impl CustomOp3 for TiledConvBackward {
    fn name(&self) -> &'static str {
        "conv2d-tiled-backward"
    }

    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
        s3: &CpuStorage,
        l3: &Layout,
    ) -> Result<(CpuStorage, Shape)> {
        let g = self.geom;
        let x = super::simd::contiguous_f32(s1, l1, "conv: input")?;
        let w = super::simd::contiguous_f32(s2, l2, "conv: weight")?;
        let dy = super::simd::contiguous_f32(s3, l3, "conv: output gradient")?;
        let co = l2.shape().dims()[0];
        let d = Dims::new(l1.shape().dims(), g)?;
        let hw = d.ho * d.wo;
        let (in_len, k) = (d.c * d.h * d.w, d.k);
        if dy.len() != d.b * co * hw {
            candle_core::bail!("conv backward: gradient {:?} does not fit", l3.shape());
        }
        // out = [dx (col2im accumulates: zeroed), dw, db].
        let mut out = vec![0f32; d.b * in_len + co * k + co];
        let (dx, rest) = out.split_at_mut(d.b * in_len);
        let (dw, db) = rest.split_at_mut(co * k);
        // Per sample dWᵀ [K, Cout]: cols · dYᵀ keeps the long pixel axis as the summed one and the small channel
        // axis as C's rows, the shape the GEMM kernels run fastest (see `sgemm::avx512::gemm_nt`).
        let mut dwt_parts = vec![0f32; d.b * k * co];
        let mut db_parts = vec![0f64; d.b * co];
        // A = Wᵀ [K, Cout] read in place from W [Cout, K].
        let wt_packed = PackedA::new(k, co, w, 1, k)?;
        let backend = wt_packed.backend();
        dx.par_chunks_mut(in_len)
            .zip(dwt_parts.par_chunks_mut(k * co))
            .zip(db_parts.par_chunks_mut(co))
            .enumerate()
            .try_for_each_init(
                || (vec![0f32; k * d.tile], vec![0f32; k * d.tile]),
                |(cols, dcols), (b, ((dxb, dwtb), dbb))| -> Result<()> {
                    let xb = &x[b * in_len..(b + 1) * in_len];
                    let dyb = &dy[b * co * hw..(b + 1) * co * hw];
                    for (s, row) in dbb.iter_mut().zip(dyb.chunks(hw)) {
                        *s = super::conv_direct::sum_f64(row);
                    }
                    for tile in 0..d.tiles() {
                        let p0 = tile * d.tile;
                        let t = d.tile.min(hw - p0);
                        let cols = &mut cols[..k * t];
                        im2col_tile(xb, &d, g, p0, t, cols);
                        // dWᵀ_b[k, co] += cols[k, t] · dY[co, p0..p0+t]ᵀ
                        matmul_nt(
                            backend,
                            (k, co, t),
                            cols,
                            t,
                            &dyb[p0..],
                            hw,
                            dwtb,
                            co,
                            tile > 0,
                        )?;
                        // dcols[k, t] = Wᵀ[k, co] · dY[co, p0..p0+t]
                        wt_packed.matmul(t, &dyb[p0..], hw, &mut dcols[..k * t], t, Init::Zero)?;
                        col2im_tile(&dcols[..k * t], &d, g, p0, t, dxb);
                    }
                    Ok(())
                },
            )?;
        super::conv_direct::sum_parts(&dwt_parts, &db_parts, dw, db);
        let n = out.len();
        Ok((CpuStorage::F32(out), Shape::from(n)))
    }
}
