//! Fused multi-head self-attention on the CPU: `o = softmax(q kᵀ / √d) v` for every head, read straight from the
//! channel-major `[B, 3C, N]` output of one q/k/v projection (a 1 × 1 convolution of the image: no token-major
//! transpose) and written channel-major `[B, C, N]` for `to_out` (another 1 × 1 convolution), so the
//! `[B, heads, N, N]` scores and the head transposes are never materialised (FlashAttention's recompute idea, on
//! blocks of [`ROWS`] rows of scores at a time). The backward recomputes each block's probabilities from q and k
//! instead of storing them.
//!
//! Each task is one (sample, head): its q `[N, d]`, `kᵀ` and `vᵀ` `[d, N]` (the latter two are the layout's own
//! rows) are packed once, so every inner loop runs over N contiguous floats (16-lane vectors; head widths of 8
//! would waste most of a GEMM's register tile).

use candle_core::{CpuStorage, CustomOp1, CustomOp3, Layout, Result, Shape, Tensor};
use rayon::prelude::*;

use super::simd::contiguous_f32;
use super::simd::simd_level;

mod rows;
use rows::*;

/// `softmax(q kᵀ · scale) v` per head of `qkv` `[B, 3C, N]` (channel-major: q, k, v one after the other on the
/// channel axis, head `h` at channels `h·d .. (h+1)·d` of each, N tokens per channel) → `[B, C, N]`,
/// differentiable.
pub fn fused_attention(qkv: &Tensor, heads: usize, scale: f32) -> Result<Tensor> {
    qkv.contiguous()?.apply_op1(FusedAttention { heads, scale })
}

#[derive(Clone, Copy, Debug)]
struct FusedAttention {
    heads: usize,
    scale: f32,
}

/// Backward of [`FusedAttention`] on `(qkv, o, do)` → `d qkv`.
#[derive(Clone, Copy, Debug)]
struct FusedAttentionBackward(FusedAttention);

/// The sizes of one call: batch, tokens, channels (C, not 3C), heads and head width.
#[derive(Clone, Copy, Debug)]
struct Dims {
    b: usize,
    n: usize,
    c: usize,
    heads: usize,
    d: usize,
}

impl FusedAttention {
    fn dims(&self, shape: &Shape) -> Result<Dims> {
        let (b, c3, n) = shape.dims3()?;
        let heads = self.heads.max(1);
        if n == 0 || c3 == 0 {
            candle_core::bail!("attention: no tokens or no channels (shape {shape:?})");
        }
        if c3 % 3 != 0 || (c3 / 3) % heads != 0 {
            candle_core::bail!("attention: {c3} channels are not q, k, v of {heads} equal heads");
        }
        let c = c3 / 3;
        Ok(Dims {
            b,
            n,
            c,
            heads,
            d: c / heads,
        })
    }
}

impl CustomOp1 for FusedAttention {
    fn name(&self) -> &'static str {
        "fused-attention"
    }

    fn cpu_fwd(&self, s: &CpuStorage, l: &Layout) -> Result<(CpuStorage, Shape)> {
        let qkv = contiguous_f32(s, l, "attention: qkv")?;
        let dm = self.dims(l.shape())?;
        let Dims { b, n, c, d, .. } = dm;
        // One head's output [N, d] per task, then scattered token-major.
        // SAFETY: every task writes its whole block (head_forward).
        let mut per_head = unsafe { super::alloc::output_vec(b * c * n) };
        let (scale, level) = (self.scale, simd_level());
        per_head
            .par_chunks_mut(n * d)
            .enumerate()
            .for_each(|(task, out)| {
                let packed = Packed::of(qkv, dm, task);
                match level {
                    #[cfg(target_arch = "x86_64")]
                    // SAFETY: the CPU has these features (simd_level).
                    2 => unsafe { simd::head_forward_avx512(&packed, scale, out) },
                    #[cfg(target_arch = "x86_64")]
                    // SAFETY: as above.
                    1 => unsafe { simd::head_forward_avx2(&packed, scale, out) },
                    _ => head_forward(&packed, scale, out),
                }
            });
        // SAFETY: scatter_heads writes every element.
        let mut o = unsafe { super::alloc::output_vec(b * n * c) };
        scatter_heads(&per_head, dm, &mut o);
        Ok((CpuStorage::F32(o), Shape::from((b, c, n))))
    }

    fn bwd(&self, qkv: &Tensor, o: &Tensor, d_o: &Tensor) -> Result<Option<Tensor>> {
        let d_qkv = qkv.apply_op3_no_bwd(o, &d_o.contiguous()?, &FusedAttentionBackward(*self))?;
        Ok(Some(d_qkv))
    }
}

