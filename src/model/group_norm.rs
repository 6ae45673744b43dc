//! GroupNorm of the U-Net (paper IV.B; `torch.nn.GroupNorm`, keys `weight`/`bias`), fused with the SiLU that follows
//! it in every ResNet block and before `conv_out`. candle-nn's GroupNorm is a chain of ~10 elementwise tensor ops
//! (each a full pass over the activations, forward and backward); here forward and backward are one custom op each,
//! parallel over (sample, group). Tests compare with candle-nn's GroupNorm + SiLU, values and gradients.

use candle_core::{CpuStorage, CustomOp3, Layout, Result, Shape, Tensor};
use candle_nn::VarBuilder;
use rayon::prelude::*;

/// `nn.GroupNorm(groups, channels, eps, affine=True)`.
#[derive(Clone, Debug)]
pub struct GroupNorm {
    pub weight: Tensor,
    pub bias: Tensor,
    pub groups: usize,
    pub eps: f64,
}

/// Build from `vb` (keys `weight`, `bias`), like `candle_nn::group_norm`.
pub fn group_norm(groups: usize, channels: usize, eps: f64, vb: VarBuilder) -> Result<GroupNorm> {
    if groups == 0 || channels % groups != 0 {
        candle_core::bail!("GroupNorm: {channels} channels are not divisible into {groups} groups");
    }
    Ok(GroupNorm {
        weight: vb.get_with_hints(channels, "weight", candle_nn::Init::Const(1.0))?,
        bias: vb.get_with_hints(channels, "bias", candle_nn::Init::Const(0.0))?,
        groups,
        eps,
    })
}

impl GroupNorm {
    /// `GroupNorm(x)` for `x` `[B, C, ...]`.
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        self.apply(x, false)
    }

    /// `silu(GroupNorm(x))`.
    pub fn forward_silu(&self, x: &Tensor) -> Result<Tensor> {
        self.apply(x, true)
    }

    fn apply(&self, x: &Tensor, silu: bool) -> Result<Tensor> {
        let op = GnOp {
            groups: self.groups,
            eps: self.eps as f32,
            silu,
        };
        x.contiguous()?.apply_op3(&self.weight, &self.bias, op)
    }
}

#[derive(Clone, Copy, Debug)]
struct GnOp {
    groups: usize,
    eps: f32,
    silu: bool,
}

/// The backward as a separate op on `(x, grad, [weight; bias])`, returning `[dx…, dweight…, dbias…]` flat.
#[derive(Clone, Copy, Debug)]
struct GnBackward(GnOp);

fn slice<'a>(s: &'a CpuStorage, l: &Layout, what: &str) -> Result<&'a [f32]> {
    match l.contiguous_offsets() {
        Some((a, b)) => Ok(&s.as_slice::<f32>()?[a..b]),
        None => candle_core::bail!("group_norm: {what} must be contiguous"),
    }
}

#[inline]
fn sigmoid(z: f32) -> f32 {
    1.0 / (1.0 + (-z).exp())
}

/// Mean and 1/σ of one group's values.
fn stats(v: &[f32], eps: f32) -> (f32, f32) {
    let n = v.len() as f64;
    let mean = v.iter().map(|&x| f64::from(x)).sum::<f64>() / n;
    let var = v
        .iter()
        .map(|&x| (f64::from(x) - mean).powi(2))
        .sum::<f64>()
        / n;
    (mean as f32, (1.0 / (var + f64::from(eps)).sqrt()) as f32)
}

