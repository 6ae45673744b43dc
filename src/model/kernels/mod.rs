//! # CPU kernels of the U-Net
//!
//! What makes the paper's model fast on a laptop CPU, kept apart from the model's paper files
//! ([`super::unet`], [`super::resnet`], …): single-precision GEMMs with our AVX-512 micro-kernels ([`sgemm`]), the
//! direct (implicit-GEMM) and cache-tiled im2col convolutions, fused multi-head attention ([`attention`]) (`conv_direct`, `conv_tiled`, chosen per model
//! by [`super::conv::ConvBackend`]), uninitialised output buffers for ops that write every element (`alloc`), and
//! the two half-batches of a step run side by side ([`parallel_batch`]). Each kernel is tested against candle's
//! own op (values and gradients); a test on a CPU without AVX-512 says that it tested the portable path only.
//!
//! Process-wide settings are explicit values ([`KernelSettings`]) that every front end (`tnd`, the workbench)
//! applies the same way at start-up; library code never sets environment variables.

pub(crate) mod alloc;
pub mod attention;
pub(crate) mod conv_direct;
pub(crate) mod conv_tiled;
pub mod parallel_batch;
pub mod sgemm;
pub(crate) mod simd;

use serde::{Deserialize, Serialize};

/// Geometry of one convolution: kernel size, stride and zero padding before/after (rows and columns alike).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ConvGeom {
    pub kernel: usize,
    pub stride: usize,
    pub pad_begin: usize,
    pub pad_end: usize,
}

impl ConvGeom {
    /// Output rows (or columns) of an input of `n`.
    pub fn out_size(&self, n: usize) -> usize {
        (n + self.pad_begin + self.pad_end - self.kernel) / self.stride + 1
    }
}

/// Which implementation of the network's custom operations a model runs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Kernels {
    /// Our fused CPU kernels (convolutions, GroupNorm + SiLU, attention, up-sampling).
    #[default]
    Fast,
    /// candle's own tensor ops, which run on every candle device (CUDA, Metal) and differentiate through autograd;
    /// on the CPU they check the fast kernels (`tests/model_unet.rs`).
    Portable,
}

/// How the model's CPU work is run, process-wide: one value shared by the CLI and the workbench.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default)]
pub struct KernelSettings {
    /// Threads for candle's own elementwise ops (candle reads `CANDLE_NUM_THREADS` once). 1 runs them on the
    /// calling thread: candle 0.11 splits large elementwise ops over a spin-waiting barrier pool, and on 2 cores
    /// shared with other jobs the main thread spent 12–20 % of a training step spinning for a descheduled worker
    /// (`perf`); measured back to back (`tnd bench unet`, batch-16 training step): 20.9 s → 13.4 s for the peer's
    /// 6.3 M-parameter config, 3.13 s → 1.40 s for the default model. Our convolutions, GroupNorm and GEMMs still
    /// use every core (rayon).
    pub elementwise_threads: usize,
    /// Keep freed memory in the heap for reuse (glibc `mallopt`; no-op elsewhere). Every candle op allocates its
    /// output and im2col buffers of a batch-16 64 × 64 step are 20–250 MB; glibc serves blocks above its mmap
    /// threshold with fresh `mmap`s and trims the heap on free, so each op pays page faults and page zeroing
    /// again — a third of the forward time in `perf`.
    pub keep_freed_memory: bool,
}

impl Default for KernelSettings {
    fn default() -> Self {
        Self {
            elementwise_threads: 1,
            keep_freed_memory: true,
        }
    }
}

impl KernelSettings {
    /// The environment variables a program sets for these settings at start-up, before it starts threads or runs
    /// any candle op (candle reads them once). A program keeps a variable its user already set.
    pub fn environment(&self) -> Vec<(&'static str, String)> {
        vec![(
            "CANDLE_NUM_THREADS",
            self.elementwise_threads.max(1).to_string(),
        )]
    }

    /// Apply the allocator policy (process-wide; call once at start-up of a program that runs the model).
    pub fn apply_allocator_policy(&self) {
        if self.keep_freed_memory {
            alloc::keep_freed_memory();
        }
    }
}
