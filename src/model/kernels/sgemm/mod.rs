//! Single-precision GEMM for the tiled convolution (paper IV.B, speed on the CPU).
//!
//! [`super::conv_tiled`] needs three row-major products per tile: the forward
//! `Y[co, t] = bias + W[co, k] · cols[k, t]`, the input gradient `dcols[k, t] = Wᵀ[k, co] · dY[co, t]` (both
//! [`PackedA::matmul`]: A is the weight, packed once per convolution) and the weight gradient, taken as
//! `dWᵀ[k, co] (+)= cols[k, t] · dY[co, t]ᵀ` ([`matmul_nt`]) so that the long pixel axis is the summed one. On CPUs
//! with AVX-512 they run our kernels in [`avx512`] (about twice the `gemm` crate's GFLOP/s: `tnd bench gemm`);
//! elsewhere (other architectures, older x86, [`GemmBackend::GemmCrate`] asked for explicitly, or a dimension below
//! [`SMALL_DIM`]) the `gemm` crate, whose x86 kernel on stable Rust is AVX2. The CPU is probed once per process
//! ([`GemmBackend::detect`]). Both backends sum every output element in an order fixed by the sizes, so re-runs on
//! the same machine are bit-identical.

#[cfg(target_arch = "x86_64")]
pub mod avx512;

use std::ops::Range;
use std::sync::OnceLock;

use candle_core::Result;
use gemm::{gemm, Parallelism};

/// Products with a dimension below this ([`PackedA`] rows or inner size, [`matmul_nt`] columns) use the `gemm`
/// crate on every backend.
pub const SMALL_DIM: usize = 8;

/// Which GEMM implementation runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GemmBackend {
    /// Our AVX-512 kernels (x86-64 with `avx512f` only).
    Avx512,
    /// The `gemm` crate (portable; AVX2 + FMA on x86-64).
    GemmCrate,
}

impl GemmBackend {
    /// The fastest backend this CPU runs, detected on first use and cached.
    pub fn detect() -> Self {
        static DETECTED: OnceLock<GemmBackend> = OnceLock::new();
        *DETECTED.get_or_init(|| {
            if Self::Avx512.is_available() {
                Self::Avx512
            } else {
                Self::GemmCrate
            }
        })
    }

    /// Whether this CPU can run the backend.
    pub fn is_available(self) -> bool {
        match self {
            Self::GemmCrate => true,
            #[cfg(target_arch = "x86_64")]
            Self::Avx512 => std::arch::is_x86_feature_detected!("avx512f"),
            #[cfg(not(target_arch = "x86_64"))]
            Self::Avx512 => false,
        }
    }

    /// `self` if this CPU runs it, else the `gemm` crate.
    fn usable(self) -> Self {
        if self.is_available() {
            self
        } else {
            Self::GemmCrate
        }
    }
}

/// What C holds before the product is added by [`PackedA::matmul`].
#[derive(Clone, Copy, Debug)]
pub enum Init<'a> {
    /// Nothing: `C = A · B` (C is only written).
    Zero,
    /// Its current values: `C += A · B`.
    Accumulate,
    /// Row `i` starts from `bias[i]`: `C = bias ⊗ 1 + A · B`, without reading C (a convolution's bias).
    RowBias(&'a [f32]),
}

/// Whether a row-major `rows × cols` matrix at row stride `ld` fits in `len` floats.
fn fits(len: usize, rows: usize, cols: usize, ld: usize) -> bool {
    rows == 0 || cols == 0 || ((rows - 1) * ld + cols <= len && (rows == 1 || ld >= cols))
}

/// The left operand `A` (`m × k`) of `C = A · B`, laid out once for the backend (the weight of a convolution is
/// packed once per call and shared by every tile and thread).
#[derive(Clone, Debug)]
pub struct PackedA {
    backend: GemmBackend,
    m: usize,
    k: usize,
    /// AVX-512: panels of [`avx512::MR`] rows; `gemm` crate: row-major `m × k`.
    data: Vec<f32>,
}

