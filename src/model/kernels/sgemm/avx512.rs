//! AVX-512 single-precision GEMM kernels for the tiled convolution (paper IV.B, speed on the CPU).
//!
//! Two register-blocked kernels, chosen by [`super`] at run time when the CPU has `avx512f`:
//! - [`gemm_packed`]: `C[m, n] = init + A[m, k] · B[k, n]`, with A packed into panels of [`MR`] rows
//!   (`[m / MR][k][MR]`) and B read in place, row by row. An [`MR`] × 48 block of C lives in 24 zmm
//!   registers; each step broadcasts [`MR`] values of A and loads three vectors of one B row. K is split in blocks
//!   of [`KC`] so a `KC × 48` strip of B stays in L1 while every row block of A passes over it. Column tails use
//!   masked loads and stores; row tails compute on the zero rows of the panel and store only the valid rows.
//! - [`gemm_nt`]: `C[m, n] (+)= A[m, k] · B[n, k]ᵀ` with both operands contiguous along k (the weight gradient,
//!   computed as `dWᵀ = cols · dYᵀ`): the small B (`n` = output channels) is transposed once per call with
//!   16 × 16 register transposes, then the same register kernel runs with A broadcast straight from its rows
//!   (blocks of 8 × 48, 12 × 32 or 24 × 16 by the width of C). Measured against 4 × 6 blocks of 16-lane dot
//!   products reduced at the end: 2.2–4× faster except for the 18-wide first layer (equal).
//!
//! Every output element is summed in an order fixed by the sizes alone (no threads here, no run-time
//! heuristics), so repeated runs are bit-identical.

use super::Init;
use core::arch::x86_64::{
    __m512, __mmask16, _mm512_castpd_ps, _mm512_castps_pd, _mm512_fmadd_ps, _mm512_loadu_ps,
    _mm512_mask_storeu_ps, _mm512_maskz_loadu_ps, _mm512_set1_ps, _mm512_setzero_ps,
    _mm512_shuffle_f32x4, _mm512_storeu_ps, _mm512_unpackhi_pd, _mm512_unpackhi_ps,
    _mm512_unpacklo_pd, _mm512_unpacklo_ps,
};

/// Rows of A (and C) per register block of [`gemm_packed`].
pub const MR: usize = 8;
/// Columns of C per register block of [`gemm_packed`] (three zmm vectors).
const NR: usize = 48;
/// Block of the inner dimension: a `KC × NR` strip of B is 24 KB, resident in L1.
const KC: usize = 128;

/// Packs `a[i * rs + p * cs]` (`m × k`) into panels `[m.div_ceil(MR)][k][MR]`, zero-padding the last panel.
pub fn pack_a(m: usize, k: usize, a: &[f32], rs: usize, cs: usize) -> Vec<f32> {
    let blocks = m.div_ceil(MR);
    let mut out = vec![0f32; blocks * k * MR];
    for ib in 0..blocks {
        let rows = MR.min(m - ib * MR);
        let panel = &mut out[ib * k * MR..(ib + 1) * k * MR];
        for (p, dst) in panel.chunks_exact_mut(MR).enumerate() {
            for (r, d) in dst[..rows].iter_mut().enumerate() {
                *d = a[(ib * MR + r) * rs + p * cs];
            }
        }
    }
    out
}

/// Where a kernel finds row `p` of a row-major operand: at a fixed stride ([`Strided`]), or at per-row offsets
/// ([`Offsets`]: the shifted rows of a padded image, the implicit im2col of [`crate::model::conv_direct`]).
pub trait Rows: Copy {
    /// Start of row `p`.
    ///
    /// # Safety
    /// `p` is a row of the operand.
    unsafe fn row(self, p: usize) -> *const f32;
    /// The operand from row `p0` and column `j0` on.
    ///
    /// # Safety
    /// Row `p0` and column `j0` are inside the operand.
    unsafe fn shifted(self, p0: usize, j0: usize) -> Self;
}

