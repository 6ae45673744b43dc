//! Direct ("implicit GEMM") convolution for the U-Net's stride-1 "same" convolutions (paper IV.B, speed on the
//! CPU): every 3 × 3 convolution of the ResNet blocks and up-samplers, and the 1 × 1 shortcuts.
//!
//! Measured first (`perf`, default model, training step): the tiled path's im2col and col2im copies
//! ([`super::conv_tiled`]) took about a quarter of the step. Here nothing is unfolded. A sample's channels are
//! copied once into a zero-padded image of row width `Wp = W + 2p`; on that grid, the im2col row of tap
//! `(ci, ky, kx)` *is* the padded image read from offset `ci·plane + ky·Wp + kx`, so the GEMM kernels read B's rows
//! (or A's, for the weight gradient) straight from the image at those offsets ([`PackedA::matmul_offsets_raw`],
//! [`matmul_nt_offsets`]). The products are computed at all `H × Wp` grid positions; the `2p` columns past each
//! row are discarded when the result is copied out. The backward is the same trick twice: the input gradient is a
//! direct convolution of the padded output gradient with the flipped, transposed kernel, and the weight gradient
//! reads the padded input and the padded output gradient, whose off-image columns are zero. Work is split by
//! (sample, row tile) forward and by sample backward, with a fixed summation order (deterministic results).
//! Tests compare it with candle's `conv2d` (values and gradients) in `tests/model_unet.rs`.

use candle_core::{CpuStorage, CustomOp3, Layout, Result, Shape, Tensor};
use std::sync::Arc;

use rayon::prelude::*;

use super::conv_tiled::SendPtr;
use super::sgemm::{matmul_nt_offsets, GemmBackend, Init, PackedA};
use super::ConvGeom;

/// Whether [`conv2d_direct`] computes a convolution of this geometry: stride 1, odd kernel, padding
/// `(kernel − 1) / 2` on every side (the output has the input's size).
pub fn supports(g: ConvGeom) -> bool {
    g.stride == 1 && g.kernel % 2 == 1 && g.pad_begin == g.kernel / 2 && g.pad_end == g.kernel / 2
}

/// Convolution of `x` `[B, Cin, H, W]` with `w` `[Cout, Cin, k, k]` plus `bias` by the direct path
/// (differentiable). The geometry must satisfy [`supports`]. `frozen`: `w` already packed (used where it fits).
pub fn conv2d_direct(
    x: &Tensor,
    w: &Tensor,
    bias: &Tensor,
    geom: ConvGeom,
    frozen: Option<&Arc<PackedA>>,
) -> Result<Tensor> {
    if !supports(geom) {
        candle_core::bail!("direct convolution: unsupported geometry {geom:?}");
    }
    let op = DirectConv {
        kernel: geom.kernel,
        backend: GemmBackend::detect(),
        frozen: frozen.cloned(),
    };
    x.contiguous()?
        .apply_op3(&w.contiguous()?, &bias.contiguous()?, op)
}

/// Forward op on `(x, w, bias)`; `backend` is the GEMM to use (tests force the portable one); `frozen` is `w`
/// packed once for inference (used when it was packed for this shape and backend, else `w` is packed per call).
#[derive(Clone, Debug)]
pub struct DirectConv {
    pub kernel: usize,
    pub backend: GemmBackend,
    pub frozen: Option<Arc<PackedA>>,
}

/// Backward op on `(x, w, dy)` returning `[dx…, dw…, db…]` flat.
#[derive(Clone, Copy, Debug)]
struct DirectConvBackward {
    kernel: usize,
    backend: GemmBackend,
}

/// Grid positions per forward work item (its padded input and output stay in L2). Each item pads its rows plus
/// `2p` halo rows, so larger tiles copy less, but a batch-1 forward then has fewer items for the two threads:
/// 1024 made it 15-16 ms instead of 12.5-13 (256 was within noise of 384).
const TILE_POSITIONS: usize = 384;

/// Sizes of one convolution on the padded grid.
#[derive(Clone, Copy, Debug)]
struct Grid {
    b: usize,
    h: usize,
    w: usize,
    /// Kernel size `k` and padding `p = (k − 1) / 2`.
    k: usize,
    p: usize,
    /// Padded row width `W + 2p`.
    wp: usize,
}

