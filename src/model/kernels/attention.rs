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

use crate::model::contiguous_f32;
use crate::model::group_norm::{exp_f32, simd_level};

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

/// `s_j = Σ_e a_e · bt[e][j]` for every j: a row of `a` (length d) against `bt` `[d, N]`. Blocks of [`LANES`]
/// columns are summed in registers and stored once (an e-outer loop would load and store all of `s` d times).
#[inline(always)]
fn row_times_transposed(a: &[f32], bt: &[f32], n: usize, s: &mut [f32]) {
    let blocks = n / LANES;
    for jb in 0..blocks {
        let j0 = jb * LANES;
        let mut acc = V16::ZERO;
        for (e, &ae) in a.iter().enumerate() {
            acc = acc.mul_add(ae, V16::load(&bt[e * n + j0..]));
        }
        acc.store(&mut s[j0..]);
    }
    for j in blocks * LANES..n {
        s[j] = a
            .iter()
            .enumerate()
            .fold(0.0, |acc, (e, &ae)| acc + ae * bt[e * n + j]);
    }
}

/// `out_e = Σ_j p_j · bt[e][j]` for every e < d (`bt` `[d, N]`): groups of [`GROUP`] outputs keep one
/// [`LANES`]-wide partial sum each in registers while `p` is read once per group.
#[inline(always)]
fn row_dots(p: &[f32], bt: &[f32], n: usize, out: &mut [f32]) {
    let blocks = n / LANES;
    for (g, og) in out.chunks_mut(GROUP).enumerate() {
        let e0 = g * GROUP;
        if og.len() < GROUP {
            for (k, o) in og.iter_mut().enumerate() {
                *o = dot_lanes(p, &bt[(e0 + k) * n..(e0 + k + 1) * n]);
            }
            continue;
        }
        let rows: [&[f32]; GROUP] = std::array::from_fn(|k| &bt[(e0 + k) * n..(e0 + k + 1) * n]);
        let mut acc = [V16::ZERO; GROUP];
        for jb in 0..blocks {
            let j0 = jb * LANES;
            let pv = V16::load(&p[j0..]);
            acc[0] = acc[0].mul_add_v(pv, V16::load(&rows[0][j0..]));
            acc[1] = acc[1].mul_add_v(pv, V16::load(&rows[1][j0..]));
            acc[2] = acc[2].mul_add_v(pv, V16::load(&rows[2][j0..]));
            acc[3] = acc[3].mul_add_v(pv, V16::load(&rows[3][j0..]));
            acc[4] = acc[4].mul_add_v(pv, V16::load(&rows[4][j0..]));
            acc[5] = acc[5].mul_add_v(pv, V16::load(&rows[5][j0..]));
            acc[6] = acc[6].mul_add_v(pv, V16::load(&rows[6][j0..]));
            acc[7] = acc[7].mul_add_v(pv, V16::load(&rows[7][j0..]));
        }
        for ((o, a), row) in og.iter_mut().zip(&acc).zip(&rows) {
            let tail: f32 = (blocks * LANES..n).map(|j| p[j] * row[j]).sum();
            *o = a.sum() + tail;
        }
    }
}

/// Outputs per register group of [`row_dots`] (a head width of 8 is one group).
const GROUP: usize = 8;

/// [`row_dots`] of two rows `p0`, `p1` at once for a head width of [`GROUP`]: each chunk of `bt` is loaded once for
/// both (one row at a time was 9 loads per 8 multiply-adds); other widths run [`row_dots`] per row.
#[inline(always)]
fn row_dots_pair(p0: &[f32], p1: &[f32], bt: &[f32], n: usize, o0: &mut [f32], o1: &mut [f32]) {
    if o0.len() != GROUP || o1.len() != GROUP {
        row_dots(p0, bt, n, o0);
        row_dots(p1, bt, n, o1);
        return;
    }
    let blocks = n / LANES;
    let rows: [&[f32]; GROUP] = std::array::from_fn(|k| &bt[k * n..(k + 1) * n]);
    let (mut a, mut b) = ([V16::ZERO; GROUP], [V16::ZERO; GROUP]);
    for jb in 0..blocks {
        let j0 = jb * LANES;
        let (u, v) = (V16::load(&p0[j0..]), V16::load(&p1[j0..]));
        macro_rules! lane {
            ($k:literal) => {
                let r = V16::load(&rows[$k][j0..]);
                a[$k] = a[$k].mul_add_v(u, r);
                b[$k] = b[$k].mul_add_v(v, r);
            };
        }
        lane!(0);
        lane!(1);
        lane!(2);
        lane!(3);
        lane!(4);
        lane!(5);
        lane!(6);
        lane!(7);
    }
    for k in 0..GROUP {
        let (t0, t1) = (blocks * LANES..n).fold((0f32, 0f32), |(s0, s1), j| {
            (s0 + p0[j] * rows[k][j], s1 + p1[j] * rows[k][j])
        });
        o0[k] = a[k].sum() + t0;
        o1[k] = b[k].sum() + t1;
    }
}

