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