impl Grid {
    fn new(x: &[usize], k: usize) -> Result<(Self, usize)> {
        let [b, c, h, w] = x else {
            candle_core::bail!("conv: input must be 4-D, found {x:?}")
        };
        let p = k / 2;
        Ok((
            Self {
                b: *b,
                h: *h,
                w: *w,
                k,
                p,
                wp: w + 2 * p,
            },
            *c,
        ))
    }

    /// Floats of one padded channel holding `rows` image rows (plus `p` zero rows above and below).
    fn plane(&self, rows: usize) -> usize {
        (rows + 2 * self.p) * self.wp
    }

    /// Length of a padded image of `c` channels of `rows` rows: the last tap's reads of the off-image columns run
    /// `2p` floats past the last plane.
    fn padded_len(&self, c: usize, rows: usize) -> usize {
        c * self.plane(rows) + 2 * self.p
    }

    /// Offsets of the taps `(c, ky, kx)` (the weight's inner index order) in a padded image of `rows` rows.
    fn tap_offsets(&self, c: usize, rows: usize) -> Vec<usize> {
        let plane = self.plane(rows);
        let mut offs = Vec::with_capacity(c * self.k * self.k);
        for ci in 0..c {
            for ky in 0..self.k {
                for kx in 0..self.k {
                    offs.push(ci * plane + ky * self.wp + kx);
                }
            }
        }
        offs
    }

    /// Image rows per forward work item: about [`TILE_POSITIONS`] grid positions.
    fn tile_rows(&self) -> usize {
        TILE_POSITIONS.div_ceil(self.wp).clamp(1, self.h.max(1))
    }
}

/// Output channels per forward work item. A batch-1 forward at 16 × 16 is one tile, and at 32 × 32 three: as
/// whole-image items they left a thread idle for a third of the forward (`perf`: 1.3 of 2 cores busy). When the
/// `items` (sample, tile) pairs are few, each is split into channel ranges (whole GEMM panels of `align` rows, at
/// least two panels each) until there are at least two per thread and a multiple of `threads`. Every output element
/// is summed as before, so the split does not change the values.
fn channel_chunk(items: usize, co: usize, align: usize, threads: usize) -> usize {
    if threads < 2 || items >= 8 * threads || items == 0 {
        return co.max(1);
    }
    let max_split = (co / (2 * align)).max(1);
    let split = (1..=max_split)
        .find(|&k| items * k >= 2 * threads && (items * k).is_multiple_of(threads))
        .unwrap_or(max_split);
    co.div_ceil(split).next_multiple_of(align).max(1)
}

/// Whether the GEMM writes the output image directly ([`PackedA::matmul_offsets_image_raw`]: whole 16-wide
/// vectors per image row on AVX-512, any width on the portable path) rather than a wide product over the padded
/// grid that [`unpad_into`] copies out. At widths like 8 the wide product keeps full vectors and wins.
fn writes_image(g: &Grid, backend: GemmBackend) -> bool {
    backend != GemmBackend::Avx512 || g.w.is_multiple_of(16)
}

/// Writes rows `y0 .. y0 + rows` of one sample `src` `[C, H, W]` into `dst` as a zero-padded image with `p` rows
/// of the sample's neighbourhood (or zeros outside it) above and below and `p` zero columns on each side.
/// Only the margins are zeroed (a whole-buffer fill first was a second full-size write: 1.4 % of a training step).
fn pad_rows(src: &[f32], c: usize, g: &Grid, y0: usize, rows: usize, dst: &mut [f32]) {
    let plane = g.plane(rows);
    for ci in 0..c {
        let s = &src[ci * g.h * g.w..(ci + 1) * g.h * g.w];
        let d = &mut dst[ci * plane..(ci + 1) * plane];
        for (r, row) in d.chunks_exact_mut(g.wp).enumerate() {
            let y = (y0 + r) as isize - g.p as isize;
            if y >= 0 && (y as usize) < g.h {
                let y = y as usize;
                let (left, rest) = row.split_at_mut(g.p);
                let (mid, right) = rest.split_at_mut(g.w);
                left.fill(0.0);
                mid.copy_from_slice(&s[y * g.w..(y + 1) * g.w]);
                right.fill(0.0);
            } else {
                row.fill(0.0);
            }
        }
    }
    // The last tap's reads run 2p floats past the last plane.
    dst[c * plane..g.padded_len(c, rows)].fill(0.0);
}