impl PackedA {
    /// Packs `A[i, p] = a[i · rs + p · cs]` for the detected backend (`rs = k, cs = 1` for a row-major A,
    /// `rs = 1, cs = m` for the transpose of a row-major `k × m` matrix).
    pub fn new(m: usize, k: usize, a: &[f32], rs: usize, cs: usize) -> Result<Self> {
        Self::with_backend(GemmBackend::detect(), m, k, a, rs, cs)
    }

    /// As [`PackedA::new`] for a given backend (the `gemm` crate where the CPU lacks the one asked for, or where
    /// `m` or `k` is below [`SMALL_DIM`]).
    pub fn with_backend(
        backend: GemmBackend,
        m: usize,
        k: usize,
        a: &[f32],
        rs: usize,
        cs: usize,
    ) -> Result<Self> {
        if m > 0 && k > 0 && (m - 1) * rs + (k - 1) * cs >= a.len() {
            candle_core::bail!(
                "sgemm: A of {m}x{k} (strides {rs}, {cs}) does not fit {} floats",
                a.len()
            );
        }
        let backend = Self::resolve_backend(backend, m, k);
        let data = match backend {
            #[cfg(target_arch = "x86_64")]
            GemmBackend::Avx512 => avx512::pack_a(m, k, a, rs, cs),
            _ => {
                let mut d = Vec::with_capacity(m * k);
                for i in 0..m {
                    d.extend((0..k).map(|p| a[i * rs + p * cs]));
                }
                d
            }
        };
        Ok(Self {
            backend,
            m,
            k,
            data,
        })
    }

    /// The backend [`PackedA::with_backend`] packs an `m × k` operand for when asked for `backend`.
    pub fn resolve_backend(backend: GemmBackend, m: usize, k: usize) -> GemmBackend {
        // Our register blocks are 8 rows and 16 columns wide: a dimension below 8 (the 1-channel output layer) runs
        // as fast or faster on the gemm crate (19 against 17 GFLOP/s for Wᵀ·dY with one channel).
        if m.min(k) < SMALL_DIM {
            GemmBackend::GemmCrate
        } else {
            backend.usable()
        }
    }

    /// The backend this operand was packed for.
    pub fn backend(&self) -> GemmBackend {
        self.backend
    }

    /// `(m, k)`: rows and inner size.
    pub fn dims(&self) -> (usize, usize) {
        (self.m, self.k)
    }

