//! `tnd train`: pre-train the conditional DDPM on a dataset, or fine-tune from `--init` (paper IV.B, V.B). Running
//! the same command again resumes from the run directory's last checkpoint (also after kill -9).

use std::path::PathBuf;

use anyhow::{anyhow, bail, Context, Result};
use clap::Args;
use kdam::BarExt;
use serde_json::json;
use tactile_derender::dataset::Dataset;
use tactile_derender::model::train::{train, TrainConfig};
use tactile_derender::model::train_data::DatasetTraining;
use tactile_derender::model::UNet2DConfig;

#[derive(Args, Debug)]
pub struct TrainArgs {
    /// Dataset directory (`tnd dataset gen` / `import`); trains on its train split.
    #[arg(long)]
    pub data: PathBuf,
    /// Run directory: train_state.safetensors, model.safetensors, log.jsonl.
    #[arg(long)]
    pub out: PathBuf,
    /// Fine-tune from this checkpoint (architecture and normalisation come from it).
    #[arg(long)]
    pub init: Option<PathBuf>,
    /// Architecture for training from scratch: a UNet2DModel config JSON object or file (default: the shipped one).
    #[arg(long)]
    pub config: Option<String>,
    #[command(flatten)]
    pub train: TrainConfig,
    /// A separate validation dataset (e.g. `tnd dataset gen` with another seed and object set): the logged
    /// validation loss uses a fixed draw of its pairs instead of the training dataset's unseen_poses test split, so
    /// that stopping and tuning never look at test pairs.
    #[arg(long)]
    pub val_data: Option<PathBuf>,
}

fn model_config(a: &TrainArgs, resolution: (usize, usize)) -> Result<UNet2DConfig> {
    let mut cfg = match &a.config {
        None => UNet2DConfig::default(),
        Some(c) => {
            let text = if std::path::Path::new(c).is_file() {
                std::fs::read_to_string(c).with_context(|| c.clone())?
            } else {
                c.clone()
            };
            UNet2DConfig::from_json(&text, "--config")?
        }
    };
    if resolution.0 != resolution.1 {
        bail!(
            "the dataset's images are {}x{}; the model needs square images",
            resolution.0,
            resolution.1
        );
    }
    cfg.sample_size = resolution.0;
    cfg.validate("--config")?;
    Ok(cfg)
}

pub fn run(a: TrainArgs) -> Result<()> {
    let dataset = Dataset::open(&a.data)?;
    let cfg = model_config(&a, dataset.resolution())?;
    let tc = a.train.clone();
    if let Some(d) = tc.ema {
        if !(0.0..1.0).contains(&d) {
            return Err(anyhow!("--ema must be in [0, 1), found {d}"));
        }
    }
    let val_dataset = a.val_data.as_deref().map(Dataset::open).transpose()?;
    if let Some(v) = &val_dataset {
        if v.resolution() != dataset.resolution() {
            bail!(
                "--val-data {}: images are {:?}, the training data's {:?}",
                a.val_data
                    .as_deref()
                    .unwrap_or(std::path::Path::new(""))
                    .display(),
                v.resolution(),
                dataset.resolution()
            );
        }
    }
    let mut data = DatasetTraining::new(&dataset);
    if let Some(v) = &val_dataset {
        data = data.with_validation(v);
    }
    let mut bar = super::progress::bar("training", " steps", 0);
    let summary = train(&a.out, &tc, &cfg, a.init.as_deref(), &mut data, &mut |p| {
        bar.total = p.total as usize;
        bar.set_postfix(format!(
            "loss={:.4}, {:.1} samples/s",
            p.loss, p.samples_per_s
        ));
        let _ = bar.update_to(p.step as usize);
        true
    })
    .with_context(|| format!("training in {}", a.out.display()))?;
    super::progress::finish(&mut bar);
    println!(
        "{}",
        json!({"steps": summary.steps, "resumed_from": summary.resumed_from, "last_loss": summary.last_loss,
            "model": summary.model_path})
    );
    Ok(())
}