/// Row `p` at `base + p · ld`.
#[derive(Clone, Copy)]
pub struct Strided {
    pub base: *const f32,
    pub ld: usize,
}

impl Rows for Strided {
    #[inline(always)]
    unsafe fn row(self, p: usize) -> *const f32 {
        self.base.add(p * self.ld)
    }
    #[inline(always)]
    unsafe fn shifted(self, p0: usize, j0: usize) -> Self {
        Self {
            base: self.base.add(p0 * self.ld + j0),
            ld: self.ld,
        }
    }
}

/// Row `p` at `base + offs[p]`.
#[derive(Clone, Copy)]
pub struct Offsets {
    pub base: *const f32,
    pub offs: *const usize,
}

impl Rows for Offsets {
    #[inline(always)]
    unsafe fn row(self, p: usize) -> *const f32 {
        self.base.add(*self.offs.add(p))
    }
    #[inline(always)]
    unsafe fn shifted(self, p0: usize, j0: usize) -> Self {
        Self {
            base: self.base.add(j0),
            offs: self.offs.add(p0),
        }
    }
}

/// Lane mask of the first `w` lanes (`1 ≤ w ≤ 16`).
fn lane_mask(w: usize) -> __mmask16 {
    if w >= 16 {
        0xFFFF
    } else {
        ((1u32 << w) - 1) as __mmask16
    }
}

/// How a register block of C starts before the products are added.
#[derive(Clone, Copy)]
enum Start {
    /// From zero.
    Zero,
    /// From the values in C (accumulate, or a later block of K).
    LoadC,
    /// Row `r` from `init[r]` (a per-row bias), without reading C.
    Row(*const f32),
}

impl Start {
    /// The start of the first block of K for `Init` at rows from `row0`, and `LoadC` for later blocks.
    ///
    /// # Safety
    /// For `Init::RowBias`, `row0` is inside the bias.
    unsafe fn first(init: Init, row0: usize, k0: usize) -> Self {
        match init {
            _ if k0 > 0 => Self::LoadC,
            Init::Zero => Self::Zero,
            Init::Accumulate => Self::LoadC,
            Init::RowBias(bias) => Self::Row(bias.as_ptr().add(row0)),
        }
    }
}

/// Where the `NV` vectors of one register block of [`kernel`] sit: vector `v` reads B at column `b[v]` of each
/// row and reads and writes C at column `c[v]` of each row (both relative to the block's pointers). A plain
/// strip of C has both at `16 · v`; [`gemm_packed_image`] gathers vectors from several image rows.
#[derive(Clone, Copy)]
struct Lanes<const NV: usize> {
    b: [usize; NV],
    c: [usize; NV],
}

impl<const NV: usize> Lanes<NV> {
    /// Consecutive vectors.
    fn contiguous() -> Self {
        let v = core::array::from_fn(|v| 16 * v);
        Self { b: v, c: v }
    }

    /// The first `NV` (≤ 3) columns of `b` and `c`.
    fn first(b: [usize; 3], c: [usize; 3]) -> Self {
        Self {
            b: core::array::from_fn(|v| b[v]),
            c: core::array::from_fn(|v| c[v]),
        }
    }
}