/// Row `i`'s probabilities `softmax(q_i kᵀ · scale)` into `p` (`s` is scratch of N); with `inv`, the exponentials
/// are left unnormalised and `inv[0]` receives the row's 1 / Σ.
#[inline(always)]
fn row_probabilities(
    x: &Packed,
    i: usize,
    scale: f32,
    s: &mut [f32],
    p: &mut [f32],
    inv: Option<&mut [f32]>,
) {
    row_times_transposed(&x.q[i * x.d..(i + 1) * x.d], &x.kt, x.n, s);
    softmax_rows(s, p, x.n, scale, inv);
}

/// Query rows per block: their scores share every load of `kᵀ` (a block's [`LANES`] × [`ROWS`] partial sums fit
/// in registers).
const ROWS: usize = 4;

/// Scores of a block of [`ROWS`] rows of `a` (`[ROWS, d]`) against `bt` (`[d, N]`) into `s` (`[ROWS, N]`).
#[inline(always)]
fn block_times_transposed(a: &[f32], d: usize, bt: &[f32], n: usize, s: &mut [f32]) {
    let blocks = n / LANES;
    let (a0, a1, a2, a3) = (&a[..d], &a[d..2 * d], &a[2 * d..3 * d], &a[3 * d..4 * d]);
    for jb in 0..blocks {
        let j0 = jb * LANES;
        let (mut s0, mut s1, mut s2, mut s3) = (V16::ZERO, V16::ZERO, V16::ZERO, V16::ZERO);
        for e in 0..d {
            let b = V16::load(&bt[e * n + j0..]);
            s0 = s0.mul_add(a0[e], b);
            s1 = s1.mul_add(a1[e], b);
            s2 = s2.mul_add(a2[e], b);
            s3 = s3.mul_add(a3[e], b);
        }
        s0.store(&mut s[j0..]);
        s1.store(&mut s[n + j0..]);
        s2.store(&mut s[2 * n + j0..]);
        s3.store(&mut s[3 * n + j0..]);
    }
    for r in 0..ROWS {
        for j in blocks * LANES..n {
            s[r * n + j] = (0..d).fold(0.0, |acc, e| acc + a[r * d + e] * bt[e * n + j]);
        }
    }
}