    /// The row-major `m × k` matrix `a` packed for `backend`: `frozen` where it was packed for exactly that (a
    /// model's weights packed once for inference, [`crate::model::conv::Conv2d::freeze`]), else packed now.
    pub fn frozen_or_pack<'a>(
        frozen: Option<&'a PackedA>,
        backend: GemmBackend,
        m: usize,
        k: usize,
        a: &[f32],
    ) -> Result<std::borrow::Cow<'a, PackedA>> {
        match frozen {
            Some(p) if p.dims() == (m, k) && p.backend == Self::resolve_backend(backend, m, k) => {
                Ok(std::borrow::Cow::Borrowed(p))
            }
            _ => Ok(std::borrow::Cow::Owned(Self::with_backend(
                backend, m, k, a, k, 1,
            )?)),
        }
    }

    /// `C[m, n] = init + A · B[k, n]`, B and C row-major at row strides `ldb` and `ldc`; every element is summed
    /// as `((init + a₀b₀) + a₁b₁) + …` in order of the inner index.
    pub fn matmul(
        &self,
        n: usize,
        b: &[f32],
        ldb: usize,
        c: &mut [f32],
        ldc: usize,
        init: Init,
    ) -> Result<()> {
        if !fits(c.len(), self.m, n, ldc) {
            candle_core::bail!("sgemm: C of {}x{n} (stride {ldc}) does not fit", self.m);
        }
        // SAFETY: C was checked to lie inside the exclusively borrowed slice.
        unsafe { self.matmul_raw(n, b, ldb, c.as_mut_ptr(), ldc, init) }
    }

    /// As [`PackedA::matmul`] with C given by pointer, for outputs that several threads fill in disjoint blocks.
    ///
    /// # Safety
    /// `c` points to `m` rows of `n` floats at stride `ldc`, valid for reads and writes, and no one else reads or
    /// writes those elements during the call.
    pub unsafe fn matmul_raw(
        &self,
        n: usize,
        b: &[f32],
        ldb: usize,
        c: *mut f32,
        ldc: usize,
        init: Init,
    ) -> Result<()> {
        let (m, k) = (self.m, self.k);
        check_bias(init, m)?;
        if !fits(b.len(), k, n, ldb) {
            candle_core::bail!(
                "sgemm: B of {k}x{n} (stride {ldb}) does not fit {} floats",
                b.len()
            );
        }
        if m == 0 || n == 0 {
            return Ok(());
        }
        match self.backend {
            #[cfg(target_arch = "x86_64")]
            // SAFETY: the backend is usable (checked when packing); sizes checked above and by the caller.
            GemmBackend::Avx512 => {
                let b = avx512::Strided {
                    base: b.as_ptr(),
                    ld: ldb,
                };
                avx512::gemm_packed(m, n, k, &self.data, b, c, ldc, init)
            }
            _ => {
                if let Init::RowBias(bias) = init {
                    for (i, &v) in bias.iter().enumerate() {
                        // SAFETY: row i of C (n floats at c + i·ldc) is valid for writes (caller's contract).
                        std::slice::from_raw_parts_mut(c.add(i * ldc), n).fill(v);
                    }
                }
                gemm_crate_nn(self, n, b, ldb, c, ldc, !matches!(init, Init::Zero));
            }
        }
        Ok(())
    }
}

impl PackedA {
    /// Rows of A that [`PackedA::matmul_offsets_rows_raw`] can start a row range at a multiple of (the panel
    /// height of the AVX-512 packing, 1 for the row-major one).
    pub fn row_align(&self) -> usize {
        match self.backend {
            #[cfg(target_arch = "x86_64")]
            GemmBackend::Avx512 => avx512::MR,
            _ => 1,
        }
    }

    /// `C[m, n] = init + A · B` where row `p` of B is `b[offs[p]..offs[p] + n]` (`offs` has `k` entries): the
    /// shifted rows of a padded image, so a convolution needs no im2col copy. Summation order as
    /// [`PackedA::matmul`]. The `gemm` crate cannot read such rows: that backend runs a portable loop.
    ///
    /// # Safety
    /// As [`PackedA::matmul_raw`] for C.
    pub unsafe fn matmul_offsets_raw(
        &self,
        n: usize,
        b: &[f32],
        offs: &[usize],
        c: *mut f32,
        ldc: usize,
        init: Init,
    ) -> Result<()> {
        self.matmul_offsets_rows_raw(0..self.m, n, b, offs, c, ldc, init)
    }

