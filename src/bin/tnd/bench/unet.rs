//! `tnd bench unet`: U-Net forward (batch 1 and 16) and one Adam training step (batch 16) for the architecture of
//! `../shared/peers/unet_torch.py` (same default config; `--config` takes the same JSON object or file merged over
//! it), printing records shaped like the peer's (`unet_forward`, `unet_train_step`). Run the peer right before or
//! after: these machines drift, so only figures taken together compare.

use std::path::Path;

use anyhow::{anyhow, Context, Result};
use candle_core::{Device, Tensor};
use clap::Args;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use serde_json::{json, Value};
use tactile_derender::model::adam::Adam;
use tactile_derender::model::checkpoint::{build, named_vars};
use tactile_derender::model::conv::ConvBackend;
use tactile_derender::model::init::init_params;
use tactile_derender::model::kernels::parallel_batch;
use tactile_derender::model::{NoiseSchedule, UNet2DConfig};

use super::median_time;

#[derive(Args, Debug)]
pub struct UnetBenchArgs {
    /// Print JSON lines (the only output format).
    #[arg(long)]
    pub json: bool,
    /// JSON object or JSON file merged over the peer script's default config.
    #[arg(long)]
    pub config: Option<String>,
    /// Timed forward runs per batch size (median reported).
    #[arg(long, default_value_t = 20)]
    pub runs: usize,
    /// Timed training steps.
    #[arg(long, default_value_t = 10)]
    pub train_runs: usize,
    /// Untimed warm-up runs.
    #[arg(long, default_value_t = 3)]
    pub warmup: usize,
    /// Forward batch sizes.
    #[arg(long, value_parser = crate::args::at_most::<4096>, value_delimiter = ',', default_value = "1,16")]
    pub batches: Vec<usize>,
    /// Training batch size.
    #[arg(long, value_parser = crate::args::at_most::<1024>, default_value_t = 16)]
    pub train_batch: usize,
    /// Convolution implementation: direct (ours, default; tiled where the geometry or CPU needs it), tiled (ours,
    /// im2col tiles), im2col (ours, full buffer) or candle.
    #[arg(long, default_value = "direct")]
    pub conv: String,
    /// Parts to skip: forward, train.
    #[arg(long, value_delimiter = ',')]
    pub skip: Vec<String>,
    /// Time the forward passes with the convolution weights packed on every call, as training does, instead of
    /// once, as a loaded model does (`tnd sample`, `tnd eval`, the workbench).
    #[arg(long)]
    pub pack_per_call: bool,
}

/// The peer script's `DEFAULT_CONFIG` (diffusers defaults elsewhere, e.g. `attention_head_dim` 8).
fn peer_default() -> Value {
    json!({
        "sample_size": 64, "in_channels": 2, "out_channels": 1,
        "block_out_channels": [32, 64, 128, 128], "layers_per_block": 2,
        "down_block_types": ["DownBlock2D", "DownBlock2D", "AttnDownBlock2D", "DownBlock2D"],
        "up_block_types": ["UpBlock2D", "AttnUpBlock2D", "UpBlock2D", "UpBlock2D"],
        "norm_num_groups": 8, "attention_head_dim": 8, "mid_block_type": "UNetMidBlock2D"
    })
}

/// The peer default with `arg` (a JSON object or a path to one) merged over it.
pub fn peer_config(arg: Option<&str>) -> Result<UNet2DConfig> {
    let mut cfg = peer_default();
    if let Some(a) = arg {
        let text = if Path::new(a).is_file() {
            std::fs::read_to_string(a).with_context(|| a.to_string())?
        } else {
            a.to_string()
        };
        let over: Value = serde_json::from_str(&text).with_context(|| format!("--config {a}"))?;
        let (Some(base), Some(over)) = (cfg.as_object_mut(), over.as_object()) else {
            return Err(anyhow!("--config must be a JSON object"));
        };
        for (k, v) in over {
            base.insert(k.clone(), v.clone());
        }
    }
    Ok(UNet2DConfig::from_json(&cfg.to_string(), "--config")?)
}

fn randn(rng: &mut ChaCha8Rng, shape: (usize, usize, usize, usize)) -> Result<Tensor> {
    let n = shape.0 * shape.1 * shape.2 * shape.3;
    let v: Vec<f32> = (0..n).map(|_| rng.sample(StandardNormal)).collect();
    Ok(Tensor::from_vec(v, shape, &Device::Cpu)?)
}