impl CustomOp3 for FusedAttentionBackward {
    fn name(&self) -> &'static str {
        "fused-attention-backward"
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
        let qkv = contiguous_f32(s1, l1, "attention backward: qkv")?;
        let o = contiguous_f32(s2, l2, "attention backward: output")?;
        let d_o = contiguous_f32(s3, l3, "attention backward: output gradient")?;
        let dm = self.0.dims(l1.shape())?;
        let Dims { b, n, c, d, heads } = dm;
        if o.len() != b * n * c || d_o.len() != o.len() {
            candle_core::bail!(
                "attention backward: output shapes do not match qkv {:?}",
                l1.dims()
            );
        }
        // Per task: dq [N, d], dkᵀ [d, N], dvᵀ [d, N].
        // SAFETY: every task writes its whole block (head_backward).
        let mut per_head = unsafe { super::alloc::output_vec(b * heads * 3 * n * d) };
        let (scale, level) = (self.0.scale, simd_level());
        per_head
            .par_chunks_mut(3 * n * d)
            .enumerate()
            .for_each(|(task, grads)| {
                let packed = Packed::of(qkv, dm, task);
                let (go, gdo) = (gather_head(o, dm, task, c), gather_head(d_o, dm, task, c));
                match level {
                    #[cfg(target_arch = "x86_64")]
                    // SAFETY: the CPU has these features (simd_level).
                    2 => unsafe { simd::head_backward_avx512(&packed, &go, &gdo, scale, grads) },
                    #[cfg(target_arch = "x86_64")]
                    // SAFETY: as above.
                    1 => unsafe { simd::head_backward_avx2(&packed, &go, &gdo, scale, grads) },
                    _ => head_backward(&packed, &go, &gdo, scale, grads),
                }
            });
        // SAFETY: the three scatters write every element (q, k and v thirds of each token).
        let mut d_qkv = unsafe { super::alloc::output_vec(b * n * 3 * c) };
        scatter_grads(&per_head, dm, &mut d_qkv);
        Ok((CpuStorage::F32(d_qkv), l1.shape().clone()))
    }
}

/// One (sample, head) task's inputs: q `[N, d]`, `kᵀ` and `vᵀ` `[d, N]`.
struct Packed {
    n: usize,
    d: usize,
    q: Vec<f32>,
    kt: Vec<f32>,
    vt: Vec<f32>,
}

impl Packed {
    fn of(qkv: &[f32], dm: Dims, task: usize) -> Self {
        let Dims { n, c, d, .. } = dm;
        let (bi, h) = (task / dm.heads, task % dm.heads);
        let sample = &qkv[bi * 3 * c * n..(bi + 1) * 3 * c * n];
        // kᵀ and vᵀ are d consecutive channel rows of the layout.
        let rows = |first: usize| sample[(first + h * d) * n..(first + (h + 1) * d) * n].to_vec();
        Self {
            n,
            d,
            q: gather_head(qkv, dm, task, 3 * c),
            kt: rows(c),
            vt: rows(2 * c),
        }
    }
}

/// Head `task % heads` of sample `task / heads` as `[N, d]` (token-major), from a channel-major layout of
/// `channels` rows of N per sample (the head's channels at `h·d .. (h+1)·d`).
fn gather_head(x: &[f32], dm: Dims, task: usize, channels: usize) -> Vec<f32> {
    let Dims { n, d, .. } = dm;
    let (bi, h) = (task / dm.heads, task % dm.heads);
    let rows = &x[(bi * channels + h * d) * n..(bi * channels + (h + 1) * d) * n];
    let mut out = vec![0f32; n * d];
    for (e, row) in rows.chunks_exact(n).enumerate() {
        for (i, &v) in row.iter().enumerate() {
            out[i * d + e] = v;
        }
    }
    out
}

/// `block` `[N, d]` (token-major) into the `d` channel rows of N at `rows`.
fn transpose_into(block: &[f32], n: usize, d: usize, rows: &mut [f32]) {
    for (e, row) in rows.chunks_exact_mut(n).enumerate() {
        for (i, r) in row.iter_mut().enumerate() {
            *r = block[i * d + e];
        }
    }
}

