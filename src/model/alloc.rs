//! Allocator tuning for the U-Net on the CPU (paper IV.B, speed). Every candle op allocates its output; im2col
//! buffers of a batch-16 64 × 64 step are 20–250 MB. glibc serves blocks above its mmap threshold (at most 32 MB) with
//! fresh `mmap`s and trims the heap on free, so each op pays page faults and page zeroing again — a third of the
//! forward time in `perf`. Keeping freed memory in the heap removes that.

/// Tell glibc malloc to serve large blocks from the heap and keep freed memory for reuse (process-wide; call once at
/// start-up of a program that runs the model). No-op on other platforms.
pub fn keep_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only changes allocator parameters; it is safe to call at any time.
    unsafe {
        libc::mallopt(libc::M_MMAP_MAX, 0);
        libc::mallopt(libc::M_TRIM_THRESHOLD, i32::MAX);
        libc::mallopt(libc::M_TOP_PAD, 64 << 20);
    }
}

/// Run candle's elementwise ops on the calling thread unless `CANDLE_NUM_THREADS` is set. candle 0.11 splits large
/// elementwise ops over a spin-waiting barrier pool; on this 2-core machine shared with other jobs the main thread spent
/// 12–20 % of a training step spinning for a descheduled worker (`perf`). Measured back to back (`tnd bench unet`,
/// batch-16 training step): 20.9 s → 13.4 s for the peer's 6.3 M-parameter config, 3.13 s → 1.40 s for the default
/// model. Our convolution and GroupNorm ops and the GEMMs still use both cores (rayon). Call before any candle op.
pub fn prefer_inline_elementwise() {
    if std::env::var_os("CANDLE_NUM_THREADS").is_none() {
        std::env::set_var("CANDLE_NUM_THREADS", "1");
    }
}

/// `n` floats for an op's output that the op writes completely before anything reads it. `vec![0.0; n]` zeroes it
/// first: a serial memset on the calling (main) thread, 4–8 MB per output at batch 16, that the op's parallel
/// workers then overwrite.
///
/// # Safety
/// The caller writes every element before reading any of them and before the vector leaves the op.
#[allow(clippy::uninit_vec)]
pub(crate) unsafe fn output_vec(n: usize) -> Vec<f32> {
    let mut v = Vec::with_capacity(n);
    // SAFETY: capacity n; f32 has no invalid bit patterns and the caller writes every element before reading.
    unsafe { v.set_len(n) };
    v
}
