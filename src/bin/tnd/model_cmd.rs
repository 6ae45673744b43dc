//! `tnd model verify`: run a reference input through a checkpoint and compare with the reference output (the peer
//! script's `*_io.safetensors` layout: `input`, `timesteps`, `output`), to check an imported diffusers checkpoint.

use std::path::PathBuf;

use anyhow::{anyhow, bail, Context, Result};
use candle_core::DType;
use clap::{Args, Subcommand};
use serde_json::json;
use tactile_derender::model::checkpoint::read_tensors;
use tactile_derender::model::DiffusionModel;

#[derive(Args, Debug)]
pub struct ModelArgs {
    #[command(subcommand)]
    pub command: ModelCommand,
}

#[derive(Subcommand, Debug)]
pub enum ModelCommand {
    /// Print {"max_abs_diff": ..} of the model's output against a reference input/output file.
    Verify(VerifyArgs),
}

#[derive(Args, Debug)]
pub struct VerifyArgs {
    /// Checkpoint: our .safetensors, a diffusers save_pretrained directory, or weights + <stem>_config.json.
    #[arg(long)]
    pub model: PathBuf,
    /// Reference file with tensors `input` [B, in, H, W], `timesteps` [B] and `output` [B, out, H, W].
    #[arg(long)]
    pub io: PathBuf,
    /// Fail (exit status 1) when the difference exceeds this.
    #[arg(long)]
    pub tol: Option<f32>,
}

pub fn run(a: ModelArgs) -> Result<()> {
    match a.command {
        ModelCommand::Verify(v) => verify(&v),
    }
}

fn verify(a: &VerifyArgs) -> Result<()> {
    let model = DiffusionModel::load(&a.model)?;
    let io = read_tensors(&a.io)?;
    let get = |k: &str| {
        io.tensors.get(k).ok_or_else(|| {
            anyhow!(
                "{}: no tensor '{k}' (need input, timesteps, output)",
                a.io.display()
            )
        })
    };
    let input = get("input")?;
    let expected = get("output")?;
    let t: Vec<f32> = get("timesteps")?
        .to_dtype(DType::F32)?
        .flatten_all()?
        .to_vec1()?;
    let out = model.unet().forward(input, &t).with_context(|| {
        format!(
            "{}: running the model on {}",
            a.model.display(),
            a.io.display()
        )
    })?;
    if out.dims() != expected.dims() {
        bail!(
            "{}: output has shape {:?}, the reference {:?}",
            a.io.display(),
            out.dims(),
            expected.dims()
        );
    }
    let d: f32 = (out - expected)?
        .abs()?
        .flatten_all()?
        .max(0)?
        .to_scalar()?;
    println!(
        "{}",
        json!({"max_abs_diff": d, "model": a.model, "io": a.io})
    );
    if let Some(tol) = a.tol {
        if !(d <= tol) {
            bail!("max |Δ| {d} exceeds the tolerance {tol}");
        }
    }
    Ok(())
}