pub fn run(a: &UnetBenchArgs) -> Result<()> {
    let backend = match a.conv.as_str() {
        "candle" => ConvBackend::Candle,
        "im2col" => ConvBackend::Im2colGemm,
        "tiled" => ConvBackend::Tiled,
        "direct" => ConvBackend::Direct,
        other => {
            return Err(anyhow!(
                "--conv must be direct, tiled, im2col or candle, not '{other}'"
            ))
        }
    };
    let cfg = peer_config(a.config.as_deref())?;
    let mut vars = build(&cfg, &Device::Cpu)?;
    vars.unet.set_conv_backend(backend);
    init_params(&vars.varmap, 0)?;
    let params: usize = named_vars(&vars.varmap)
        .values()
        .map(|v| v.elem_count())
        .sum();
    let loadavg = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    println!(
        "{}",
        json!({"bench": "info", "tool": "tnd", "host": super::host(), "conv": a.conv, "params": params,
            "gflops_per_sample_forward": vars.unet.flops_per_sample() / 1e9,
            "threads": rayon::current_num_threads(), "loadavg": loadavg.trim(),
            "config": serde_json::from_str::<Value>(&cfg.to_json()?)?})
    );
    let (s, cin, cout) = (cfg.sample_size, cfg.in_channels, cfg.out_channels);
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let t_max = cfg.tactile_derender.num_train_timesteps;
    if !a.skip.iter().any(|x| x == "forward") {
        if !a.pack_per_call {
            vars.unet.freeze()?;
        }
        for &b in &a.batches {
            let x = randn(&mut rng, (b, cin, s, s))?;
            let t: Vec<f32> = (0..b).map(|_| rng.random_range(0..t_max) as f32).collect();
            let mut err = None;
            let median_s = median_time(a.warmup, a.runs, || {
                if let Err(e) = vars.unet.forward(&x, &t) {
                    err = Some(e);
                }
            });
            if let Some(e) = err {
                return Err(e.into());
            }
            println!(
                "{}",
                json!({"bench": "unet_forward", "batch": b, "median_s": median_s,
                    "weights_packed": if a.pack_per_call { "per call" } else { "once" },
                    "samples_per_s": b as f64 / median_s, "runs": a.runs})
            );
        }
    }
    if !a.skip.iter().any(|x| x == "train") {
        // The weights change every step.
        vars.unet.thaw();
        let b = a.train_batch;
        let schedule = NoiseSchedule::cosine(t_max);
        let mut adam = Adam::new(named_vars(&vars.varmap).into_iter().collect(), 1e-4)?;
        let x0 = randn(&mut rng, (b, cout, s, s))?;
        let cond = randn(&mut rng, (b, cin - cout, s, s))?;
        let mut step = || -> Result<f32> {
            let noise = randn(&mut rng, (b, cout, s, s))?;
            let t: Vec<usize> = (0..b).map(|_| rng.random_range(0..t_max)).collect();
            let xt = schedule.add_noise(&x0, &noise, &t)?;
            let tf: Vec<f32> = t.iter().map(|&t| t as f32).collect();
            let input = Tensor::cat(&[&xt, &cond], 1)?;
            // As `tnd train` does: the two half-batches side by side, gradients summed.
            let (loss, grads) = parallel_batch::loss_and_grads(b, |r| {
                let pred = vars.unet.forward_t(
                    &input.narrow(0, r.start, r.len())?,
                    &tf[r.clone()],
                    true,
                )?;
                (pred - noise.narrow(0, r.start, r.len())?)?
                    .sqr()?
                    .mean_all()
            })?;
            adam.step(&grads)?;
            Ok(loss)
        };
        let mut err = None;
        let median_s = median_time(a.warmup.min(2), a.train_runs, || {
            if let Err(e) = step() {
                err = Some(e);
            }
        });
        if let Some(e) = err {
            return Err(e);
        }
        println!(
            "{}",
            json!({"bench": "unet_train_step", "batch": b, "optimizer": "Adam", "loss": "mse",
                "median_s": median_s, "samples_per_s": b as f64 / median_s, "runs": a.train_runs})
        );
    }
    Ok(())
}
