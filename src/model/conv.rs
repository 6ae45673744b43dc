//! 2-D convolution of the U-Net (paper IV.B) and the choice of implementation: candle's `conv2d`, a full im2col +
//! one large GEMM (this file), the cache-tiled im2col custom op of [`super::conv_tiled`], or the direct
//! (implicit-GEMM) op of [`super::conv_direct`] for stride-1 "same" convolutions (the default where the CPU has
//! AVX-512; the tiled op runs every other geometry and CPU).
//!
//! candle 0.11's CPU `conv2d` reaches ~20 GFLOP/s forward and its backward goes through `conv_transpose2d`
//! (~10 GFLOP/s), while its GEMM reaches ~80 GFLOP/s on the same 2 cores. Here a convolution is
//! `W[Cout, Cin·kh·kw] @ cols[Cin·kh·kw, B·Ho·Wo]`: [`Im2Col`] is a custom op whose backward is the adjoint
//! scatter ([`Col2Im`]); the GEMM, bias and layout change are ordinary candle ops, so autograd handles the rest.
//! Tests check it against candle's `conv2d` forward and backward.

use candle_core::{CpuStorage, CustomOp1, Layout, Module, Result, Shape, Tensor};
use candle_nn::VarBuilder;

use std::sync::Arc;

use super::kernels::sgemm::{GemmBackend, PackedA};
use rayon::prelude::*;

/// Which convolution implementation a model uses (per model: [`super::UNet2DModel::set_conv_backend`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ConvBackend {
    /// candle's `Tensor::conv2d` (and its `conv_transpose2d`-based backward).
    Candle,
    /// Our im2col + GEMM path through candle's matmul (full im2col buffer).
    Im2colGemm,
    /// Our cache-tiled im2col + GEMM custom op ([`super::conv_tiled`]).
    Tiled,
    /// Our direct convolution ([`super::conv_direct`]) where the geometry allows it and the CPU has AVX-512,
    /// else [`ConvBackend::Tiled`] (default).
    #[default]
    Direct,
}

pub use super::kernels::ConvGeom;

/// `nn.Conv2d` with the keys `weight` `[Cout, Cin, k, k]` and `bias` `[Cout]` (optional).
#[derive(Clone, Debug)]
pub struct Conv2d {
    pub weight: Tensor,
    pub bias: Option<Tensor>,
    pub geom: ConvGeom,
    /// The implementation (default: [`ConvBackend::Direct`]).
    pub backend: ConvBackend,
    /// The weight packed once for inference by [`Conv2d::freeze`] (our CPU paths; `None`: packed per call).
    pub frozen: Option<Arc<PackedA>>,
}

impl Conv2d {
    /// A square `kernel` convolution with symmetric `padding`.
    pub fn new(
        vb: VarBuilder,
        c_in: usize,
        c_out: usize,
        kernel: usize,
        stride: usize,
        padding: usize,
        bias: bool,
    ) -> Result<Self> {
        let weight = vb.get((c_out, c_in, kernel, kernel), "weight")?;
        let bias = if bias {
            Some(vb.get(c_out, "bias")?)
        } else {
            None
        };
        Ok(Self {
            weight,
            bias,
            backend: ConvBackend::default(),
            frozen: None,
            geom: ConvGeom {
                kernel,
                stride,
                pad_begin: padding,
                pad_end: padding,
            },
        })
    }
}

impl Conv2d {
    /// Packs the weight once for the CPU GEMM, for inference: our convolutions otherwise re-pack it on every call,
    /// which at batch 1 was an eighth of a forward pass, on one thread. Later changes of the weight's values are
    /// not seen until [`Conv2d::thaw`] (or another `freeze`): freeze a model whose weights are final (a loaded
    /// checkpoint), never one being trained. Nothing happens off the CPU.
    pub fn freeze(&mut self) -> Result<()> {
        self.frozen = pack_weight(&self.weight)?;
        Ok(())
    }

    /// Drops the weight packed by [`Conv2d::freeze`]: every call packs the current weight again.
    pub fn thaw(&mut self) {
        self.frozen = None;
    }
}

impl Module for Conv2d {
    fn forward(&self, x: &Tensor) -> Result<Tensor> {
        conv2d(
            x,
            &self.weight,
            self.bias.as_ref(),
            self.geom,
            self.backend,
            self.frozen.as_ref(),
        )
    }
}