/// One `R × (16 · NV)` block: `C = start + A[R, kc] · B[kc, 16 · NV]`, where row `r` of A is read
/// at `a[r] + p · a_step`, vector `v` of B and C sits where `lanes` says, the last vector of each row of B and C
/// covers only the lanes in `mask`, and only the first `mr` rows of C are read and written.
///
/// # Safety
/// avx512f; `a[r] + p · a_step` is readable for `p < kc`; for every `p < kc`, `b.row(p)` holds
/// the vectors at `lanes.b` (the last one the lanes in `mask`); `c + r · ldc` likewise at `lanes.c` for `r < mr`, valid for reads (for
/// `Start::LoadC`) and writes; `Start::Row(init)` has `mr` readable values.
#[target_feature(enable = "avx512f")]
#[allow(clippy::too_many_arguments, clippy::needless_range_loop)]
unsafe fn kernel<const R: usize, const NV: usize, B: Rows>(
    kc: usize,
    a: &[*const f32; R],
    a_step: usize,
    b: B,
    c: *mut f32,
    ldc: usize,
    mr: usize,
    mask: __mmask16,
    start: Start,
    lanes: Lanes<NV>,
) {
    let mut acc = [[_mm512_setzero_ps(); NV]; R];
    match start {
        Start::Zero => {}
        Start::LoadC => {
            for r in 0..R {
                if r < mr {
                    for v in 0..NV {
                        let m = if v + 1 == NV { mask } else { 0xFFFF };
                        acc[r][v] = _mm512_maskz_loadu_ps(m, c.add(r * ldc + lanes.c[v]));
                    }
                }
            }
        }
        Start::Row(init) => {
            for r in 0..R {
                if r < mr {
                    acc[r] = [_mm512_set1_ps(*init.add(r)); NV];
                }
            }
        }
    }
    for p in 0..kc {
        let bp = b.row(p);
        let mut bv = [_mm512_setzero_ps(); NV];
        for v in 0..NV {
            bv[v] = if v + 1 == NV {
                _mm512_maskz_loadu_ps(mask, bp.add(lanes.b[v]))
            } else {
                _mm512_loadu_ps(bp.add(lanes.b[v]))
            };
        }
        let off = p * a_step;
        for r in 0..R {
            let av = _mm512_set1_ps(*a[r].add(off));
            for v in 0..NV {
                acc[r][v] = _mm512_fmadd_ps(av, bv[v], acc[r][v]);
            }
        }
    }
    for r in 0..R {
        if r < mr {
            for v in 0..NV {
                let dst = c.add(r * ldc + lanes.c[v]);
                if v + 1 == NV {
                    _mm512_mask_storeu_ps(dst, mask, acc[r][v]);
                } else {
                    _mm512_storeu_ps(dst, acc[r][v]);
                }
            }
        }
    }
}

/// `C[m, n] = init + A · B` with A packed by [`pack_a`] (`m × k`) and B's rows `0..k` of `n` floats found by `b`.
///
/// # Safety
/// avx512f must be available; `pa` comes from [`pack_a`] with these `m`, `k`; an `Init::RowBias` holds `m`
/// values; every `b.row(p)`, `p < k`, holds `n` readable floats; `c` points to `m` rows of `n` floats at stride
/// `ldc`, valid for reads and writes and not accessed by anyone else during the call.
#[target_feature(enable = "avx512f")]
#[allow(clippy::too_many_arguments)]
pub unsafe fn gemm_packed(
    m: usize,
    n: usize,
    k: usize,
    pa: &[f32],
    b: impl Rows,
    c: *mut f32,
    ldc: usize,
    init: Init,
) {
    if k == 0 {
        for i in 0..m {
            let row = core::slice::from_raw_parts_mut(c.add(i * ldc), n);
            match init {
                Init::Zero => row.fill(0.0),
                Init::Accumulate => {}
                Init::RowBias(bias) => row.fill(bias[i]),
            }
        }
        return;
    }
    for j0 in (0..n).step_by(NR) {
        let w = NR.min(n - j0);
        let nv = w.div_ceil(16);
        let mask = lane_mask(w - 16 * (nv - 1));
        strip(
            (m, k),
            pa,
            b.shifted(0, j0),
            (c.add(j0), ldc),
            init,
            (nv, CONTIGUOUS, CONTIGUOUS),
            mask,
        );
    }
}

/// Columns of the three vectors of a plain strip (B and C alike).
const CONTIGUOUS: [usize; 3] = [0, 16, 32];

