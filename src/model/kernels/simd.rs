//! Helpers every CPU kernel shares: the contiguous `f32` view of a candle storage, a vectorisable `exp`, and the
//! CPU's SIMD level.

use candle_core::{CpuStorage, Layout};

/// The `f32` data of a contiguous CPU tensor, for our custom ops; `what` ("conv: weight") names it in the error.
pub(crate) fn contiguous_f32<'a>(
    storage: &'a CpuStorage,
    layout: &Layout,
    what: &str,
) -> candle_core::Result<&'a [f32]> {
    match layout.contiguous_offsets() {
        Some((start, end)) => Ok(&storage.as_slice::<f32>()?[start..end]),
        None => candle_core::bail!("{what} must be contiguous"),
    }
}

/// `exp(x)` for f32 without a library call, so that loops using it vectorise: Cody–Waite range reduction
/// `x = n ln2 + r` and a degree-7 Taylor polynomial on |r| ≤ ln2/2 (truncation ≤ 5e-9; the result is within f32
/// rounding of `f32::exp`).
#[inline(always)]
pub(crate) fn exp_f32(x: f32) -> f32 {
    let x = x.clamp(-87.0, 88.0);
    // Round x/ln2 to the nearest integer with the 1.5·2²³ trick (branch-free, vectorises without SSE4.1): t's
    // mantissa then holds n itself, read back as integer bits below (a float-to-int `as` cast is saturating
    // and NaN-checked in Rust, which LLVM does lane by lane: a third of the GroupNorm forward in `perf`).
    let t = x * std::f32::consts::LOG2_E + 12_582_912.0;
    let n = t - 12_582_912.0;
    let n_int = t.to_bits().wrapping_sub(0x4B40_0000); // n as two's complement, |n| ≤ 127
    let r = x - n * 0.693_145_75 - n * 1.428_606_8e-6;
    let p = 1.0
        + r * (1.0
            + r * (0.5
                + r * (1.0 / 6.0
                    + r * (1.0 / 24.0
                        + r * (1.0 / 120.0 + r * (1.0 / 720.0 + r * (1.0 / 5040.0)))))));
    p * f32::from_bits(n_int.wrapping_add(127) << 23)
}

/// The fastest build of the kernels (GroupNorm, attention) this CPU runs: 2 = AVX-512, 1 = AVX2 + FMA, 0 = portable.
pub(crate) fn simd_level() -> u8 {
    #[cfg(target_arch = "x86_64")]
    {
        if is_x86_feature_detected!("avx512f") && is_x86_feature_detected!("avx512vl") && has_avx2()
        {
            return 2;
        }
    }
    u8::from(has_avx2())
}

fn has_avx2() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}
