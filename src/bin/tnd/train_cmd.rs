//! `tnd train`: pre-train the conditional DDPM on a dataset, or fine-tune from `--init` (paper IV.B, V.B). Running
//! the same command again resumes from the run directory's last checkpoint (also after kill -9); Ctrl-C or SIGTERM
//! stop it after the step under way with a fresh checkpoint.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};

use anyhow::{anyhow, bail, Context, Result};
use clap::Args;
use kdam::BarExt;
use serde_json::json;
use tactile_derender::dataset::stats::target_range_sample;
use tactile_derender::dataset::{Dataset, SplitName};
use tactile_derender::model::train::{train, TrainConfig};
use tactile_derender::model::train_data::DatasetTraining;
use tactile_derender::model::UNet2DConfig;

/// Set by SIGINT or SIGTERM: the run stops after its current step and writes a checkpoint.
static STOP: AtomicBool = AtomicBool::new(false);

#[cfg(unix)]
extern "C" fn on_stop_signal(signal: libc::c_int) {
    STOP.store(true, Ordering::Relaxed);
    // A second Ctrl-C stops at once (both calls are async-signal-safe).
    // SAFETY: restoring the default disposition of the signal being handled.
    unsafe {
        libc::signal(signal, libc::SIG_DFL);
    }
}

/// Ctrl-C or `kill` (SIGINT, SIGTERM) stop training at the end of the step under way, with a checkpoint, instead of
/// losing up to a checkpoint interval of work.
fn stop_on_signals() {
    #[cfg(unix)]
    for signal in [libc::SIGINT, libc::SIGTERM] {
        // SAFETY: installs a handler that only stores to an atomic and resets its own disposition.
        unsafe {
            libc::signal(signal, on_stop_signal as *const () as libc::sighandler_t);
        }
    }
}