/// One strip of C `nv` (≤ 3) vectors wide, vector `v` at column `lb[v]` of B's rows and `lc[v]` of C's (from `b`
/// and `c`), the last vector covering the lanes in `mask`: for each block of K in turn, every row block of A.
///
/// # Safety
/// As [`kernel`] for every block.
#[target_feature(enable = "avx512f")]
unsafe fn strip(
    (m, k): (usize, usize),
    pa: &[f32],
    b: impl Rows,
    (c, ldc): (*mut f32, usize),
    init: Init,
    (nv, lb, lc): (usize, [usize; 3], [usize; 3]),
    mask: __mmask16,
) {
    for k0 in (0..k).step_by(KC) {
        let kc = KC.min(k - k0);
        let bp = b.shifted(k0, 0);
        for ib in 0..m.div_ceil(MR) {
            let mr = MR.min(m - ib * MR);
            let panel = pa.as_ptr().add((ib * k + k0) * MR);
            let ap: [*const f32; MR] = core::array::from_fn(|r| panel.add(r));
            let cp = c.add(ib * MR * ldc);
            let start = Start::first(init, ib * MR, k0);
            match nv {
                1 => kernel::<MR, 1, _>(
                    kc,
                    &ap,
                    MR,
                    bp,
                    cp,
                    ldc,
                    mr,
                    mask,
                    start,
                    Lanes::first(lb, lc),
                ),
                2 => kernel::<MR, 2, _>(
                    kc,
                    &ap,
                    MR,
                    bp,
                    cp,
                    ldc,
                    mr,
                    mask,
                    start,
                    Lanes::first(lb, lc),
                ),
                _ => kernel::<MR, 3, _>(
                    kc,
                    &ap,
                    MR,
                    bp,
                    cp,
                    ldc,
                    mr,
                    mask,
                    start,
                    Lanes::first(lb, lc),
                ),
            }
        }
    }
}

/// [`gemm_packed`] on the image positions of a padded grid only. B's columns are `rows` grid rows of `wp`
/// positions of which the first `w` lie on the image (`w` a multiple of 16); the product at grid position
/// `(y, x < w)` goes to column `y · w + x` of C. Each register block takes the next three 16-wide pieces of image
/// rows in row order, so no work is spent on the off-image columns and nothing is copied out afterwards (the
/// wide product's row-by-row copy was 4.8 % of a batch-16 forward of the peer configuration). Every element is
/// summed exactly as [`gemm_packed`] sums it.
///
/// # Safety
/// As [`gemm_packed`] with `n = rows · wp` for B, and C holding `m` rows of `rows · w` floats at stride `ldc`.
#[target_feature(enable = "avx512f")]
#[allow(clippy::too_many_arguments)]
pub unsafe fn gemm_packed_image(
    m: usize,
    k: usize,
    pa: &[f32],
    b: impl Rows,
    (rows, w, wp): (usize, usize, usize),
    c: *mut f32,
    ldc: usize,
    init: Init,
) {
    debug_assert!(w.is_multiple_of(16) && w <= wp);
    if k == 0 || w == 0 {
        gemm_packed(m, rows * w, k, pa, b, c, ldc, init);
        return;
    }
    let per_row = w / 16;
    let vectors = rows * per_row;
    // Column of piece `s` in B (grid) and in C (image).
    let at = |s: usize| {
        let (y, x) = (s / per_row, s % per_row * 16);
        (y * wp + x, y * w + x)
    };
    for s0 in (0..vectors).step_by(3) {
        let nv = 3.min(vectors - s0);
        let (mut lb, mut lc) = ([0; 3], [0; 3]);
        for v in 0..nv {
            (lb[v], lc[v]) = at(s0 + v);
        }
        strip((m, k), pa, b, (c, ldc), init, (nv, lb, lc), 0xFFFF);
    }
}

thread_local! {
    /// Per-thread scratch for the transposed right operand of [`gemm_nt`].
    static SCRATCH: core::cell::RefCell<Vec<f32>> = const { core::cell::RefCell::new(Vec::new()) };
}

