//! The row kernels of the fused attention ([`super`]): scores of one query row or a block of [`ROWS`] rows against
//! `kᵀ`, their softmax, and the `P·V`-style row products, all over N contiguous floats in [`LANES`]-wide named
//! vectors ([`V16`]) so LLVM keeps the partial sums in registers. They are `#[inline(always)]` into the per-head
//! functions that [`super`] compiles for AVX-512 and AVX2.

use super::super::simd::exp_f32;
use super::Packed;

/// `s_j = Σ_e a_e · bt[e][j]` for every j: a row of `a` (length d) against `bt` `[d, N]`. Blocks of [`LANES`]
/// columns are summed in registers and stored once (an e-outer loop would load and store all of `s` d times).
#[inline(always)]
pub(super) fn row_times_transposed(a: &[f32], bt: &[f32], n: usize, s: &mut [f32]) {
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
pub(super) fn row_dots(p: &[f32], bt: &[f32], n: usize, out: &mut [f32]) {
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

/// `out` `[rows, d]` = rows of `a` (`[rows, N]`, row stride N) times `btᵀ` (`bt` `[d, N]`): [`row_dots_pair`] two rows
/// at a time, [`row_dots`] for an odd last row.
#[inline(always)]
pub(super) fn rows_times(a: &[f32], bt: &[f32], n: usize, out: &mut [f32]) {
    let d = bt.len() / n.max(1);
    let rows = out.len() / d.max(1);
    let mut r = 0;
    while r < rows {
        let (head, tail) = out[r * d..].split_at_mut(d);
        if r + 1 < rows {
            let (pa, pb) = a[r * n..(r + 2) * n].split_at(n);
            row_dots_pair(pa, pb, bt, n, head, &mut tail[..d]);
            r += 2;
        } else {
            row_dots(&a[r * n..(r + 1) * n], bt, n, head);
            r += 1;
        }
    }
}

/// [`row_dots`] of two rows `p0`, `p1` at once for a head width of [`GROUP`]: each chunk of `bt` is loaded once for
/// both (one row at a time was 9 loads per 8 multiply-adds); other widths run [`row_dots`] per row.
#[inline(always)]
pub(super) fn row_dots_pair(
    p0: &[f32],
    p1: &[f32],
    bt: &[f32],
    n: usize,
    o0: &mut [f32],
    o1: &mut [f32],
) {
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
pub(super) fn row_probabilities(
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
pub(super) const ROWS: usize = 4;

/// Scores of a block of [`ROWS`] rows of `a` (`[ROWS, d]`) against `bt` (`[d, N]`) into `s` (`[ROWS, N]`).
#[inline(always)]
pub(super) fn block_times_transposed(a: &[f32], d: usize, bt: &[f32], n: usize, s: &mut [f32]) {
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
pub(super) fn block_probabilities(
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

/// Lanes of the row loops: 16 independent maxima and partial sums, so the loops vectorise (a single running
/// `max`/`sum` is a serial dependency LLVM must keep scalar, and with it the `exp` of every score).
pub(super) const LANES: usize = 16;

/// `softmax(scale · x)` of every row of `n` values of `xr` into `yr`; with `inv` (one value per row), the
/// exponentials are left unnormalised and each row's 1 / Σ goes to `inv`.
#[inline(always)]
pub(super) fn softmax_rows(
    xr: &[f32],
    yr: &mut [f32],
    n: usize,
    scale: f32,
    mut inv: Option<&mut [f32]>,
) {
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
pub(super) fn dot_lanes(a: &[f32], b: &[f32]) -> f32 {
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
pub(super) struct V16([f32; LANES]);

impl V16 {
    pub(super) const ZERO: Self = Self([0.0; LANES]);

    /// The first [`LANES`] values of `s` (panics if shorter: callers pass whole blocks).
    #[inline(always)]
    pub(super) fn load(s: &[f32]) -> Self {
        let mut v = [0f32; LANES];
        v.copy_from_slice(&s[..LANES]);
        Self(v)
    }

    #[inline(always)]
    pub(super) fn store(self, s: &mut [f32]) {
        s[..LANES].copy_from_slice(&self.0);
    }

    /// `self + a · b` (a broadcast).
    #[inline(always)]
    pub(super) fn mul_add(self, a: f32, b: Self) -> Self {
        let mut v = self.0;
        for (x, &y) in v.iter_mut().zip(&b.0) {
            *x = a.mul_add(y, *x);
        }
        Self(v)
    }

    /// `self + a ⊙ b`.
    #[inline(always)]
    pub(super) fn mul_add_v(self, a: Self, b: Self) -> Self {
        let mut v = self.0;
        for ((x, &y), &z) in v.iter_mut().zip(&a.0).zip(&b.0) {
            *x = y.mul_add(z, *x);
        }
        Self(v)
    }

    #[inline(always)]
    pub(super) fn add(self, b: Self) -> Self {
        let mut v = self.0;
        for (x, &y) in v.iter_mut().zip(&b.0) {
            *x += y;
        }
        Self(v)
    }

    /// Lane-wise maximum (NaN-free inputs; a NaN in `b` is skipped).
    #[inline(always)]
    pub(super) fn max(self, b: Self) -> Self {
        let mut v = self.0;
        for (x, &y) in v.iter_mut().zip(&b.0) {
            *x = if y > *x { y } else { *x };
        }
        Self(v)
    }

    #[inline(always)]
    pub(super) fn max_lane(self) -> f32 {
        self.0
            .iter()
            .fold(f32::NEG_INFINITY, |a, &b| if b > a { b } else { a })
    }

    /// `exp((self − max) · scale)` lane-wise.
    #[inline(always)]
    pub(super) fn scaled_exp(self, max: f32, scale: f32) -> Self {
        let mut v = self.0;
        for x in &mut v {
            *x = exp_f32((*x - max) * scale);
        }
        Self(v)
    }

    #[inline(always)]
    pub(super) fn sum(self) -> f32 {
        self.0.iter().sum()
    }
}