/// Probabilities of query rows `i0 .. i0 + rows` into `p` (`[rows, N]`; `s` is scratch of the same size); with
/// `inv` (`rows` values), unnormalised exponentials and each row's 1 / Σ.
#[inline(always)]
fn block_probabilities(
    x: &Packed,
    i0: usize,
    rows: usize,
    scale: f32,
    s: &mut [f32],
    p: &mut [f32],
    mut inv: Option<&mut [f32]>,
) {
    let (n, d) = (x.n, x.d);
    if rows == ROWS {
        block_times_transposed(&x.q[i0 * d..(i0 + ROWS) * d], d, &x.kt, n, s);
        softmax_rows(&s[..ROWS * n], &mut p[..ROWS * n], n, scale, inv);
    } else {
        for r in 0..rows {
            row_probabilities(
                x,
                i0 + r,
                scale,
                &mut s[r * n..(r + 1) * n],
                &mut p[r * n..(r + 1) * n],
                inv.as_deref_mut().map(|v| &mut v[r..r + 1]),
            );
        }
    }
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
        let mut r = 0;
        while r < rows {
            let (head, tail) = ob[r * d..].split_at_mut(d);
            if r + 1 < rows {
                let (pa, pb) = p[r * n..(r + 2) * n].split_at(n);
                row_dots_pair(pa, pb, &x.vt, n, head, &mut tail[..d]);
                r += 2;
            } else {
                row_dots(&p[r * n..(r + 1) * n], &x.vt, n, head);
                r += 1;
            }
        }
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
        let dqb = &mut dq[i0 * d..(i0 + rows) * d];
        let mut r = 0;
        while r < rows {
            let (head, tail) = dqb[r * d..].split_at_mut(d);
            if r + 1 < rows {
                let (sa, sb) = ds[r * n..(r + 2) * n].split_at(n);
                row_dots_pair(sa, sb, &x.kt, n, head, &mut tail[..d]);
                r += 2;
            } else {
                row_dots(&ds[r * n..(r + 1) * n], &x.kt, n, head);
                r += 1;
            }
        }
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

/// Lanes of the row loops: 16 independent maxima and partial sums, so the loops vectorise (a single running
/// `max`/`sum` is a serial dependency LLVM must keep scalar, and with it the `exp` of every score).
const LANES: usize = 16;

/// `softmax(scale · x)` of every row of `n` values of `xr` into `yr`; with `inv` (one value per row), the
/// exponentials are left unnormalised and each row's 1 / Σ goes to `inv`.
#[inline(always)]
fn softmax_rows(xr: &[f32], yr: &mut [f32], n: usize, scale: f32, mut inv: Option<&mut [f32]>) {
    let blocks = n / LANES;
    for (row, (yrow, xrow)) in yr.chunks_mut(n).zip(xr.chunks(n)).enumerate() {
        let mut m = V16([f32::NEG_INFINITY; LANES]);
        for jb in 0..blocks {
            m = m.max(V16::load(&xrow[jb * LANES..]));
        }
        let max = xrow[blocks * LANES..]
            .iter()
            .fold(m.max_lane(), |a, &b| if b > a { b } else { a });
        let mut sum = V16::ZERO;
        for jb in 0..blocks {
            let e = V16::load(&xrow[jb * LANES..]).scaled_exp(max, scale);
            e.store(&mut yrow[jb * LANES..]);
            sum = sum.add(e);
        }
        let mut tail = 0f32;
        for (o, &v) in yrow[blocks * LANES..]
            .iter_mut()
            .zip(&xrow[blocks * LANES..])
        {
            *o = exp_f32((v - max) * scale);
            tail += *o;
        }
        let k = 1.0 / (sum.sum() + tail);
        match inv.as_deref_mut() {
            Some(v) => v[row] = k,
            None => yrow.iter_mut().for_each(|o| *o *= k),
        }
    }
}

/// `Σ a·b` over [`LANES`] interleaved partial sums.
#[inline(always)]
fn dot_lanes(a: &[f32], b: &[f32]) -> f32 {
    let n = a.len().min(b.len());
    let blocks = n / LANES;
    let mut acc = V16::ZERO;
    for jb in 0..blocks {
        acc = acc.mul_add_v(V16::load(&a[jb * LANES..]), V16::load(&b[jb * LANES..]));
    }
    acc.sum() + (blocks * LANES..n).map(|j| a[j] * b[j]).sum::<f32>()
}

/// [`LANES`] floats that LLVM keeps in one vector register (AVX-512) or two (AVX2): named values of this type
/// vectorise reliably where arrays of partial sums indexed in loops fell back to scalar code on the stack.
/// Products are fused multiply-adds (`mul_add`): one instruction in the AVX2/AVX-512 builds and on aarch64; only an
/// x86 CPU without FMA (the portable build) pays a library call per lane.
#[derive(Clone, Copy)]
struct V16([f32; LANES]);

impl V16 {
    const ZERO: Self = Self([0.0; LANES]);

    /// The first [`LANES`] values of `s` (panics if shorter: callers pass whole blocks).
    #[inline(always)]
    fn load(s: &[f32]) -> Self {
        let mut v = [0f32; LANES];
        v.copy_from_slice(&s[..LANES]);
        Self(v)
    }

    #[inline(always)]
    fn store(self, s: &mut [f32]) {
        s[..LANES].copy_from_slice(&self.0);
    }

    /// `self + a · b` (a broadcast).
    #[inline(always)]
    fn mul_add(self, a: f32, b: Self) -> Self {
        let mut v = self.0;
        for (x, &y) in v.iter_mut().zip(&b.0) {
            *x = a.mul_add(y, *x);
        }
        Self(v)
    }

    /// `self + a ⊙ b`.
    #[inline(always)]
    fn mul_add_v(self, a: Self, b: Self) -> Self {
        let mut v = self.0;
        for ((x, &y), &z) in v.iter_mut().zip(&a.0).zip(&b.0) {
            *x = y.mul_add(z, *x);
        }
        Self(v)
    }

    #[inline(always)]
    fn add(self, b: Self) -> Self {
        let mut v = self.0;
        for (x, &y) in v.iter_mut().zip(&b.0) {
            *x += y;
        }
        Self(v)
    }

    /// Lane-wise maximum (NaN-free inputs; a NaN in `b` is skipped).
    #[inline(always)]
    fn max(self, b: Self) -> Self {
        let mut v = self.0;
        for (x, &y) in v.iter_mut().zip(&b.0) {
            *x = if y > *x { y } else { *x };
        }
        Self(v)
    }

    #[inline(always)]
    fn max_lane(self) -> f32 {
        self.0
            .iter()
            .fold(f32::NEG_INFINITY, |a, &b| if b > a { b } else { a })
    }

    /// `exp((self − max) · scale)` lane-wise.
    #[inline(always)]
    fn scaled_exp(self, max: f32, scale: f32) -> Self {
        let mut v = self.0;
        for x in &mut v {
            *x = exp_f32((*x - max) * scale);
        }
        Self(v)
    }

    #[inline(always)]
    fn sum(self) -> f32 {
        self.0.iter().sum()
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
