//! Memory for the kernels: the allocator policy behind [`super::KernelSettings::keep_freed_memory`] and
//! uninitialised output buffers for ops that write every element.

/// Tell glibc malloc to serve large blocks from the heap and keep freed memory for reuse (process-wide; call once at
/// start-up of a program that runs the model). No-op on other platforms.
pub(crate) fn keep_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only changes allocator parameters; it is safe to call at any time.
    unsafe {
        libc::mallopt(libc::M_MMAP_MAX, 0);
        libc::mallopt(libc::M_TRIM_THRESHOLD, i32::MAX);
        libc::mallopt(libc::M_TOP_PAD, 64 << 20);
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
    // SAFETY: capacity n. The elements are uninitialised until the op writes them through `&mut [f32]`; nothing
    // reads one before it is written (the caller's contract), f32 has no invalid bit patterns and no drop, so no
    // uninitialised value is ever observed (Miri accepts the pattern: writing through a reference to uninitialised
    // floats is not undefined behaviour under the current unsafe-code guidelines, reading would be).
    unsafe { v.set_len(n) };
    v
}