/// A convolution weight `[Cout, …]` packed as the `Cout × (Cin·k·k)` GEMM operand of our CPU paths (`None` off the
/// CPU): what [`Conv2d::freeze`] and the attention projections keep.
pub fn pack_weight(w: &Tensor) -> Result<Option<Arc<PackedA>>> {
    if !w.device().is_cpu() {
        return Ok(None);
    }
    let co = w.dim(0)?;
    let v = w.flatten_all()?.to_vec1::<f32>()?;
    let k = v.len() / co.max(1);
    Ok(Some(Arc::new(PackedA::new(co, k, &v, k, 1)?)))
}

/// Convolution of `x` `[B, Cin, H, W]` with `w` `[Cout, Cin, k, k]` plus `bias`, by the chosen backend; `frozen`
/// is `w` packed for our CPU paths ([`Conv2d::freeze`]), used where it fits.
pub fn conv2d(
    x: &Tensor,
    w: &Tensor,
    bias: Option<&Tensor>,
    geom: ConvGeom,
    backend: ConvBackend,
    frozen: Option<&Arc<PackedA>>,
) -> Result<Tensor> {
    let (b, _c_in, h, wd) = x.dims4()?;
    let c_out = w.dim(0)?;
    let y = match backend {
        ConvBackend::Tiled | ConvBackend::Direct => {
            let zeros;
            let bias = match bias {
                Some(b) => b,
                None => {
                    zeros = Tensor::zeros(c_out, x.dtype(), x.device())?;
                    &zeros
                }
            };
            let direct = backend == ConvBackend::Direct
                && super::kernels::conv_direct::supports(geom)
                && GemmBackend::detect() == GemmBackend::Avx512;
            if direct {
                super::kernels::conv_direct::conv2d_direct(x, w, bias, geom, frozen)?
            } else {
                super::kernels::conv_tiled::conv2d_tiled(x, w, bias, geom, frozen)?
            }
        }
        ConvBackend::Candle => {
            let x = if geom.pad_begin == geom.pad_end {
                x.clone()
            } else {
                x.pad_with_zeros(2, geom.pad_begin, geom.pad_end)?
                    .pad_with_zeros(3, geom.pad_begin, geom.pad_end)?
            };
            let pad = if geom.pad_begin == geom.pad_end {
                geom.pad_begin
            } else {
                0
            };
            let y = x.conv2d(w, pad, geom.stride, 1, 1)?;
            match bias {
                Some(bias) => y.broadcast_add(&bias.reshape((1, c_out, 1, 1))?)?,
                None => y,
            }
        }
        ConvBackend::Im2colGemm => {
            let (ho, wo) = (geom.out_size(h), geom.out_size(wd));
            let cols = x.contiguous()?.apply_op1(Im2Col { geom })?; // [K, B*Ho*Wo]
            let k = cols.dim(0)?;
            let y = w.reshape((c_out, k))?.matmul(&cols)?; // [Cout, B*Ho*Wo]
            let y = match bias {
                Some(bias) => y.broadcast_add(&bias.reshape((c_out, 1))?)?,
                None => y,
            };
            if b == 1 {
                y.reshape((1, c_out, ho, wo))?
            } else {
                y.reshape((c_out, b, ho, wo))?
                    .transpose(0, 1)?
                    .contiguous()?
            }
        }
    };
    Ok(y)
}

/// `[B, C, H, W]` -> `[C·k·k, B·Ho·Wo]`; row `(c·k + i)·k + j` holds input pixel `(oy·s + i − p, ox·s + j − p)`.
#[derive(Clone, Copy, Debug)]
pub struct Im2Col {
    pub geom: ConvGeom,
}

/// The adjoint of [`Im2Col`]: scatter-add `[C·k·k, B·Ho·Wo]` back to `[B, C, H, W]`.
#[derive(Clone, Copy, Debug)]
pub struct Col2Im {
    pub geom: ConvGeom,
    pub dims: (usize, usize, usize, usize),
}