    /// Rows `rows` of [`PackedA::matmul_offsets_raw`]'s product: `c` points to row `rows.start` of C and holds
    /// `rows.len()` rows; an `Init::RowBias` still holds one value per row of the whole of A. `rows.start` must be
    /// a multiple of [`PackedA::row_align`]. Each element is summed exactly as in the whole product, so threads
    /// that split the rows of one product between them give the same bits as one thread.
    ///
    /// # Safety
    /// As [`PackedA::matmul_raw`] for the `rows.len()` rows of C at `c`.
    #[allow(clippy::too_many_arguments)]
    pub unsafe fn matmul_offsets_rows_raw(
        &self,
        rows: Range<usize>,
        n: usize,
        b: &[f32],
        offs: &[usize],
        c: *mut f32,
        ldc: usize,
        init: Init,
    ) -> Result<()> {
        let k = self.k;
        check_offsets(offs, k, n, b.len(), "B")?;
        let init = self.rows_init(&rows, init)?;
        let m = rows.len();
        if m == 0 || n == 0 {
            return Ok(());
        }
        match self.backend {
            #[cfg(target_arch = "x86_64")]
            // SAFETY: the backend is usable (checked when packing); every row of B checked above, C by the caller;
            // the panels from `rows.start / MR` on hold rows `rows` (rows.start is a panel boundary).
            GemmBackend::Avx512 => {
                let b_rows = avx512::Offsets {
                    base: b.as_ptr(),
                    offs: offs.as_ptr(),
                };
                let panels = &self.data[rows.start * k..];
                avx512::gemm_packed(m, n, k, panels, b_rows, c, ldc, init);
            }
            _ => {
                for i in 0..m {
                    // SAFETY: row i of C is valid and exclusive (caller's contract).
                    let row = std::slice::from_raw_parts_mut(c.add(i * ldc), n);
                    match init {
                        Init::Zero => row.fill(0.0),
                        Init::Accumulate => {}
                        Init::RowBias(bias) => row.fill(bias[i]),
                    }
                    let a = &self.data[(rows.start + i) * k..(rows.start + i + 1) * k];
                    for (&a, &o) in a.iter().zip(offs) {
                        for (y, &v) in row.iter_mut().zip(&b[o..o + n]) {
                            *y += a * v;
                        }
                    }
                }
            }
        }
        Ok(())
    }
}

impl PackedA {
    /// Checks that `rows` is a range of A's rows starting at a multiple of [`PackedA::row_align`] and that an
    /// `Init::RowBias` holds one value per row of A; returns `init` for those rows.
    fn rows_init<'a>(&self, rows: &Range<usize>, init: Init<'a>) -> Result<Init<'a>> {
        check_bias(init, self.m)?;
        if rows.end > self.m
            || rows.start > rows.end
            || !rows.start.is_multiple_of(self.row_align())
        {
            candle_core::bail!(
                "sgemm: rows {rows:?} of a {}-row A (starts at multiples of {})",
                self.m,
                self.row_align()
            );
        }
        Ok(match init {
            Init::RowBias(bias) => Init::RowBias(&bias[rows.clone()]),
            other => other,
        })
    }

    /// [`PackedA::matmul_offsets_rows_raw`] over a padded grid of `rows` rows of `wp` positions (B's `n` is
    /// `rows · wp`), keeping only the first `w` positions of each grid row: the product at `(y, x < w)` goes to
    /// column `y · w + x` of C, which holds `rows.len()` rows of `rows · w` floats at stride `ldc` — a
    /// convolution writes its output image directly instead of a wide product copied out row by row. Each element
    /// is summed exactly as in the wide product. On the AVX-512 backend `w` must be a multiple of 16 (whole
    /// vectors per image row); other backends take any `w`.
    ///
    /// # Safety
    /// As [`PackedA::matmul_raw`] for the `rows.len()` rows of `rows · w` floats at `c`.
    #[allow(clippy::too_many_arguments)]
    pub unsafe fn matmul_offsets_image_raw(
        &self,
        rows: Range<usize>,
        (grid_rows, w, wp): (usize, usize, usize),
        b: &[f32],
        offs: &[usize],
        c: *mut f32,
        ldc: usize,
        init: Init,
    ) -> Result<()> {
        if w > wp {
            candle_core::bail!("sgemm: image width {w} exceeds the grid's row of {wp}");
        }
        check_offsets(offs, self.k, grid_rows * wp, b.len(), "B")?;
        match self.backend {
            #[cfg(target_arch = "x86_64")]
            GemmBackend::Avx512 => {
                if !w.is_multiple_of(16) {
                    candle_core::bail!("sgemm: image width {w} is not a multiple of 16");
                }
                let k = self.k;
                let init = self.rows_init(&rows, init)?;
                let b_rows = avx512::Offsets {
                    base: b.as_ptr(),
                    offs: offs.as_ptr(),
                };
                let panels = &self.data[rows.start * k..];
                // SAFETY: as in matmul_offsets_rows_raw; B's grid rows checked above, C by the caller.
                avx512::gemm_packed_image(
                    rows.len(),
                    k,
                    panels,
                    b_rows,
                    (grid_rows, w, wp),
                    c,
                    ldc,
                    init,
                );
                Ok(())
            }
            _ => {
                for y in 0..grid_rows {
                    // SAFETY: column y · w of C's rows (caller's contract); grid row y of B is B from y · wp.
                    self.matmul_offsets_rows_raw(
                        rows.clone(),
                        w,
                        b.get(y * wp..).unwrap_or_default(),
                        offs,
                        c.add(y * w),
                        ldc,
                        init,
                    )?;
                }
                Ok(())
            }
        }
    }
}