/// Width of the next column strip of [`gemm_nt`] for `rem` columns left: 48 (three vectors), except that 49–64
/// columns go as 32 + the rest so no strip is left with a single vector.
fn strip_width(rem: usize) -> usize {
    if rem > 48 && rem <= 64 {
        32
    } else {
        rem.min(48)
    }
}

/// `C[m, n] = (accumulate ? C : 0) + A · Bᵀ` with A row-major (`m × k`, row stride `lda`), B row-major
/// (`n × k`, row stride `ldb`) and C row-major (row stride `ldc`), for small `n` (the weight gradient with
/// `A = cols`, `B = dY`, `C = dWᵀ`): B is transposed into a per-thread `k × n` scratch, then register blocks of
/// 8 × 48, 12 × 32 or 24 × 16 of C broadcast A straight from its rows.
///
/// # Safety
/// avx512f must be available; every `a.row(i)`, `i < m`, holds `k` readable floats, `b` rows `0..n` of `k` floats
/// at stride `ldb`; `c` points to `m` rows of `n` floats at stride `ldc`, valid for reads and writes and not
/// accessed by anyone else during the call.
#[target_feature(enable = "avx512f")]
#[allow(clippy::too_many_arguments)]
pub unsafe fn gemm_nt(
    m: usize,
    n: usize,
    k: usize,
    a: impl Rows,
    b: *const f32,
    ldb: usize,
    c: *mut f32,
    ldc: usize,
    accumulate: bool,
) {
    if k == 0 || m == 0 || n == 0 {
        if !accumulate {
            for i in 0..m {
                core::ptr::write_bytes(c.add(i * ldc), 0, n);
            }
        }
        return;
    }
    let run = |bt: &mut Vec<f32>| {
        // Every element of bt[..k·n] is written by the transpose: grow the scratch, never clear it.
        if bt.len() < k * n {
            bt.resize(k * n, 0.0);
        }
        transpose(n, k, b, ldb, bt.as_mut_ptr());
        let mut j0 = 0;
        while j0 < n {
            let w = strip_width(n - j0);
            let nv = w.div_ceil(16);
            let mask = lane_mask(w - 16 * (nv - 1));
            for k0 in (0..k).step_by(KC) {
                let kc = KC.min(k - k0);
                let bp = bt.as_ptr().add(k0 * n + j0);
                let start = if accumulate || k0 > 0 {
                    Start::LoadC
                } else {
                    Start::Zero
                };
                match nv {
                    1 => nt_rows::<24, 1>(
                        (m, kc),
                        a.shifted(0, k0),
                        Strided { base: bp, ld: n },
                        (c.add(j0), ldc),
                        mask,
                        start,
                    ),
                    2 => nt_rows::<12, 2>(
                        (m, kc),
                        a.shifted(0, k0),
                        Strided { base: bp, ld: n },
                        (c.add(j0), ldc),
                        mask,
                        start,
                    ),
                    _ => nt_rows::<8, 3>(
                        (m, kc),
                        a.shifted(0, k0),
                        Strided { base: bp, ld: n },
                        (c.add(j0), ldc),
                        mask,
                        start,
                    ),
                }
            }
            j0 += w;
        }
    };
    let done = SCRATCH.with(|s| match s.try_borrow_mut() {
        Ok(mut bt) => {
            run(&mut bt);
            true
        }
        Err(_) => false,
    });
    if !done {
        run(&mut Vec::new());
    }
}