/// Per-head `[N, d]` blocks (task order) into `[B, C, N]`, in parallel over (sample, head).
fn scatter_heads(per_head: &[f32], dm: Dims, out: &mut [f32]) {
    let Dims { n, d, .. } = dm;
    out.par_chunks_mut(d * n)
        .zip(per_head.par_chunks(n * d))
        .for_each(|(rows, block)| transpose_into(block, n, d, rows));
}

/// Per-task `(dq [N, d], dkᵀ [d, N], dvᵀ [d, N])` into `[B, 3C, N]`.
fn scatter_grads(per_head: &[f32], dm: Dims, d_qkv: &mut [f32]) {
    let Dims { n, c, d, heads, .. } = dm;
    d_qkv
        .par_chunks_mut(3 * c * n)
        .enumerate()
        .for_each(|(bi, sample)| {
            for h in 0..heads {
                let g = &per_head[(bi * heads + h) * 3 * n * d..][..3 * n * d];
                let (dq, rest) = g.split_at(n * d);
                let (dkt, dvt) = rest.split_at(n * d);
                transpose_into(dq, n, d, &mut sample[h * d * n..(h + 1) * d * n]);
                sample[(c + h * d) * n..(c + (h + 1) * d) * n].copy_from_slice(dkt);
                sample[(2 * c + h * d) * n..(2 * c + (h + 1) * d) * n].copy_from_slice(dvt);
            }
        });
}

/// One head's output `[N, d]`: `P·V` from unnormalised exponentials, scaled by each row's 1 / Σ at the end (d
/// multiplies per row instead of N).
#[inline(always)]
fn head_forward(x: &Packed, scale: f32, out: &mut [f32]) {
    let (n, d) = (x.n, x.d);
    let (mut s, mut p) = (vec![0f32; ROWS * n], vec![0f32; ROWS * n]);
    let mut inv = [0f32; ROWS];
    for (blk, ob) in out.chunks_mut(ROWS * d).enumerate() {
        let rows = ob.len() / d;
        block_probabilities(x, blk * ROWS, rows, scale, &mut s, &mut p, Some(&mut inv));
        rows_times(&p, &x.vt, n, ob);
        for (or, &k) in ob.chunks_exact_mut(d).zip(&inv) {
            or.iter_mut().for_each(|o| *o *= k);
        }
    }
}