/// Copies the first `W` of every `Wp` grid columns of `wide` (`c` rows of `rows · Wp`) into rows `y0..` of `dst`
/// (`[c, H, W]`).
fn unpad_into(wide: &[f32], c: usize, g: &Grid, y0: usize, rows: usize, dst: &mut [f32]) {
    for ci in 0..c {
        for r in 0..rows {
            let from = &wide[(ci * rows + r) * g.wp..(ci * rows + r) * g.wp + g.w];
            let to = (ci * g.h + y0 + r) * g.w;
            dst[to..to + g.w].copy_from_slice(from);
        }
    }
}

impl CustomOp3 for DirectConv {
    fn name(&self) -> &'static str {
        "conv2d-direct"
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
        let x = super::simd::contiguous_f32(s1, l1, "conv: input")?;
        let w = super::simd::contiguous_f32(s2, l2, "conv: weight")?;
        let bias = super::simd::contiguous_f32(s3, l3, "conv: bias")?;
        let (g, c) = Grid::new(l1.shape().dims(), self.kernel)?;
        let co = l2.shape().dims()[0];
        let kk = c * g.k * g.k;
        if w.len() != co * kk || bias.len() != co {
            candle_core::bail!(
                "conv: weight {:?} / bias {} do not fit input {:?}",
                l2.shape(),
                bias.len(),
                l1.shape()
            );
        }
        let hw = g.h * g.w;
        // SAFETY: the work items below write every (sample, channel, row) of y.
        let mut y = unsafe { super::alloc::output_vec(g.b * co * hw) };
        let yp = SendPtr(y.as_mut_ptr());
        let w_packed = PackedA::frozen_or_pack(self.frozen.as_deref(), self.backend, co, kk, w)?;
        let tr = g.tile_rows();
        let tiles = g.h.div_ceil(tr);
        let image = writes_image(&g, w_packed.backend());
        // Tap offsets of a full tile and of the last, possibly shorter one (they depend on the tile's plane size).
        let last_rows = g.h - tiles.saturating_sub(1) * tr;
        let (offs_full, offs_last) = (g.tap_offsets(c, tr), g.tap_offsets(c, last_rows));
        let chunk = channel_chunk(
            g.b * tiles,
            co,
            w_packed.row_align(),
            rayon::current_num_threads(),
        );
        let items: Vec<(usize, usize, usize)> = (0..g.b)
            .flat_map(|b| (0..tiles).map(move |t| (b, t)))
            .flat_map(|(b, t)| (0..co).step_by(chunk).map(move |c0| (b, t, c0)))
            .collect();
        items.par_iter().try_for_each_init(
            // SAFETY (scratch, allocated per rayon split, zeroing it was 0.5 % of a training step): every item
            // writes the part of `xp` it reads (pad_rows: all of padded_len(c, rows)) and of `wide` (the GEMM: its
            // rows × n) first.
            || unsafe {
                (
                    super::alloc::output_vec(g.padded_len(c, tr)),
                    super::alloc::output_vec(if image { 0 } else { chunk * tr * g.wp }),
                )
            },
            |(xp, wide), &(b, tile, c0)| -> Result<()> {
                let y0 = tile * tr;
                let rows = tr.min(g.h - y0);
                let cs = c0..(c0 + chunk).min(co);
                pad_rows(&x[b * c * hw..(b + 1) * c * hw], c, &g, y0, rows, xp);
                let offs = if rows == tr { &offs_full } else { &offs_last };
                let xp = &xp[..g.padded_len(c, rows)];
                if image {
                    // SAFETY: channels cs, rows y0..y0+rows of sample b (at stride hw): inside `y`, disjoint
                    // across items.
                    return unsafe {
                        w_packed.matmul_offsets_image_raw(
                            cs.clone(),
                            (rows, g.w, g.wp),
                            xp,
                            offs,
                            yp.ptr().add((b * co + cs.start) * hw + y0 * g.w),
                            hw,
                            Init::RowBias(bias),
                        )
                    };
                }
                let n = rows * g.wp;
                // SAFETY: `wide` holds chunk ≥ cs.len() rows of n floats and is this work item's own buffer.
                unsafe {
                    w_packed.matmul_offsets_rows_raw(
                        cs.clone(),
                        n,
                        xp,
                        offs,
                        wide.as_mut_ptr(),
                        n,
                        Init::RowBias(bias),
                    )?;
                }
                // SAFETY: channels cs, rows y0..y0+rows of sample b: inside `y`, disjoint across items.
                let yb = unsafe {
                    std::slice::from_raw_parts_mut(
                        yp.ptr().add((b * co + cs.start) * hw),
                        cs.len() * hw,
                    )
                };
                unpad_into(&wide[..cs.len() * n], cs.len(), &g, y0, rows, yb);
                Ok(())
            },
        )?;
        Ok((CpuStorage::F32(y), Shape::from((g.b, co, g.h, g.w))))
    }

    fn bwd(
        &self,
        x: &Tensor,
        w: &Tensor,
        _bias: &Tensor,
        _res: &Tensor,
        grad: &Tensor,
    ) -> Result<(Option<Tensor>, Option<Tensor>, Option<Tensor>)> {
        let op = DirectConvBackward {
            kernel: self.kernel,
            backend: self.backend,
        };
        conv_grads(x, w, grad, &op)
    }
}