/// All row blocks of `R` rows of one column strip of [`gemm_nt`]; the last block repeats its last valid row.
///
/// # Safety
/// As [`kernel`] for every block.
#[target_feature(enable = "avx512f")]
unsafe fn nt_rows<const R: usize, const NV: usize>(
    (m, kc): (usize, usize),
    a: impl Rows,
    b: Strided,
    (c, ldc): (*mut f32, usize),
    mask: __mmask16,
    start: Start,
) {
    for i0 in (0..m).step_by(R) {
        let mr = R.min(m - i0);
        let ap: [*const f32; R] = core::array::from_fn(|r| a.row(i0 + r.min(mr - 1)));
        kernel::<R, NV, _>(
            kc,
            &ap,
            1,
            b,
            c.add(i0 * ldc),
            ldc,
            mr,
            mask,
            start,
            Lanes::contiguous(),
        );
    }
}

/// `dst[p · rows + j] = src[j · lds + p]` for a `rows × cols` source: 16 × 16 blocks in registers, edges scalar.
///
/// # Safety
/// avx512f; `src` holds `rows` rows of `cols` floats at stride `lds`; `dst` holds `rows · cols` floats.
#[target_feature(enable = "avx512f")]
unsafe fn transpose(rows: usize, cols: usize, src: *const f32, lds: usize, dst: *mut f32) {
    let (rows16, cols16) = (rows / 16 * 16, cols / 16 * 16);
    for j0 in (0..rows16).step_by(16) {
        for p0 in (0..cols16).step_by(16) {
            transpose16(src.add(j0 * lds + p0), lds, dst.add(p0 * rows + j0), rows);
        }
    }
    for j in 0..rows {
        let from = if j < rows16 { cols16 } else { 0 };
        for p in from..cols {
            *dst.add(p * rows + j) = *src.add(j * lds + p);
        }
    }
}

/// Transposes one 16 × 16 block (`src` rows at stride `lds` into `dst` rows at stride `ldd`): 32-bit and 64-bit
/// interleaves, then two rounds of 128-bit lane shuffles.
///
/// # Safety
/// avx512f; both blocks lie inside their buffers.
#[target_feature(enable = "avx512f")]
#[allow(clippy::needless_range_loop)]
unsafe fn transpose16(src: *const f32, lds: usize, dst: *mut f32, ldd: usize) {
    let r: [__m512; 16] = core::array::from_fn(|i| _mm512_loadu_ps(src.add(i * lds)));
    let mut t = [_mm512_setzero_ps(); 16];
    for i in 0..8 {
        t[2 * i] = _mm512_unpacklo_ps(r[2 * i], r[2 * i + 1]);
        t[2 * i + 1] = _mm512_unpackhi_ps(r[2 * i], r[2 * i + 1]);
    }
    let lo = |a: __m512, b: __m512| {
        _mm512_castpd_ps(_mm512_unpacklo_pd(_mm512_castps_pd(a), _mm512_castps_pd(b)))
    };
    let hi = |a: __m512, b: __m512| {
        _mm512_castpd_ps(_mm512_unpackhi_pd(_mm512_castps_pd(a), _mm512_castps_pd(b)))
    };
    let mut u = [_mm512_setzero_ps(); 16];
    for q in 0..4 {
        u[4 * q] = lo(t[4 * q], t[4 * q + 2]);
        u[4 * q + 1] = hi(t[4 * q], t[4 * q + 2]);
        u[4 * q + 2] = lo(t[4 * q + 1], t[4 * q + 3]);
        u[4 * q + 3] = hi(t[4 * q + 1], t[4 * q + 3]);
    }
    for h in 0..2 {
        for i in 0..4 {
            t[8 * h + i] = _mm512_shuffle_f32x4::<0x88>(u[8 * h + i], u[8 * h + i + 4]);
            t[8 * h + i + 4] = _mm512_shuffle_f32x4::<0xdd>(u[8 * h + i], u[8 * h + i + 4]);
        }
    }
    for i in 0..8 {
        _mm512_storeu_ps(
            dst.add(i * ldd),
            _mm512_shuffle_f32x4::<0x88>(t[i], t[i + 8]),
        );
        _mm512_storeu_ps(
            dst.add((i + 8) * ldd),
            _mm512_shuffle_f32x4::<0xdd>(t[i], t[i + 8]),
        );
    }
}