impl CustomOp1 for Im2Col {
    fn name(&self) -> &'static str {
        "im2col"
    }

    fn cpu_fwd(&self, storage: &CpuStorage, layout: &Layout) -> Result<(CpuStorage, Shape)> {
        let x = super::contiguous_f32(storage, layout, "im2col: input")?;
        let (b, c, h, w) = layout.shape().dims4()?;
        let g = self.geom;
        let (k, s, p) = (g.kernel, g.stride, g.pad_begin as isize);
        let (ho, wo) = (g.out_size(h), g.out_size(w));
        let n = b * ho * wo;
        let mut cols = vec![0f32; c * k * k * n];
        cols.par_chunks_mut(n).enumerate().for_each(|(row, out)| {
            let (ci, i, j) = (row / (k * k), (row / k) % k, row % k);
            for bi in 0..b {
                let plane = &x[(bi * c + ci) * h * w..(bi * c + ci + 1) * h * w];
                for oy in 0..ho {
                    let iy = (oy * s + i) as isize - p;
                    let dst = &mut out[(bi * ho + oy) * wo..(bi * ho + oy + 1) * wo];
                    if iy < 0 || iy >= h as isize {
                        continue; // stays zero
                    }
                    let src = &plane[iy as usize * w..(iy as usize + 1) * w];
                    if s == 1 {
                        // ix = ox + j - p: copy the valid run in one go.
                        let shift = j as isize - p;
                        let lo = (-shift).max(0) as usize;
                        let hi = ((w as isize - shift).min(wo as isize)).max(0) as usize;
                        if hi > lo {
                            let a = (lo as isize + shift) as usize;
                            dst[lo..hi].copy_from_slice(&src[a..a + (hi - lo)]);
                        }
                    } else {
                        for (ox, d) in dst.iter_mut().enumerate() {
                            let ix = (ox * s + j) as isize - p;
                            if ix >= 0 && ix < w as isize {
                                *d = src[ix as usize];
                            }
                        }
                    }
                }
            }
        });
        Ok((CpuStorage::F32(cols), Shape::from((c * k * k, n))))
    }

    fn bwd(&self, arg: &Tensor, _res: &Tensor, grad_res: &Tensor) -> Result<Option<Tensor>> {
        let dims = arg.dims4()?;
        let g = grad_res.contiguous()?.apply_op1_no_bwd(&Col2Im {
            geom: self.geom,
            dims,
        })?;
        Ok(Some(g))
    }
}

impl CustomOp1 for Col2Im {
    fn name(&self) -> &'static str {
        "col2im"
    }

    fn cpu_fwd(&self, storage: &CpuStorage, layout: &Layout) -> Result<(CpuStorage, Shape)> {
        let cols = super::contiguous_f32(storage, layout, "col2im: input")?;
        let (b, c, h, w) = self.dims;
        let g = self.geom;
        let (k, s, p) = (g.kernel, g.stride, g.pad_begin as isize);
        let (ho, wo) = (g.out_size(h), g.out_size(w));
        let n = b * ho * wo;
        if cols.len() != c * k * k * n {
            candle_core::bail!(
                "col2im: expected {} values, found {}",
                c * k * k * n,
                cols.len()
            );
        }
        let mut x = vec![0f32; b * c * h * w];
        x.par_chunks_mut(h * w)
            .enumerate()
            .for_each(|(plane_idx, plane)| {
                let (bi, ci) = (plane_idx / c, plane_idx % c);
                for i in 0..k {
                    for j in 0..k {
                        let row = &cols[((ci * k + i) * k + j) * n..((ci * k + i) * k + j + 1) * n];
                        for oy in 0..ho {
                            let iy = (oy * s + i) as isize - p;
                            if iy < 0 || iy >= h as isize {
                                continue;
                            }
                            let dst = &mut plane[iy as usize * w..(iy as usize + 1) * w];
                            let src = &row[(bi * ho + oy) * wo..(bi * ho + oy + 1) * wo];
                            if s == 1 {
                                let shift = j as isize - p;
                                let lo = (-shift).max(0) as usize;
                                let hi = ((w as isize - shift).min(wo as isize)).max(0) as usize;
                                for ox in lo..hi {
                                    dst[(ox as isize + shift) as usize] += src[ox];
                                }
                            } else {
                                for (ox, v) in src.iter().enumerate() {
                                    let ix = (ox * s + j) as isize - p;
                                    if ix >= 0 && ix < w as isize {
                                        dst[ix as usize] += v;
                                    }
                                }
                            }
                        }
                    }
                }
            });
        Ok((CpuStorage::F32(x), Shape::from((b, c, h, w))))
    }
}