impl CustomOp3 for DirectConvBackward {
    fn name(&self) -> &'static str {
        "conv2d-direct-backward"
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
        let x = super::simd::contiguous_f32(s1, l1, "conv: input")?;
        let w = super::simd::contiguous_f32(s2, l2, "conv: weight")?;
        let dy = super::simd::contiguous_f32(s3, l3, "conv: output gradient")?;
        let (g, c) = Grid::new(l1.shape().dims(), self.kernel)?;
        let co = l2.shape().dims()[0];
        let (hw, kk, taps) = (g.h * g.w, c * g.k * g.k, g.k * g.k);
        if w.len() != co * kk || dy.len() != g.b * co * hw {
            candle_core::bail!(
                "conv backward: weight {:?} / gradient {:?} do not fit input {:?}",
                l2.shape(),
                l3.shape(),
                l1.shape()
            );
        }
        // dX = conv(dY padded by p, W flipped in space with in/out channels swapped): A'[ci, (co, ky, kx)].
        let mut wt = vec![0f32; c * co * taps];
        for o in 0..co {
            for ci in 0..c {
                for t in 0..taps {
                    wt[(ci * co + o) * taps + t] = w[(o * c + ci) * taps + (taps - 1 - t)];
                }
            }
        }
        let wt_packed = PackedA::with_backend(self.backend, c, co * taps, &wt, co * taps, 1)?;
        let (x_offs, dy_offs) = (g.tap_offsets(c, g.h), g.tap_offsets(co, g.h));
        let (plane, n) = (g.plane(g.h), g.h * g.wp);
        let tr = g.tile_rows();
        let image = writes_image(&g, wt_packed.backend());
        // out = [dx, dw, db]: dx written by the per-sample items (every channel and row), dw and db below.
        let (nx, nw) = (g.b * c * hw, co * kk);
        // SAFETY: every element is written before `out` is returned.
        let mut out = unsafe { super::alloc::output_vec(nx + nw + co) };
        let (dx, rest) = out.split_at_mut(nx);
        let (dw, db) = rest.split_at_mut(nw);
        // Per sample: dWᵀ_b (overwritten by the GEMM) and Σ dY per channel in f64.
        // SAFETY: matmul_nt_offsets below overwrites every element (accumulate = false).
        let mut dwt_parts = unsafe { super::alloc::output_vec(g.b * kk * co) };
        let mut db_parts = vec![0f64; g.b * co];
        dx.par_chunks_mut(c * hw)
            .zip(dwt_parts.par_chunks_mut(kk * co))
            .zip(db_parts.par_chunks_mut(co))
            .enumerate()
            .try_for_each_init(
                // SAFETY (uninitialised scratch, as in the forward): pad_rows writes all of `xp` and `dyp`, the dX
                // GEMM (Init::Zero) the c × m of `wide` that unpad_into reads.
                || unsafe {
                    (
                        super::alloc::output_vec(g.padded_len(c, g.h)),
                        super::alloc::output_vec(g.padded_len(co, g.h)),
                        super::alloc::output_vec(if image { 0 } else { c * tr * g.wp }),
                    )
                },
                |(xp, dyp, wide), (b, ((dxb, dwtb), dbb))| -> Result<()> {
                    let dy_b = &dy[b * co * hw..(b + 1) * co * hw];
                    pad_rows(&x[b * c * hw..(b + 1) * c * hw], c, &g, 0, g.h, xp);
                    pad_rows(dy_b, co, &g, 0, g.h, dyp);
                    for (s, row) in dbb.iter_mut().zip(dy_b.chunks(hw)) {
                        *s = sum_f64(row);
                    }
                    // dWᵀ_b[(ci, ky, kx), o] = Σ_q Xp[ci, q + ky·Wp + kx] · dYp[o, q + p·Wp + p] over all grid
                    // positions q: dYp's off-image columns are zero, so the extra positions add nothing.
                    let dyw = &dyp[g.p * g.wp + g.p..];
                    matmul_nt_offsets(
                        self.backend,
                        (kk, co, n),
                        xp,
                        &x_offs,
                        dyw,
                        plane,
                        dwtb,
                        co,
                        false,
                    )?;
                    // dX_b row tile by row tile: rows y0.. of the grid start at dYp row y0.
                    for y0 in (0..g.h).step_by(tr) {
                        let rows = tr.min(g.h - y0);
                        if image {
                            // SAFETY: rows y0..y0+rows of every channel of this sample's own dX (stride hw).
                            unsafe {
                                wt_packed.matmul_offsets_image_raw(
                                    0..c,
                                    (rows, g.w, g.wp),
                                    &dyp[y0 * g.wp..],
                                    &dy_offs,
                                    dxb.as_mut_ptr().add(y0 * g.w),
                                    hw,
                                    Init::Zero,
                                )?;
                            }
                            continue;
                        }
                        let m = rows * g.wp;
                        // SAFETY: `wide` holds c rows of m floats and is this work item's own buffer.
                        unsafe {
                            wt_packed.matmul_offsets_raw(
                                m,
                                &dyp[y0 * g.wp..],
                                &dy_offs,
                                wide.as_mut_ptr(),
                                m,
                                Init::Zero,
                            )?;
                        }
                        unpad_into(&wide[..c * m], c, &g, y0, rows, dxb);
                    }
                    Ok(())
                },
            )?;
        sum_parts(&dwt_parts, &db_parts, dw, db);
        let n = out.len();
        Ok((CpuStorage::F32(out), Shape::from(n)))
    }
}