#[derive(Args, Debug)]
pub struct TrainArgs {
    /// Dataset directory (`tnd dataset gen` / `import`); trains on its train split. Several (`--data A B` or
    /// `--data A --data B`: e.g. one sensor's recordings, each imported on its own) train as one dataset.
    #[arg(long, required = true, num_args = 1..)]
    pub data: Vec<PathBuf>,
    /// Run directory: train_state.safetensors, model.safetensors, log.jsonl.
    #[arg(long)]
    pub out: PathBuf,
    #[command(flatten)]
    pub force: crate::args::ForceArg,
    /// Fine-tune from this checkpoint (architecture and normalisation come from it).
    #[arg(long)]
    pub init: Option<PathBuf>,
    /// Architecture for training from scratch: a UNet2DModel config JSON object or file (default: the bundled default
    /// model's, a v-prediction U-Net of 2.7 M parameters; `small`: the bundled small model's).
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

/// The run's inputs besides its settings (the data and the starting point) in `OUT/run_inputs.json`: a resume with
/// other ones is refused (it would continue the old run on new data), and the user is told whether the run starts
/// or resumes.
fn check_run_inputs(a: &TrainArgs) -> Result<()> {
    let path = a.out.join("run_inputs.json");
    let canonical = |p: &std::path::Path| {
        std::fs::canonicalize(p)
            .unwrap_or_else(|_| p.to_path_buf())
            .display()
            .to_string()
    };
    // One dataset is stored as its path (as runs before several were possible), several as a list.
    let data = match a.data.as_slice() {
        [one] => json!(canonical(one)),
        many => json!(many.iter().map(|p| canonical(p)).collect::<Vec<_>>()),
    };
    let now = json!({
        "data": data,
        "init": a.init.as_deref().map(|p| if p.exists() { canonical(p) } else { p.display().to_string() }),
    });
    let resuming = a.out.join("train_state.safetensors").is_file();
    if resuming {
        if let Ok(text) = std::fs::read_to_string(&path) {
            let saved: serde_json::Value = serde_json::from_str(&text)
                .map_err(|e| anyhow!("{}: not JSON: {e}", path.display()))?;
            for key in ["data", "init"] {
                if saved[key] != now[key] {
                    let shown = |v: &serde_json::Value| match v {
                        serde_json::Value::Null => format!("no --{key}"),
                        v => format!("--{key} {v}"),
                    };
                    bail!(
                        "{}: this run was started with {}, not {}; resume with it or use a new --out",
                        a.out.display(),
                        shown(&saved[key]),
                        shown(&now[key])
                    );
                }
            }
        }
        eprintln!(
            "{}: resuming the run from its last checkpoint",
            a.out.display()
        );
    } else {
        eprintln!(
            "{}: no checkpoint there, starting a new run",
            a.out.display()
        );
    }
    std::fs::create_dir_all(&a.out)
        .map_err(|e| anyhow!("{}: cannot create: {e}", a.out.display()))?;
    tactile_derender::io::write_atomic(&path, format!("{now}\n").as_bytes())
        .map_err(|e| anyhow!("{}: cannot write: {e}", path.display()))?;
    Ok(())
}

/// The architecture to train: the bundled default's, the small one's, or a `--config` file or inline JSON, checked
/// before any data is read; `true` when it states its own `tactile_derender` mapping.
fn given_config(a: &TrainArgs) -> Result<(UNet2DConfig, bool)> {
    Ok(match a.config.as_deref() {
        None => (
            tactile_derender::model::checkpoint::locate(std::path::Path::new("default"))?.1,
            false,
        ),
        Some("small") => (
            tactile_derender::model::checkpoint::locate(std::path::Path::new("small"))?.1,
            false,
        ),
        Some(c) => {
            let (text, source) = if std::path::Path::new(c).is_file() {
                let text = std::fs::read_to_string(c).with_context(|| c.to_string())?;
                (text, c.to_string())
            } else {
                (c.to_string(), "--config (inline JSON)".to_string())
            };
            let cfg = UNet2DConfig::from_json(&text, &source)?;
            let states_mapping = serde_json::from_str::<serde_json::Value>(&text)
                .is_ok_and(|v| v.get("tactile_derender").is_some());
            (cfg, states_mapping)
        }
    })
}

fn model_config(mut cfg: UNet2DConfig, resolution: (usize, usize)) -> Result<UNet2DConfig> {
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

/// A new run's model config checked against the data's in-contact depths (sampled from the train split): a
/// fine-tune (`--init`) or a `--config` that sets its own `tactile_derender` mapping must already hold them (else the
/// run is refused, saying why); otherwise the mapping is fitted to them, as the default's is to the default sensor,
/// so that a sensor with shallower or deeper contact does not train a model whose every sample decodes as no contact.
fn fit_to_data(
    a: &TrainArgs,
    datasets: &[Dataset],
    cfg: UNet2DConfig,
    states_mapping: bool,
) -> Result<UNet2DConfig> {
    let mut range: Option<[f32; 2]> = None;
    for ds in datasets {
        if let Some([lo, hi]) = target_range_sample(ds, SplitName::Train, 256)? {
            range = Some(range.map_or([lo, hi], |[l, h]| [l.min(lo), h.max(hi)]));
        }
    }
    let Some([lo, hi]) = range else {
        return Ok(cfg);
    };
    let data = shown_data(a);
    if let Some(init) = &a.init {
        let (_, init_cfg) = tactile_derender::model::checkpoint::locate(init)?;
        if let Some(problem) = init_cfg.tactile_derender.contact_range_problem(lo, hi) {
            bail!(
                "{}: the model of --init {} does not fit this sensor: {problem}; a fine-tune keeps its model's \
                 mapping, so train for this sensor from scratch (without --init, tnd train fits the mapping to the data)",
                data,
                init.display()
            );
        }
        return Ok(cfg);
    }
    let Some(problem) = cfg.tactile_derender.contact_range_problem(lo, hi) else {
        return Ok(cfg);
    };
    if states_mapping {
        bail!(
            "{}: the --config does not fit this sensor: {problem}; fit its tactile_derender.target and \
             contact_min_depth_m to the sensor, or leave tactile_derender out and tnd train fits them",
            data
        );
    }
    let fitted = cfg.tactile_derender.fitted_to_contact_range(lo, hi);
    eprintln!(
        "{}: in-contact depths {:.1}–{:.1} mm do not fit the default mapping (contact cut {:.1} mm, deepest {:.1} mm); \
         fitted to this sensor: no contact at −1, {:.1} mm at +1, contact cut {:.1} mm",
        data,
        lo * 1e3,
        hi * 1e3,
        cfg.tactile_derender.contact_min_depth_m * 1e3,
        cfg.tactile_derender.target.inverse(1.0) * 1e3,
        fitted.target.inverse(1.0) * 1e3,
        fitted.contact_min_depth_m * 1e3
    );
    Ok(UNet2DConfig {
        tactile_derender: fitted,
        ..cfg
    })
}

/// The `--data` folders as one string for messages.
fn shown_data(a: &TrainArgs) -> String {
    a.data
        .iter()
        .map(|p| p.display().to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

pub fn run(a: TrainArgs) -> Result<()> {
    // One writer per run folder: a second `tnd train --out` here is refused at once, naming the first's pid.
    let mut inputs: Vec<&std::path::Path> = a.data.iter().map(PathBuf::as_path).collect();
    inputs.extend(a.init.as_deref());
    inputs.extend(a.val_data.as_deref());
    let _out = crate::outputs::folder("--out", &a.out, a.force.force, &inputs)?;
    for d in a.data.iter().chain(a.val_data.iter()) {
        tactile_derender::io::lock::check_not_written(d)?;
    }
    let (given, states_mapping) = given_config(&a)?;
    let datasets = a
        .data
        .iter()
        .map(Dataset::open)
        .collect::<Result<Vec<_>, _>>()?;
    let resolution = datasets[0].resolution();
    if let Some((path, other)) = a
        .data
        .iter()
        .zip(&datasets)
        .find(|(_, d)| d.resolution() != resolution)
    {
        bail!(
            "--data {}: images are {:?}, those of {} {:?}; datasets trained together need one image size",
            path.display(),
            other.resolution(),
            a.data[0].display(),
            resolution
        );
    }
    let mut cfg = model_config(given, resolution)?;
    if !a.out.join("train_state.safetensors").is_file() {
        cfg = fit_to_data(&a, &datasets, cfg, states_mapping)?;
    }
    let tc = a.train.clone();
    if let Some(d) = tc.ema {
        if !(0.0..1.0).contains(&d) {
            return Err(anyhow!("--ema must be in [0, 1), found {d}"));
        }
    }
    // A NaN rate trains a NaN model, found only when it is loaded.
    if !(tc.lr.is_finite() && tc.lr > 0.0 && tc.lr <= 1.0) {
        bail!("--lr must be a learning rate in (0, 1], got {}", tc.lr);
    }
    let val_dataset = a.val_data.as_deref().map(Dataset::open).transpose()?;
    if let Some(v) = &val_dataset {
        if v.resolution() != resolution {
            bail!(
                "--val-data {}: images are {:?}, the training data's {:?}",
                a.val_data
                    .as_deref()
                    .unwrap_or(std::path::Path::new(""))
                    .display(),
                v.resolution(),
                resolution
            );
        }
    }
    let mut data = DatasetTraining::concatenated(datasets.iter().collect());
    if let Some(v) = &val_dataset {
        data = data.with_validation(v);
    }
    check_run_inputs(&a)?;
    let mut bar = super::progress::bar("training", " steps", 0);
    stop_on_signals();
    let mut at_step = 0;
    let result = train(&a.out, &tc, &cfg, a.init.as_deref(), &mut data, &mut |p| {
        bar.total = p.total as usize;
        bar.set_postfix(format!(
            "loss={:.4}, {:.1} samples/s",
            p.loss, p.samples_per_s
        ));
        let _ = bar.update_to(p.step as usize);
        at_step = p.step;
        !STOP.load(Ordering::Relaxed)
    });
    super::progress::finish(&mut bar);
    if let Err(tactile_derender::model::ModelError::Cancelled) = result {
        bail!(
            "interrupted at step {at_step}: checkpoint saved in {}; the same command resumes from it",
            a.out.display()
        );
    }
    let summary = result.with_context(|| format!("training in {}", a.out.display()))?;
    println!(
        "{}",
        json!({"steps": summary.steps, "resumed_from": summary.resumed_from, "last_loss": summary.last_loss,
            "model": crate::path_json(&summary.model_path)})
    );
    Ok(())
}