/// One head's gradients `(dq [N, d], dkᵀ [d, N], dvᵀ [d, N])` into `grads`, from its output `o` and output
/// gradient `d_o` (`[N, d]` each). With `P = softmax(S · scale)`: `dV = Pᵀ dO`, `dP = dO Vᵀ`,
/// `dS = scale · P ⊙ (dP − rowsum(dO ⊙ O))`, `dQ = dS K`, `dK = dSᵀ Q`. Rows go in blocks of [`ROWS`], so each
/// `dkᵀ`/`dvᵀ` chunk is loaded and stored once per block.
#[inline(always)]
fn head_backward(x: &Packed, o: &[f32], d_o: &[f32], scale: f32, grads: &mut [f32]) {
    let (n, d) = (x.n, x.d);
    let (dq, rest) = grads.split_at_mut(n * d);
    let (dkt, dvt) = rest.split_at_mut(n * d);
    dkt.fill(0.0);
    dvt.fill(0.0);
    let (mut s, mut p, mut ds) = (
        vec![0f32; ROWS * n],
        vec![0f32; ROWS * n],
        vec![0f32; ROWS * n],
    );
    for i0 in (0..n).step_by(ROWS) {
        let rows = ROWS.min(n - i0);
        block_probabilities(x, i0, rows, scale, &mut s, &mut p, None);
        let (ob, dob) = (&o[i0 * d..(i0 + rows) * d], &d_o[i0 * d..(i0 + rows) * d]);
        // dP_ij = dO_i · v_j, then dS (scaled) in place.
        if rows == ROWS {
            block_times_transposed(dob, d, &x.vt, n, &mut ds);
        } else {
            for r in 0..rows {
                row_times_transposed(
                    &dob[r * d..(r + 1) * d],
                    &x.vt,
                    n,
                    &mut ds[r * n..(r + 1) * n],
                );
            }
        }
        for r in 0..rows {
            let (oi, doi) = (&ob[r * d..(r + 1) * d], &dob[r * d..(r + 1) * d]);
            let delta: f32 = oi.iter().zip(doi).map(|(a, b)| a * b).sum();
            for (dsj, &pj) in ds[r * n..(r + 1) * n]
                .iter_mut()
                .zip(&p[r * n..(r + 1) * n])
            {
                *dsj = scale * pj * (*dsj - delta);
            }
        }
        // dQ = dS K, two rows at a time.
        rows_times(&ds, &x.kt, n, &mut dq[i0 * d..(i0 + rows) * d]);
        // dkᵀ[e] += Σ_r q_re · dS_r and dvᵀ[e] += Σ_r dO_re · P_r, a chunk of LANES at a time held in registers.
        let qb = &x.q[i0 * d..(i0 + rows) * d];
        let blocks = n / LANES;
        if rows == ROWS {
            // A full block: each chunk of the block's dS and P rows is loaded once for all d rows of dkᵀ and dvᵀ
            // (e-outer loops reloaded them d times: 12 memory operations per 8 multiply-adds, load-bound).
            for jb in 0..blocks {
                let j0 = jb * LANES;
                let (s0, s1, s2, s3) = (
                    V16::load(&ds[j0..]),
                    V16::load(&ds[n + j0..]),
                    V16::load(&ds[2 * n + j0..]),
                    V16::load(&ds[3 * n + j0..]),
                );
                let (p0, p1, p2, p3) = (
                    V16::load(&p[j0..]),
                    V16::load(&p[n + j0..]),
                    V16::load(&p[2 * n + j0..]),
                    V16::load(&p[3 * n + j0..]),
                );
                for e in 0..d {
                    let (q, g) = (|r: usize| qb[r * d + e], |r: usize| dob[r * d + e]);
                    let at = e * n + j0;
                    let dk = V16::load(&dkt[at..])
                        .mul_add(q(0), s0)
                        .mul_add(q(1), s1)
                        .mul_add(q(2), s2)
                        .mul_add(q(3), s3);
                    let dv = V16::load(&dvt[at..])
                        .mul_add(g(0), p0)
                        .mul_add(g(1), p1)
                        .mul_add(g(2), p2)
                        .mul_add(g(3), p3);
                    dk.store(&mut dkt[at..]);
                    dv.store(&mut dvt[at..]);
                }
            }
            for e in 0..d {
                for j in blocks * LANES..n {
                    for r in 0..rows {
                        dkt[e * n + j] += qb[r * d + e] * ds[r * n + j];
                        dvt[e * n + j] += dob[r * d + e] * p[r * n + j];
                    }
                }
            }
            continue;
        }
        for e in 0..d {
            let (dk_row, dv_row) = (&mut dkt[e * n..(e + 1) * n], &mut dvt[e * n..(e + 1) * n]);
            for jb in 0..blocks {
                let j0 = jb * LANES;
                let (mut dk, mut dv) = (V16::load(&dk_row[j0..]), V16::load(&dv_row[j0..]));
                for r in 0..rows {
                    dk = dk.mul_add(qb[r * d + e], V16::load(&ds[r * n + j0..]));
                    dv = dv.mul_add(dob[r * d + e], V16::load(&p[r * n + j0..]));
                }
                dk.store(&mut dk_row[j0..]);
                dv.store(&mut dv_row[j0..]);
            }
            for j in blocks * LANES..n {
                for r in 0..rows {
                    dk_row[j] += qb[r * d + e] * ds[r * n + j];
                    dv_row[j] += dob[r * d + e] * p[r * n + j];
                }
            }
        }
    }
}

/// The row kernels compiled for AVX-512 and for AVX2 + FMA, chosen at run time.
#[cfg(target_arch = "x86_64")]
mod simd {
    use super::Packed;

    #[target_feature(enable = "avx512f,avx512vl,avx2,fma")]
    pub(super) unsafe fn head_forward_avx512(x: &Packed, scale: f32, out: &mut [f32]) {
        super::head_forward(x, scale, out)
    }

    #[target_feature(enable = "avx2,fma")]
    pub(super) unsafe fn head_forward_avx2(x: &Packed, scale: f32, out: &mut [f32]) {
        super::head_forward(x, scale, out)
    }

    #[target_feature(enable = "avx512f,avx512vl,avx2,fma")]
    pub(super) unsafe fn head_backward_avx512(
        x: &Packed,
        o: &[f32],
        d_o: &[f32],
        scale: f32,
        grads: &mut [f32],
    ) {
        super::head_backward(x, o, d_o, scale, grads)
    }

    #[target_feature(enable = "avx2,fma")]
    pub(super) unsafe fn head_backward_avx2(
        x: &Packed,
        o: &[f32],
        d_o: &[f32],
        scale: f32,
        grads: &mut [f32],
    ) {
        super::head_backward(x, o, d_o, scale, grads)
    }
}