/// `(dx, dw, db)` of a convolution from a backward op on `(x, w, dy)` that returns them packed flat, in that order
/// (shared with [`super::conv_tiled`]).
pub(super) fn conv_grads(
    x: &Tensor,
    w: &Tensor,
    grad: &Tensor,
    op: &impl CustomOp3,
) -> Result<(Option<Tensor>, Option<Tensor>, Option<Tensor>)> {
    let (nx, nw, co) = (x.elem_count(), w.elem_count(), w.dim(0)?);
    let packed = x
        .contiguous()?
        .apply_op3_no_bwd(&w.contiguous()?, &grad.contiguous()?, op)?;
    let dx = packed.narrow(0, 0, nx)?.reshape(x.shape())?;
    let dw = packed.narrow(0, nx, nw)?.reshape(w.shape())?;
    let db = packed.narrow(0, nx + nw, co)?;
    Ok((Some(dx), Some(dw), Some(db)))
}

/// The weight and bias gradients from per-sample parts: `dw[o, j] = Σ_b dwt_parts[b][j, o]` and
/// `db[o] = Σ_b db_parts[b][o]` (f64 parts), summed in sample order (deterministic). The parts are summed in their
/// own `[j, o]` layout (contiguous, vectorised, rows of j in parallel), then transposed once. Shared with
/// [`super::conv_tiled`].
pub(super) fn sum_parts(dwt_parts: &[f32], db_parts: &[f64], dw: &mut [f32], db: &mut [f32]) {
    let (co, kk) = (db.len(), dw.len() / db.len().max(1));
    let n = kk * co;
    let mut dwt = dwt_parts[..n].to_vec();
    dwt.par_chunks_mut(co * 16)
        .enumerate()
        .for_each(|(i, acc)| {
            let (start, len) = (i * co * 16, acc.len());
            for part in dwt_parts.chunks(n).skip(1) {
                for (a, &v) in acc.iter_mut().zip(&part[start..start + len]) {
                    *a += v;
                }
            }
        });
    for (j, row) in dwt.chunks(co).enumerate() {
        for (o, &v) in row.iter().enumerate() {
            dw[o * kk + j] = v;
        }
    }
    for (o, v) in db.iter_mut().enumerate() {
        *v = db_parts.iter().skip(o).step_by(co).sum::<f64>() as f32;
    }
}