/// An `Init::RowBias` holds one value per row of C.
fn check_bias(init: Init, m: usize) -> Result<()> {
    match init {
        Init::RowBias(bias) if bias.len() != m => {
            candle_core::bail!("sgemm: {} row biases for {m} rows", bias.len())
        }
        _ => Ok(()),
    }
}

/// The backend an `A·Bᵀ` product with `n` columns runs on: the `gemm` crate below [`SMALL_DIM`] columns (our
/// blocks are 16 columns wide), else `backend` where the CPU has it.
fn nt_backend(backend: GemmBackend, n: usize) -> GemmBackend {
    if n < SMALL_DIM {
        GemmBackend::GemmCrate
    } else {
        backend.usable()
    }
}

/// Every row `offs[p] .. offs[p] + n` of a `k`-row operand lies inside `len` floats.
fn check_offsets(offs: &[usize], k: usize, n: usize, len: usize, what: &str) -> Result<()> {
    if offs.len() != k {
        candle_core::bail!("sgemm: {} row offsets for {k} rows of {what}", offs.len());
    }
    if let Some(&o) = offs.iter().find(|&&o| o + n > len) {
        candle_core::bail!("sgemm: a row of {what} at {o} + {n} floats does not fit {len}");
    }
    Ok(())
}

/// `C[m, n] = (accumulate ? C : 0) + A · B[n, k]ᵀ` where row `i` of A is `a[a_offs[i]..a_offs[i] + k]` (the
/// weight gradient of the direct convolution: A's rows are shifted rows of the padded input) and B is row-major
/// at stride `ldb`. Fewer than [`SMALL_DIM`] columns, or no AVX-512: 16-lane dot products in a fixed order.
#[allow(clippy::too_many_arguments)]
pub fn matmul_nt_offsets(
    backend: GemmBackend,
    (m, n, k): (usize, usize, usize),
    a: &[f32],
    a_offs: &[usize],
    b: &[f32],
    ldb: usize,
    c: &mut [f32],
    ldc: usize,
    accumulate: bool,
) -> Result<()> {
    check_offsets(a_offs, m, k, a.len(), "A")?;
    if !fits(b.len(), n, k, ldb) || !fits(c.len(), m, n, ldc) {
        candle_core::bail!(
            "sgemm: A·Bᵀ of {m}x{k} · ({n}x{k})ᵀ does not fit its buffers ({}, {} floats)",
            b.len(),
            c.len()
        );
    }
    if m == 0 || n == 0 {
        return Ok(());
    }
    let backend = nt_backend(backend, n);
    match backend {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: avx512f present (usable); every row of A and the whole of B and C checked above.
        GemmBackend::Avx512 => unsafe {
            let rows = avx512::Offsets {
                base: a.as_ptr(),
                offs: a_offs.as_ptr(),
            };
            avx512::gemm_nt(
                m,
                n,
                k,
                rows,
                b.as_ptr(),
                ldb,
                c.as_mut_ptr(),
                ldc,
                accumulate,
            );
        },
        _ => {
            for (i, &o) in a_offs.iter().enumerate() {
                let ar = &a[o..o + k];
                for j in 0..n {
                    let dot = dot16(ar, &b[j * ldb..j * ldb + k]);
                    let cij = &mut c[i * ldc + j];
                    *cij = if accumulate { *cij + dot } else { dot };
                }
            }
        }
    }
    Ok(())
}

