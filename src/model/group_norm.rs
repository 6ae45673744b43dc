//! GroupNorm of the U-Net (paper IV.B; `torch.nn.GroupNorm`, keys `weight`/`bias`), fused with the SiLU that follows
//! it in every ResNet block and before `conv_out`. candle-nn's GroupNorm is a chain of ~10 elementwise tensor ops
//! (each a full pass over the activations, forward and backward); here forward and backward are one custom op each,
//! parallel over (sample, group). Tests compare with candle-nn's GroupNorm + SiLU, values and gradients.

use super::kernels::simd::{exp_f32, simd_level};
use std::sync::{Arc, OnceLock};

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
    /// Use candle's own tensor ops instead of the fused CPU op (always on devices other than the CPU).
    pub portable: bool,
}

/// Build from `vb` (keys `weight`, `bias`), like `candle_nn::group_norm`.
pub fn group_norm(groups: usize, channels: usize, eps: f64, vb: VarBuilder) -> Result<GroupNorm> {
    if groups == 0 || !channels.is_multiple_of(groups) {
        candle_core::bail!("GroupNorm: {channels} channels are not divisible into {groups} groups");
    }
    Ok(GroupNorm {
        weight: vb.get_with_hints(channels, "weight", candle_nn::Init::Const(1.0))?,
        bias: vb.get_with_hints(channels, "bias", candle_nn::Init::Const(0.0))?,
        groups,
        eps,
        portable: false,
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

    /// `silu(GroupNorm(x + shift))` with `shift` `[B, C]` broadcast over the pixels (the ResNet block's time
    /// embedding projection), in one pass: no `[B, C, H, W]` sum is materialised, forward or backward.
    pub fn forward_shift_silu(&self, x: &Tensor, shift: &Tensor) -> Result<Tensor> {
        let (b, c) = (x.dim(0)?, x.dim(1)?);
        if shift.dims() != [b, c] {
            candle_core::bail!(
                "GroupNorm shift {:?} does not fit input {:?}",
                shift.dims(),
                x.dims()
            );
        }
        if self.portable || !x.device().is_cpu() {
            let shape: Vec<usize> = [b, c]
                .into_iter()
                .chain(std::iter::repeat_n(1, x.rank() - 2))
                .collect();
            return self.candle_ops(&x.broadcast_add(&shift.reshape(shape)?)?, true);
        }
        self.apply_op(x, shift.contiguous()?, true, true)
    }

    /// The same computation with candle's differentiable tensor ops (any device).
    fn candle_ops(&self, x: &Tensor, silu: bool) -> Result<Tensor> {
        let dims = x.dims().to_vec();
        let (b, c) = (x.dim(0)?, x.dim(1)?);
        let xg = x.reshape((b, self.groups, ()))?;
        let mean = xg.mean_keepdim(2)?;
        let centred = xg.broadcast_sub(&mean)?;
        let var = centred.sqr()?.mean_keepdim(2)?;
        let normed = centred
            .broadcast_div(&(var + self.eps)?.sqrt()?)?
            .reshape(dims.as_slice())?;
        let shape: Vec<usize> = [1, c]
            .into_iter()
            .chain(std::iter::repeat_n(1, dims.len() - 2))
            .collect();
        let y = normed
            .broadcast_mul(&self.weight.reshape(shape.as_slice())?)?
            .broadcast_add(&self.bias.reshape(shape.as_slice())?)?;
        if silu {
            y.silu()
        } else {
            Ok(y)
        }
    }

    fn apply(&self, x: &Tensor, silu: bool) -> Result<Tensor> {
        if self.portable || !x.device().is_cpu() {
            return self.candle_ops(x, silu);
        }
        let zeros = Tensor::zeros((x.dim(0)?, x.dim(1)?), x.dtype(), x.device())?;
        self.apply_op(x, zeros, silu, false)
    }

    fn apply_op(&self, x: &Tensor, shift: Tensor, silu: bool, has_shift: bool) -> Result<Tensor> {
        let op = GnOp {
            groups: self.groups,
            eps: self.eps as f32,
            silu,
            has_shift,
        };
        let wb = Tensor::cat(&[&self.weight, &self.bias], 0)?;
        let op = GnForward {
            op,
            stats: Arc::new(OnceLock::new()),
        };
        x.contiguous()?.apply_op3(&wb, &shift, op)
    }
}

/// Per-(sample, group) `(mean, 1/σ)` of a forward, set once by it and read by its backward.
type SavedStats = Arc<OnceLock<Vec<(f32, f32)>>>;

/// The forward op: [`GnOp`] plus the per-(sample, group) `(mean, 1/σ)` it computed, kept for its backward (which
/// recomputed them from x: two of the backward's four passes over the input).
#[derive(Clone, Debug)]
struct GnForward {
    op: GnOp,
    stats: SavedStats,
}

#[derive(Clone, Copy, Debug)]
struct GnOp {
    groups: usize,
    eps: f32,
    silu: bool,
    /// Whether the shift input `[B, C]` needs a gradient (otherwise it is zeros).
    has_shift: bool,
}

/// The backward as a separate op on `(x, grad, [weight; bias; shift])`, returning
/// `[dx…, dweight…, dbias…, dshift…]` flat; `stats` are the forward's (used when they fit the input).
#[derive(Clone, Debug)]
struct GnBackward {
    op: GnOp,
    stats: Option<SavedStats>,
}

/// Values summed in f32 lanes before each flush into an f64 total (keeps f32 rounding negligible).
const BLOCK: usize = 64;
/// f32 lanes of the vectorisable loops (one AVX register).
const LANES: usize = 8;

#[inline(always)]
fn sigmoid(z: f32) -> f32 {
    1.0 / (1.0 + exp_f32(-z))
}

/// Σ v (f32 lanes flushed into f64 every [`BLOCK`] values).
#[inline(always)]
fn sum_lanes(v: &[f32], shift: f32) -> (f64, f64) {
    let (mut s, mut s2) = (0f64, 0f64);
    for blk in v.chunks(BLOCK) {
        let (mut a, mut a2) = ([0f32; LANES], [0f32; LANES]);
        let mut it = blk.chunks_exact(LANES);
        for c in &mut it {
            for l in 0..LANES {
                let d = c[l] - shift;
                a[l] += d;
                a2[l] += d * d;
            }
        }
        for &x in it.remainder() {
            let d = x - shift;
            s += f64::from(d);
            s2 += f64::from(d * d);
        }
        s += a.iter().map(|&x| f64::from(x)).sum::<f64>();
        s2 += a2.iter().map(|&x| f64::from(x)).sum::<f64>();
    }
    (s, s2)
}

/// Mean and 1/σ of one group's values `v + t_k` (channel rows of `hw` values, `t` one shift per channel; two passes:
/// mean, then squared deviations).
#[inline(always)]
fn stats(v: &[f32], hw: usize, t: &[f32], eps: f32) -> (f32, f32) {
    let n = v.len() as f64;
    let rows = || v.chunks(hw).zip(t);
    let mean = (rows().map(|(r, &tk)| sum_lanes(r, -tk).0).sum::<f64>() / n) as f32;
    let (mut d, mut d2) = (0f64, 0f64);
    for (r, &tk) in rows() {
        let (a, a2) = sum_lanes(r, mean - tk);
        d += a;
        d2 += a2;
    }
    let var = (d2 - d * d / n) / n;
    (mean, (1.0 / (var.max(0.0) + f64::from(eps)).sqrt()) as f32)
}

/// Forward of one group `xg` (+ per-channel shifts `tg`) -> `yg` (`cpg` channels of `hw` values starting at channel
/// `c0`).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn fwd_group(
    op: GnOp,
    w: &[f32],
    b: &[f32],
    tg: &[f32],
    c0: usize,
    hw: usize,
    xg: &[f32],
    yg: &mut [f32],
) -> (f32, f32) {
    let (mean, rstd) = stats(xg, hw, tg, op.eps);
    for (k, (ys, xs)) in yg.chunks_mut(hw).zip(xg.chunks(hw)).enumerate() {
        let mean_k = mean - tg[k];
        let (sc, sh) = (w[c0 + k] * rstd, b[c0 + k] - mean_k * rstd * w[c0 + k]);
        if op.silu {
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
    (mean, rstd)
}

/// Backward of one group: writes `dxg`, returns per channel `[Σ dz·x̂, Σ dz, Σ dx]` (dL/dweight, dL/dbias,
/// dL/dshift) into `pg`. `saved`: the group's `(mean, 1/σ)` from the forward (recomputed from `xg` when absent;
/// the same function of the same values either way).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn bwd_group(
    op: GnOp,
    w: &[f32],
    b: &[f32],
    tg: &[f32],
    c0: usize,
    hw: usize,
    xg: &[f32],
    dyg: &[f32],
    dxg: &mut [f32],
    pg: &mut [[f64; 3]],
    saved: Option<(f32, f32)>,
) {
    let (mean, rstd) = saved.unwrap_or_else(|| stats(xg, hw, tg, op.eps));
    // dz = dL/dz at z = x̂ w + b (through the SiLU when fused); dx̂ = dz w. Σ dx̂ = Σ_k w_k Σ dz and
    // Σ dx̂ x̂ = Σ_k w_k Σ dz x̂ follow from the per-channel sums.
    let (mut s1, mut s2) = (0f64, 0f64);
    for (k, p) in pg.iter_mut().enumerate() {
        let (wk, bk, mean) = (w[c0 + k], b[c0 + k], mean - tg[k]);
        let (xs, dys) = (&xg[k * hw..(k + 1) * hw], &dyg[k * hw..(k + 1) * hw]);
        let dxs = &mut dxg[k * hw..(k + 1) * hw];
        let dz_at = |x: f32, dy: f32| -> (f32, f32) {
            let xh = (x - mean) * rstd;
            let dz = if op.silu {
                let z = xh * wk + bk;
                let s = sigmoid(z);
                dy * (s * (1.0 + z * (1.0 - s)))
            } else {
                dy
            };
            (xh, dz)
        };
        let (mut dwk, mut dbk) = (0f64, 0f64);
        for ((xb, dyb), dxb) in xs
            .chunks(BLOCK)
            .zip(dys.chunks(BLOCK))
            .zip(dxs.chunks_mut(BLOCK))
        {
            let (mut aw, mut ab) = ([0f32; LANES], [0f32; LANES]);
            let mut xi = xb.chunks_exact(LANES);
            let mut di = dyb.chunks_exact(LANES);
            let mut oi = dxb.chunks_exact_mut(LANES);
            for ((xc, dc), oc) in (&mut xi).zip(&mut di).zip(&mut oi) {
                for l in 0..LANES {
                    let (xh, dz) = dz_at(xc[l], dc[l]);
                    aw[l] += dz * xh;
                    ab[l] += dz;
                    oc[l] = dz * wk; // stash dx̂; finished below
                }
            }
            let rem = xi.remainder().iter().zip(di.remainder());
            for ((&x, &dy), o) in rem.zip(oi.into_remainder()) {
                let (xh, dz) = dz_at(x, dy);
                dwk += f64::from(dz * xh);
                dbk += f64::from(dz);
                *o = dz * wk;
            }
            dwk += aw.iter().map(|&v| f64::from(v)).sum::<f64>();
            dbk += ab.iter().map(|&v| f64::from(v)).sum::<f64>();
        }
        *p = [dwk, dbk, 0.0];
        s1 += f64::from(wk) * dbk;
        s2 += f64::from(wk) * dwk;
    }
    let m = (pg.len() * hw) as f64;
    let (m1, m2) = ((s1 / m) as f32, (s2 / m) as f32);
    for (k, (ds, xs)) in dxg.chunks_mut(hw).zip(xg.chunks(hw)).enumerate() {
        let mean = mean - tg[k];
        for (d, &x) in ds.iter_mut().zip(xs) {
            let xh = (x - mean) * rstd;
            *d = rstd * (*d - m1 - xh * m2);
        }
        if op.has_shift {
            pg[k][2] = sum_lanes(ds, 0.0).0;
        }
    }
}

/// Defines module `$name` with [`fwd_group`] and [`bwd_group`] compiled for the target features `$features`
/// (same operations in the same order as the portable versions; Rust never contracts to FMA by itself).
macro_rules! simd_group_kernels {
    ($name:ident, $features:literal) => {
        #[cfg(target_arch = "x86_64")]
        mod $name {
            use super::GnOp;

            #[target_feature(enable = $features)]
            #[allow(clippy::too_many_arguments)]
            pub(super) unsafe fn fwd_group(
                op: GnOp,
                w: &[f32],
                b: &[f32],
                tg: &[f32],
                c0: usize,
                hw: usize,
                xg: &[f32],
                yg: &mut [f32],
            ) -> (f32, f32) {
                super::fwd_group(op, w, b, tg, c0, hw, xg, yg)
            }

            #[target_feature(enable = $features)]
            #[allow(clippy::too_many_arguments)]
            pub(super) unsafe fn bwd_group(
                op: GnOp,
                w: &[f32],
                b: &[f32],
                tg: &[f32],
                c0: usize,
                hw: usize,
                xg: &[f32],
                dyg: &[f32],
                dxg: &mut [f32],
                pg: &mut [[f64; 3]],
                saved: Option<(f32, f32)>,
            ) {
                super::bwd_group(op, w, b, tg, c0, hw, xg, dyg, dxg, pg, saved)
            }
        }
    };
}

// AVX2 + FMA (8 f32 lanes) and AVX-512 (16-lane loops where LLVM widens them), chosen at run time (`simd_level`);
// the portable versions run elsewhere.
simd_group_kernels!(avx2, "avx2,fma");
simd_group_kernels!(avx512, "avx512f,avx512vl,avx2,fma");

impl CustomOp3 for GnForward {
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
        let x = super::contiguous_f32(s1, l1, "group_norm: x")?;
        let wb = super::contiguous_f32(s2, l2, "group_norm: weight/bias")?;
        let t = super::contiguous_f32(s3, l3, "group_norm: shift")?;
        let dims = l1.shape().dims();
        let c = dims[1];
        let hw: usize = dims[2..].iter().product();
        let cpg = c / self.op.groups;
        if wb.len() != 2 * c || t.len() != dims[0] * c {
            candle_core::bail!("group_norm: parameters do not fit input {dims:?}");
        }
        let (w, b) = wb.split_at(c);
        // SAFETY: fwd_group writes every value of every (sample, group) chunk.
        let mut y = unsafe { super::kernels::alloc::output_vec(x.len()) };
        let (op, fast) = (self.op, simd_level());
        let stats: Vec<(f32, f32)> = y
            .par_chunks_mut(cpg * hw)
            .zip(x.par_chunks(cpg * hw))
            .zip(t.par_chunks(cpg))
            .enumerate()
            .map(|(bg, ((yg, xg), tg))| {
                let c0 = (bg % op.groups) * cpg;
                #[cfg(target_arch = "x86_64")]
                match fast {
                    // SAFETY: the CPU supports AVX-512 (F, VL), AVX2 and FMA (checked above).
                    2 => return unsafe { avx512::fwd_group(op, w, b, tg, c0, hw, xg, yg) },
                    // SAFETY: the CPU supports AVX2 and FMA (checked above).
                    1 => return unsafe { avx2::fwd_group(op, w, b, tg, c0, hw, xg, yg) },
                    _ => {}
                }
                let _ = fast;
                fwd_group(op, w, b, tg, c0, hw, xg, yg)
            })
            .collect();
        // A second forward of the same op instance (not done by candle) keeps the first's statistics; the backward
        // checks that they fit its input.
        let _ = self.stats.set(stats);
        Ok((CpuStorage::F32(y), l1.shape().clone()))
    }

    fn bwd(
        &self,
        x: &Tensor,
        wb: &Tensor,
        t: &Tensor,
        _res: &Tensor,
        grad: &Tensor,
    ) -> Result<(Option<Tensor>, Option<Tensor>, Option<Tensor>)> {
        let (n, c2, nt) = (x.elem_count(), wb.elem_count(), t.elem_count());
        let params = Tensor::cat(&[wb, &t.flatten_all()?], 0)?;
        let backward = GnBackward {
            op: self.op,
            stats: Some(self.stats.clone()),
        };
        let packed = x
            .contiguous()?
            .apply_op3_no_bwd(&grad.contiguous()?, &params, &backward)?;
        let dx = packed.narrow(0, 0, n)?.reshape(x.shape())?;
        let dwb = packed.narrow(0, n, c2)?;
        let dt = if self.op.has_shift {
            Some(packed.narrow(0, n + c2, nt)?.reshape(t.shape())?)
        } else {
            None
        };
        Ok((Some(dx), Some(dwb), dt))
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
        let op = self.op;
        let x = super::contiguous_f32(s1, l1, "group_norm: x")?;
        let dy = super::contiguous_f32(s2, l2, "group_norm: grad")?;
        let params = super::contiguous_f32(s3, l3, "group_norm: weight/bias/shift")?;
        let dims = l1.shape().dims();
        let (bsz, c) = (dims[0], dims[1]);
        if params.len() != 2 * c + bsz * c {
            candle_core::bail!("group_norm backward: parameters do not fit input {dims:?}");
        }
        let (w, rest) = params.split_at(c);
        let (b, t) = rest.split_at(c);
        let hw: usize = dims[2..].iter().product();
        let cpg = c / op.groups;
        let n = x.len();
        // SAFETY: dx by bwd_group (every value), the parameter gradients by the loops below (every entry).
        let mut out = unsafe { super::kernels::alloc::output_vec(n + 2 * c + bsz * c) };
        let (dx, _) = out.split_at_mut(n);
        // Per (sample, channel) sums of dL/dw, dL/db and dL/dshift.
        let mut partial = vec![[0f64; 3]; bsz * c];
        let fast = simd_level();
        // The forward's statistics where they are for this input's (sample, group) count.
        let saved = self
            .stats
            .as_ref()
            .and_then(|s| s.get())
            .filter(|s| s.len() == bsz * op.groups);
        dx.par_chunks_mut(cpg * hw)
            .zip(partial.par_chunks_mut(cpg))
            .zip(t.par_chunks(cpg))
            .enumerate()
            .for_each(|(bg, ((dxg, pg), tg))| {
                let off = bg * cpg * hw;
                let (xg, dyg) = (&x[off..off + cpg * hw], &dy[off..off + cpg * hw]);
                let c0 = (bg % op.groups) * cpg;
                let st = saved.map(|s| s[bg]);
                #[cfg(target_arch = "x86_64")]
                match fast {
                    // SAFETY: the CPU supports AVX-512 (F, VL), AVX2 and FMA (checked above).
                    2 => {
                        return unsafe {
                            avx512::bwd_group(op, w, b, tg, c0, hw, xg, dyg, dxg, pg, st)
                        }
                    }
                    // SAFETY: the CPU supports AVX2 and FMA (checked above).
                    1 => {
                        return unsafe {
                            avx2::bwd_group(op, w, b, tg, c0, hw, xg, dyg, dxg, pg, st)
                        }
                    }
                    _ => {}
                }
                let _ = fast;
                bwd_group(op, w, b, tg, c0, hw, xg, dyg, dxg, pg, st);
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
        for (o, p) in out[n + 2 * c..].iter_mut().zip(&partial) {
            *o = p[2] as f32;
        }
        let len = out.len();
        Ok((CpuStorage::F32(out), Shape::from(len)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exp_f32_is_within_rounding_of_std() {
        let mut worst = 0f32;
        for i in -8700..=8790 {
            let x = i as f32 * 0.01 + 0.003;
            let (a, b) = (exp_f32(x), x.exp());
            worst = worst.max((a - b).abs() / b);
        }
        assert!(worst < 4e-7, "relative error {worst}");
        assert!(sigmoid(-200.0) >= 0.0 && sigmoid(-200.0) < 1e-30);
        assert!((sigmoid(200.0) - 1.0).abs() < 1e-7);
    }

    #[test]
    fn stats_match_f64_two_pass() {
        let v: Vec<f32> = (0..1000)
            .map(|i| ((i * 37 % 101) as f32) * 0.1 + 5.0)
            .collect();
        let n = v.len() as f64;
        let mean = v.iter().map(|&x| f64::from(x)).sum::<f64>() / n;
        let var = v
            .iter()
            .map(|&x| (f64::from(x) - mean).powi(2))
            .sum::<f64>()
            / n;
        let (m, r) = stats(&v, 100, &[0.0; 10], 1e-5);
        assert!((f64::from(m) - mean).abs() < 1e-5);
        assert!((f64::from(r) - 1.0 / (var + 1e-5).sqrt()).abs() < 1e-6 * f64::from(r));
    }

    /// The backward with the forward's saved statistics gives the bits of the backward that recomputes them, and
    /// statistics of another shape are ignored.
    #[test]
    fn saved_statistics_give_the_recomputed_backward() {
        use candle_core::{Device, Var};
        let dev = Device::Cpu;
        let vals = |n: usize, k: f32| -> Vec<f32> {
            (0..n)
                .map(|i| ((i * 7919 % 613) as f32 / 613.0 - 0.4) * k)
                .collect()
        };
        let (b, c, h, w) = (2, 8, 5, 6);
        let x = Var::from_vec(vals(b * c * h * w, 3.0), (b, c, h, w), &dev).unwrap();
        let gn = GroupNorm {
            weight: Tensor::from_vec(vals(c, 2.0), c, &dev).unwrap(),
            bias: Tensor::from_vec(vals(c, 1.0), c, &dev).unwrap(),
            groups: 4,
            eps: 1e-5,
            portable: false,
        };
        let shift = Tensor::from_vec(vals(b * c, 0.5), (b, c), &dev).unwrap();
        let r = Tensor::from_vec(vals(b * c * h * w, 1.0), (b, c, h, w), &dev).unwrap();
        let y = gn.forward_shift_silu(x.as_tensor(), &shift).unwrap();
        let saved = (&y * &r).unwrap().sum_all().unwrap().backward().unwrap();
        let saved = saved
            .get(&x)
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1::<f32>()
            .unwrap();
        let wb = Tensor::cat(&[&gn.weight, &gn.bias], 0).unwrap();
        let params = Tensor::cat(&[&wb, &shift.flatten_all().unwrap()], 0).unwrap();
        let op = GnOp {
            groups: 4,
            eps: 1e-5,
            silu: true,
            has_shift: true,
        };
        let wrong = Arc::new(OnceLock::new());
        let _ = wrong.set(vec![(0.0f32, 1.0f32); 3]);
        for stats in [None, Some(wrong)] {
            let packed = x
                .as_tensor()
                .apply_op3_no_bwd(&r, &params, &GnBackward { op, stats })
                .unwrap();
            let dx = packed
                .narrow(0, 0, b * c * h * w)
                .unwrap()
                .to_vec1::<f32>()
                .unwrap();
            assert_eq!(dx, saved);
        }
    }
}