/// `Σ v` of f32 values in f64, over 8 interleaved partial sums (vectorised, fixed order).
pub(super) fn sum_f64(v: &[f32]) -> f64 {
    let mut acc = [0f64; 8];
    let chunks = v.chunks_exact(8);
    let rest = chunks.remainder();
    for c in chunks {
        for l in 0..8 {
            acc[l] += f64::from(c[l]);
        }
    }
    for (l, &x) in rest.iter().enumerate() {
        acc[l] += f64::from(x);
    }
    acc.iter().sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::kernels::sgemm::GemmBackend;
    use candle_core::{Device, Var};

    fn rand_t(shape: &[usize], seed: u64) -> Tensor {
        // Deterministic pseudo-random values in [-0.5, 0.5) (LCG), independent of candle's RNG.
        let mut s = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let v: Vec<f32> = (0..shape.iter().product::<usize>())
            .map(|_| {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                ((s >> 33) as f32 / (1u64 << 31) as f32) - 0.5
            })
            .collect();
        Tensor::from_vec(v, shape, &Device::Cpu).unwrap()
    }

    fn max_abs(a: &Tensor, b: &Tensor) -> f32 {
        (a - b)
            .unwrap()
            .abs()
            .unwrap()
            .flatten_all()
            .unwrap()
            .max(0)
            .unwrap()
            .to_scalar()
            .unwrap()
    }

    /// Channel ranges: whole panels, at least two per range, enough items for the threads, none when items abound.
    #[test]
    fn channel_chunks_cover_the_outputs_in_whole_panels() {
        assert_eq!(channel_chunk(1, 128, 8, 2), 32); // 16 × 16 at batch 1: 4 ranges
        assert_eq!(channel_chunk(3, 64, 8, 2), 32); // 32 × 32: 3 tiles × 2 ranges
        assert_eq!(channel_chunk(11, 32, 8, 2), 16); // 64 × 64: 22 items
        assert_eq!(channel_chunk(16, 128, 8, 2), 128); // enough items: no split
        assert_eq!(channel_chunk(1, 128, 8, 1), 128); // one thread
        assert_eq!(channel_chunk(1, 1, 1, 2), 1);
        for (items, co, align) in [(1, 40, 8), (3, 9, 1), (5, 200, 8), (1, 8, 8)] {
            let chunk = channel_chunk(items, co, align, 2);
            assert!(
                chunk.is_multiple_of(align) && chunk > 0 && chunk <= co.next_multiple_of(align)
            );
        }
    }

    /// The direct convolution on the portable GEMM loop (CPUs without AVX-512, and 1-row products) and on our
    /// AVX-512 kernels (listed as ignored on a CPU without them) against candle's `conv2d`, values and gradients.
    #[test]
    fn direct_conv_portable_gemm_matches_candle() {
        direct_conv_matches_candle(GemmBackend::GemmCrate);
    }

    #[test]
    #[cfg_attr(
        not(tnd_host_avx512),
        ignore = "this CPU has no AVX-512F: our AVX-512 kernels cannot run here"
    )]
    fn direct_conv_avx512_matches_candle() {
        assert!(GemmBackend::Avx512.is_available());
        direct_conv_matches_candle(GemmBackend::Avx512);
    }

    /// Also: a batch of one split into channel ranges (40 channels: a range ends inside a GEMM panel) and the
    /// weight packed once ("frozen") give the same bits as the whole and the per-call packing; a frozen packing of
    /// another shape is not used.
    fn direct_conv_matches_candle(backend: GemmBackend) {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .unwrap();
        pool.install(|| direct_conv_cases(backend));
    }

    fn direct_conv_cases(backend: GemmBackend) {
        for (i, &(b, ci, co, h, w, k)) in [
            (2, 3, 9, 6, 5, 3),
            (1, 8, 16, 12, 9, 1),
            (2, 4, 3, 5, 5, 5),
            (1, 6, 40, 7, 6, 3),
            // Widths of whole 16-lane vectors: the GEMM writes the output image directly (several row tiles
            // for the 70-row image).
            (2, 5, 19, 7, 16, 3),
            (1, 3, 12, 70, 32, 3),
            (1, 4, 9, 3, 48, 1),
        ]
        .iter()
        .enumerate()
        {
            let x = Var::from_tensor(&rand_t(&[b, ci, h, w], 40 + i as u64)).unwrap();
            let kw = Var::from_tensor(&rand_t(&[co, ci, k, k], 50 + i as u64)).unwrap();
            let bias = Var::from_tensor(&rand_t(&[co], 60 + i as u64)).unwrap();
            let r = rand_t(&[b, co, h, w], 70 + i as u64);
            let grads = |y: &Tensor| {
                let g = (y * &r).unwrap().sum_all().unwrap().backward().unwrap();
                [&x, &kw, &bias].map(|v| g.get(v).unwrap().clone())
            };
            let op = DirectConv {
                kernel: k,
                backend,
                frozen: None,
            };
            let ours = x
                .as_tensor()
                .apply_op3(kw.as_tensor(), bias.as_tensor(), op)
                .unwrap();
            let reference = x
                .as_tensor()
                .conv2d(kw.as_tensor(), k / 2, 1, 1, 1)
                .unwrap()
                .broadcast_add(&bias.as_tensor().reshape((1, co, 1, 1)).unwrap())
                .unwrap();
            let kk = ci * k * k;
            let wv = kw
                .as_tensor()
                .flatten_all()
                .unwrap()
                .to_vec1::<f32>()
                .unwrap();
            let run = |frozen: Option<Arc<PackedA>>| {
                let op = DirectConv {
                    kernel: k,
                    backend,
                    frozen,
                };
                let y = x.apply_op3(kw.as_tensor(), bias.as_tensor(), op).unwrap();
                y.flatten_all().unwrap().to_vec1::<f32>().unwrap()
            };
            let packed = PackedA::with_backend(backend, co, kk, &wv, kk, 1).unwrap();
            let want = ours.flatten_all().unwrap().to_vec1::<f32>().unwrap();
            assert_eq!(run(Some(Arc::new(packed))), want, "frozen, case {i}");
            // A packing of another shape (a stale one) is ignored, not misread.
            let other = PackedA::with_backend(backend, co, kk - 1, &wv, kk - 1, 1).unwrap();
            assert_eq!(run(Some(Arc::new(other))), want, "stale, case {i}");
            // One thread: no channel split.
            let one = rayon::ThreadPoolBuilder::new()
                .num_threads(1)
                .build()
                .unwrap();
            assert_eq!(one.install(|| run(None)), want, "one thread, case {i}");
            let (go, gr) = (grads(&ours), grads(&reference));
            for (what, a, b) in [
                ("forward", &reference, &ours),
                ("grad x", &gr[0], &go[0]),
                ("grad w", &gr[1], &go[1]),
                ("grad b", &gr[2], &go[2]),
            ] {
                let scale = max_abs(a, &a.zeros_like().unwrap()).max(1.0);
                let err = max_abs(a, b);
                assert!(err < 1e-5 * scale, "{what} case {i}: {err} (scale {scale})");
            }
        }
    }
}
