//! `tnd model verify`: run a reference input through a checkpoint and compare with the reference output (the peer
//! script's `*_io.safetensors` layout: `input`, `timesteps`, `output`), to check an imported diffusers checkpoint.
//! `tnd model diagnose`: the one-step x0 quality of a checkpoint per diffusion timestep on dataset pairs.
//! `tnd model export --diffusers DIR` / `tnd model import --diffusers DIR`: diffusers folders out and in.

use std::path::PathBuf;

use anyhow::{anyhow, bail, Context, Result};
use candle_core::DType;
use clap::{Args, Subcommand};
use serde_json::json;
use tactile_derender::dataset::{Dataset, SplitName};
use tactile_derender::model::checkpoint::{read_tensors, save_model};
use tactile_derender::model::diagnose::x0_quality;
use tactile_derender::model::diffusers_folder;
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
    /// One JSON line per timestep: how well the model recovers X0 from one noised copy of the truth (ε and x0
    /// errors, background marked as contact, contact missed) on the first pairs of a dataset split.
    Diagnose(DiagnoseArgs),
    /// Write a checkpoint as a diffusers folder: `UNet2DModel.from_pretrained(DIR)` and
    /// `DDIMScheduler.from_pretrained(DIR)` open it (config.json, diffusion_pytorch_model.safetensors,
    /// scheduler_config.json, README.md).
    Export(ExportArgs),
    /// Turn a diffusers folder (`save_pretrained`, or one written by `tnd model export`) into one .safetensors file
    /// with the config inside (every `--model` option also reads the folder directly).
    Import(ImportArgs),
}

#[derive(Args, Debug)]
pub struct ExportArgs {
    /// Checkpoint to export (default: the bundled model; `small`: the bundled small one, twice as fast).
    #[arg(long, default_value = "default")]
    pub model: PathBuf,
    /// The diffusers folder to write (created if missing).
    #[arg(long)]
    pub diffusers: PathBuf,
    /// Replace the model a folder already holds (otherwise refused: it may be another model's only copy), or write
    /// into a folder that holds files tnd did not write (they are kept; the export stops rather than replace one).
    #[arg(long)]
    pub force: bool,
}

#[derive(Args, Debug)]
pub struct ImportArgs {
    /// The diffusers folder to read.
    #[arg(long)]
    pub diffusers: PathBuf,
    /// The .safetensors file to write (an existing file is replaced only if tnd wrote it, or with --force).
    #[arg(long)]
    pub out: PathBuf,
    #[command(flatten)]
    pub force: crate::args::ForceArg,
}

#[derive(Args, Debug)]
pub struct DiagnoseArgs {
    /// Checkpoint (default: the bundled model; `small`: the bundled small one, twice as fast).
    #[arg(long, default_value = "default")]
    pub model: PathBuf,
    /// Dataset directory.
    #[arg(long)]
    pub data: PathBuf,
    /// train, unseen_poses or unseen_objects.
    #[arg(long, default_value = "unseen_poses")]
    pub split: String,
    /// Pairs (the first of the split).
    #[arg(long, default_value_t = 32)]
    pub pairs: usize,
    /// Timesteps, comma-separated.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "5,25,50,100,150,200,225,240,249"
    )]
    pub timesteps: Vec<usize>,
    /// Seed of the noise.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
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
        ModelCommand::Diagnose(d) => diagnose(&d),
        ModelCommand::Export(e) => {
            let _out = crate::outputs::folder("--diffusers", &e.diffusers, e.force, &[&e.model])?;
            let held = e.diffusers.join("diffusion_pytorch_model.safetensors");
            if held.exists() && !e.force {
                bail!(
                    "{}: already holds a model; export into a new folder, or --force to replace it",
                    e.diffusers.display()
                );
            }
            let model = DiffusionModel::load(&e.model)?;
            let files = diffusers_folder::export(&model, &e.diffusers)?;
            println!(
                "{}",
                json!({"model": crate::path_json(&e.model), "diffusers": crate::path_json(&e.diffusers),
                    "files": files.iter().map(crate::path_json).collect::<Vec<_>>()})
            );
            Ok(())
        }
        ModelCommand::Import(i) => {
            let out = crate::outputs::file(
                "--out",
                &i.out,
                i.force.force,
                &[&i.diffusers],
                &tactile_derender::model::checkpoint::written_by_tnd,
            )?;
            let model = DiffusionModel::load(&i.diffusers)?;
            save_model(
                out.path(),
                &model.vars().varmap,
                model.config(),
                Default::default(),
            )?;
            println!(
                "{}",
                json!({"diffusers": crate::path_json(&i.diffusers), "out": crate::path_json(&i.out)})
            );
            Ok(())
        }
    }
}

fn diagnose(a: &DiagnoseArgs) -> Result<()> {
    let model = DiffusionModel::load(&a.model)?;
    let dataset = Dataset::open(&a.data)?;
    let split: SplitName = a.split.parse().map_err(|e| anyhow!("--split: {e}"))?;
    let n = a.pairs.min(dataset.len(split));
    if n == 0 {
        bail!("{}: split {split} has no pairs", a.data.display());
    }
    let pairs = (0..n)
        .map(|i| dataset.pair(split, i).map(|p| (p.imprint, p.target)))
        .collect::<Result<Vec<_>, _>>()?;
    for q in x0_quality(&model, &pairs, &a.timesteps, a.seed)? {
        println!("{}", serde_json::to_string(&q)?);
    }
    Ok(())
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
        json!({"max_abs_diff": d, "model": crate::path_json(&a.model), "io": crate::path_json(&a.io)})
    );
    if let Some(tol) = a.tol {
        if d.is_nan() || d > tol {
            bail!("max |Δ| {d} exceeds the tolerance {tol}");
        }
    }
    Ok(())
}