impl CustomOp3 for GnOp {
    fn name(&self) -> &'static str {
        "group-norm-silu"
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
        let x = slice(s1, l1, "x")?;
        let (w, b) = (slice(s2, l2, "weight")?, slice(s3, l3, "bias")?);
        let dims = l1.shape().dims();
        let c = dims[1];
        let hw: usize = dims[2..].iter().product();
        let cpg = c / self.groups;
        let mut y = vec![0f32; x.len()];
        y.par_chunks_mut(cpg * hw)
            .zip(x.par_chunks(cpg * hw))
            .enumerate()
            .for_each(|(bg, (yg, xg))| {
                let (mean, rstd) = stats(xg, self.eps);
                let c0 = (bg % self.groups) * cpg;
                for k in 0..cpg {
                    let (sc, sh) = (w[c0 + k] * rstd, b[c0 + k] - mean * rstd * w[c0 + k]);
                    let (ys, xs) = (&mut yg[k * hw..(k + 1) * hw], &xg[k * hw..(k + 1) * hw]);
                    if self.silu {
                        for (o, &v) in ys.iter_mut().zip(xs) {
                            let z = v * sc + sh;
                            *o = z * sigmoid(z);
                        }
                    } else {
                        for (o, &v) in ys.iter_mut().zip(xs) {
                            *o = v * sc + sh;
                        }
                    }
                }
            });
        Ok((CpuStorage::F32(y), l1.shape().clone()))
    }

    fn bwd(
        &self,
        x: &Tensor,
        w: &Tensor,
        b: &Tensor,
        _res: &Tensor,
        grad: &Tensor,
    ) -> Result<(Option<Tensor>, Option<Tensor>, Option<Tensor>)> {
        let c = w.dim(0)?;
        let n = x.elem_count();
        let wb = Tensor::cat(&[w, b], 0)?;
        let packed =
            x.contiguous()?
                .apply_op3_no_bwd(&grad.contiguous()?, &wb, &GnBackward(*self))?;
        let dx = packed.narrow(0, 0, n)?.reshape(x.shape())?;
        let dw = packed.narrow(0, n, c)?;
        let db = packed.narrow(0, n + c, c)?;
        Ok((Some(dx), Some(dw), Some(db)))
    }
}

impl CustomOp3 for GnBackward {
    fn name(&self) -> &'static str {
        "group-norm-silu-backward"
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
        let op = self.0;
        let x = slice(s1, l1, "x")?;
        let dy = slice(s2, l2, "grad")?;
        let wb = slice(s3, l3, "weight/bias")?;
        let dims = l1.shape().dims();
        let (bsz, c) = (dims[0], dims[1]);
        let (w, b) = wb.split_at(c);
        let hw: usize = dims[2..].iter().product();
        let cpg = c / op.groups;
        let n = x.len();
        let mut out = vec![0f32; n + 2 * c];
        let (dx, _) = out.split_at_mut(n);
        // Per (sample, channel) partial sums of dL/dw and dL/db.
        let mut partial = vec![[0f64; 2]; bsz * c];
        dx.par_chunks_mut(cpg * hw)
            .zip(partial.par_chunks_mut(cpg))
            .enumerate()
            .for_each(|(bg, (dxg, pg))| {
                let off = bg * cpg * hw;
                let (xg, dyg) = (&x[off..off + cpg * hw], &dy[off..off + cpg * hw]);
                let (mean, rstd) = stats(xg, op.eps);
                let c0 = (bg % op.groups) * cpg;
                // dz (gradient before the affine map's output, i.e. at z = x̂ w + b), then dx̂ = dz w.
                let (mut s1, mut s2) = (0f64, 0f64); // Σ dx̂, Σ dx̂ x̂
                for k in 0..cpg {
                    let (wk, bk) = (w[c0 + k], b[c0 + k]);
                    let (mut dwk, mut dbk) = (0f64, 0f64);
                    for i in k * hw..(k + 1) * hw {
                        let xh = (xg[i] - mean) * rstd;
                        let mut dz = dyg[i];
                        if op.silu {
                            let z = xh * wk + bk;
                            let s = sigmoid(z);
                            dz *= s * (1.0 + z * (1.0 - s));
                        }
                        dwk += f64::from(dz * xh);
                        dbk += f64::from(dz);
                        let dxh = dz * wk;
                        dxg[i] = dxh; // stash dx̂; finished below
                        s1 += f64::from(dxh);
                        s2 += f64::from(dxh * xh);
                    }
                    pg[k] = [dwk, dbk];
                }
                let m = (cpg * hw) as f64;
                let (m1, m2) = ((s1 / m) as f32, (s2 / m) as f32);
                for (i, d) in dxg.iter_mut().enumerate() {
                    let xh = (xg[i] - mean) * rstd;
                    *d = rstd * (*d - m1 - xh * m2);
                }
            });
        for ch in 0..c {
            let (mut dw, mut db) = (0f64, 0f64);
            for bi in 0..bsz {
                dw += partial[bi * c + ch][0];
                db += partial[bi * c + ch][1];
            }
            out[n + ch] = dw as f32;
            out[n + c + ch] = db as f32;
        }
        Ok((CpuStorage::F32(out), Shape::from(n + 2 * c)))
    }
}
