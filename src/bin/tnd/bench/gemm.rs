//! `tnd bench gemm`: the three single-precision GEMM patterns of the tiled convolution (paper IV.B, speed on the
//! CPU) on one thread, for each backend (our AVX-512 kernels, the `gemm` crate), on the default U-Net's layer
//! shapes. One JSON line per (pattern, shape, backend) with the median time, GFLOP/s and the backend the product
//! really ran on (`ran_on`: dimensions below `SMALL_DIM` go to the gemm crate).

use anyhow::Result;
use clap::Args;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde_json::json;
use tactile_derender::model::kernels::sgemm::{matmul_nt, GemmBackend, Init, PackedA, SMALL_DIM};

use super::median_time;

#[derive(Args, Debug)]
pub struct GemmBenchArgs {
    /// Print JSON lines (the only output format).
    #[arg(long)]
    pub json: bool,
    /// Timed runs per measurement (median reported); each run repeats the product until ~20 ms of work.
    #[arg(long, default_value_t = 15)]
    pub runs: usize,
}

/// `(co, k, t, hw)` of the default model's convolutions at 64 × 64 that take the most time in a training step
/// (tile `t` = 131072 / k clamped to the image, as in `conv_tiled`), plus its first and last layers (`conv_in`,
/// and `conv_out` with one output channel).
const SHAPES: [(usize, usize, usize, usize); 9] = [
    (16, 18, 4096, 4096),
    (16, 144, 910, 4096),
    (16, 288, 455, 4096),
    (16, 432, 303, 4096),
    (32, 288, 455, 1024),
    (32, 864, 151, 1024),
    (64, 576, 227, 256),
    (64, 1152, 64, 64),
    (1, 144, 910, 4096),
];

fn random(rng: &mut ChaCha8Rng, n: usize) -> Vec<f32> {
    (0..n).map(|_| rng.random_range(-1.0f32..1.0)).collect()
}

pub fn run(a: &GemmBenchArgs) -> Result<()> {
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let mut backends = vec![GemmBackend::GemmCrate];
    if GemmBackend::Avx512.is_available() {
        backends.insert(0, GemmBackend::Avx512);
    }
    println!(
        "{}",
        json!({"bench": "info", "tool": "tnd", "host": super::host(), "detected": format!("{:?}", GemmBackend::detect()),
            "threads": 1})
    );
    for &(co, k, t, hw) in &SHAPES {
        let w = random(&mut rng, co * k);
        let cols = random(&mut rng, k * t);
        let dy = random(&mut rng, co * hw);
        let flops = 2.0 * (co * k * t) as f64;
        let reps = (2e7 / flops).ceil().max(1.0) as usize;
        for &backend in &backends {
            let pw = PackedA::with_backend(backend, co, k, &w, k, 1)?;
            let pwt = PackedA::with_backend(backend, k, co, &w, 1, k)?;
            let mut y = vec![0f32; co * hw];
            let mut dw = vec![0f32; co * k];
            let mut dcols = vec![0f32; k * t];
            let mut err = None;
            let mut time = |f: &mut dyn FnMut() -> candle_core::Result<()>| {
                let s = median_time(2, a.runs, || {
                    for _ in 0..reps {
                        if let Err(e) = f() {
                            err = Some(e);
                        }
                    }
                });
                s / reps as f64
            };
            let forward = time(&mut || pw.matmul(t, &cols, t, &mut y, hw, Init::Accumulate));
            // dWᵀ[k, co] += cols[k, t] · dY[co, t]ᵀ (the convolution's orientation).
            let weight_grad =
                time(&mut || matmul_nt(backend, (k, co, t), &cols, t, &dy, hw, &mut dw, co, true));
            let input_grad = time(&mut || pwt.matmul(t, &dy, hw, &mut dcols, t, Init::Zero));
            if let Some(e) = err {
                return Err(e.into());
            }
            // The backend each product really ran on (small dimensions go to the gemm crate).
            let nt_backend = if co < SMALL_DIM {
                GemmBackend::GemmCrate
            } else {
                backend
            };
            for (pattern, s, ran_on) in [
                ("forward W·cols", forward, pw.backend()),
                ("weight_grad cols·dYT", weight_grad, nt_backend),
                ("input_grad WT·dY", input_grad, pwt.backend()),
            ] {
                println!(
                    "{}",
                    json!({"bench": "sgemm", "pattern": pattern, "backend": format!("{backend:?}"),
                        "ran_on": format!("{ran_on:?}"),
                        "co": co, "k": k, "t": t, "median_s": s, "gflops": flops / s / 1e9,
                        "runs": a.runs})
                );
            }
        }
    }
    Ok(())
}