/// `Σ x·y` over 16 interleaved partial sums (vectorisable without reassociation; fixed order).
fn dot16(x: &[f32], y: &[f32]) -> f32 {
    let mut acc = [0f32; 16];
    let (xc, yc) = (x.chunks_exact(16), y.chunks_exact(16));
    let (xr, yr) = (xc.remainder(), yc.remainder());
    for (a, b) in xc.zip(yc) {
        for l in 0..16 {
            acc[l] += a[l] * b[l];
        }
    }
    for (l, (a, b)) in xr.iter().zip(yr).enumerate() {
        acc[l] += a * b;
    }
    acc.iter().sum()
}

/// The `gemm` crate's `C = (read_c ? C : 0) + A · B` for a row-major `A`.
///
/// # Safety
/// As [`PackedA::matmul_raw`], with `a` packed for [`GemmBackend::GemmCrate`] and B checked.
unsafe fn gemm_crate_nn(
    a: &PackedA,
    n: usize,
    b: &[f32],
    ldb: usize,
    c: *mut f32,
    ldc: usize,
    read_c: bool,
) {
    let (m, k) = (a.m, a.k);
    // SAFETY: A is row-major m × k in `a.data`; B and C as the caller guarantees.
    unsafe {
        gemm(
            m,
            n,
            k,
            c,
            1,
            ldc as isize,
            read_c,
            a.data.as_ptr(),
            1,
            k as isize,
            b.as_ptr(),
            1,
            ldb as isize,
            1.0,
            1.0,
            false,
            false,
            false,
            Parallelism::None,
        )
    }
}

/// `C[m, n] = (accumulate ? C : 0) + A[m, k] · B[n, k]ᵀ`, all row-major (strides `lda`, `ldb`, `ldc`): the weight
/// gradient `dWᵀ = cols · dYᵀ`, with both operands contiguous along the summed dimension. Fewer than
/// [`SMALL_DIM`] columns go to the `gemm` crate on every backend (a 1-channel output layer: 28 against 8 GFLOP/s
/// for our kernel, whose blocks are 16 columns wide).
#[allow(clippy::too_many_arguments)]
pub fn matmul_nt(
    backend: GemmBackend,
    (m, n, k): (usize, usize, usize),
    a: &[f32],
    lda: usize,
    b: &[f32],
    ldb: usize,
    c: &mut [f32],
    ldc: usize,
    accumulate: bool,
) -> Result<()> {
    if !fits(a.len(), m, k, lda) || !fits(b.len(), n, k, ldb) || !fits(c.len(), m, n, ldc) {
        candle_core::bail!(
            "sgemm: A·Bᵀ of {m}x{k} · ({n}x{k})ᵀ does not fit its buffers ({}, {}, {} floats)",
            a.len(),
            b.len(),
            c.len()
        );
    }
    if m == 0 || n == 0 {
        return Ok(());
    }
    let backend = nt_backend(backend, n);
    match backend {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: avx512f present (usable); every matrix checked to lie inside its slice.
        GemmBackend::Avx512 => unsafe {
            avx512::gemm_nt(
                m,
                n,
                k,
                avx512::Strided {
                    base: a.as_ptr(),
                    ld: lda,
                },
                b.as_ptr(),
                ldb,
                c.as_mut_ptr(),
                ldc,
                accumulate,
            )
        },
        // SAFETY: every matrix checked to lie inside its slice; B is read as its transpose (column stride ldb).
        _ => unsafe {
            gemm(
                m,
                n,
                k,
                c.as_mut_ptr(),
                1,
                ldc as isize,
                accumulate,
                a.as_ptr(),
                1,
                lda as isize,
                b.as_ptr(),
                ldb as isize,
                1,
                1.0,
                1.0,
                false,
                false,
                false,
                Parallelism::None,
            )
        },
    }
    Ok(())
}

#[cfg(test)]
mod tests;
