//! Training of the conditional DDPM (paper IV.B, V.B): the ε-prediction objective of Ho et al. — draw t and ε, form
//! x_t = √ᾱ_t x0 + √(1−ᾱ_t) ε, predict ε from `cat([x_t, imprint])` — optimised with Adam (lr 1e-4), optionally with
//! an EMA of the weights; pre-training from scratch or fine-tuning from a checkpoint (`init`).
//!
//! A run directory holds `train_state.safetensors` (weights, Adam moments, EMA, step; written atomically every
//! `checkpoint_every_s` seconds and at the end), `model.safetensors` (the usable model: EMA weights when enabled) and
//! `log.jsonl`. Running the same command again resumes from the state file and continues exactly: each step's
//! randomness (timesteps, noise) comes from ChaCha8 stream `step` of the seed, and the data order is a function of
//! (seed, epoch), so the RNG state is (seed, step).

use std::collections::{BTreeMap, HashMap};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use candle_core::Tensor;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};

use super::adam::Adam;
use super::checkpoint::{
    assign, build, locate, named_vars, read_tensors, save_model, write_tensors, ModelVars,
};
use super::config::{PredictionType, UNet2DConfig};
use super::init::init_params;
use super::schedule::NoiseSchedule;
pub use super::train_config::{Loss, TrainConfig};
use super::ModelError;

/// One batch of training pairs, row-major `[n, height, width]`, metres.
#[derive(Clone, Debug, PartialEq)]
pub struct TrainBatch {
    pub n: usize,
    pub width: usize,
    pub height: usize,
    pub imprint: Vec<f32>,
    pub target: Vec<f32>,
}

/// Where training pairs come from (the dataset module, or synthetic tensors in tests).
pub trait TrainingData {
    /// Training pairs per epoch.
    fn len(&self) -> usize;
    /// True when there are no training pairs.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Batch `index` (0-based) of `epoch` with `batch` pairs, in an order fixed by `(seed, epoch)`.
    fn batch(
        &mut self,
        epoch: u64,
        index: usize,
        batch: usize,
        seed: u64,
    ) -> Result<TrainBatch, ModelError>;
    /// A fixed held-out batch for the validation loss, if there is one.
    fn validation(&mut self, batch: usize) -> Result<Option<TrainBatch>, ModelError>;
}

/// What the progress callback sees after each step.
#[derive(Clone, Debug)]
pub struct TrainProgress {
    pub step: u64,
    pub total: u64,
    pub loss: f32,
    pub samples_per_s: f64,
    pub val_loss: Option<f32>,
}

/// Result of a finished run.
#[derive(Clone, Debug)]
pub struct TrainSummary {
    pub steps: u64,
    pub resumed_from: Option<u64>,
    pub last_loss: f32,
    pub model_path: PathBuf,
}

/// A run directory's files.
pub fn state_path(run: &Path) -> PathBuf {
    run.join("train_state.safetensors")
}
pub fn model_path(run: &Path) -> PathBuf {
    run.join("model.safetensors")
}
pub fn log_path(run: &Path) -> PathBuf {
    run.join("log.jsonl")
}

struct Run {
    vars: ModelVars,
    cfg: UNet2DConfig,
    adam: Adam,
    ema: Option<BTreeMap<String, Tensor>>,
    step: u64,
}

/// Train (or resume) in `run_dir`. A new run starts from `init` (fine-tuning) or from `model_cfg` with seeded
/// initialisation; an existing state file is resumed (then `init`/`model_cfg` are ignored). `progress` returning false
/// stops the run after writing a checkpoint.
pub fn train(
    run_dir: &Path,
    tc: &TrainConfig,
    model_cfg: &UNet2DConfig,
    init: Option<&Path>,
    data: &mut dyn TrainingData,
    progress: &mut dyn FnMut(&TrainProgress) -> bool,
) -> Result<TrainSummary, ModelError> {
    if tc.batch == 0 || data.is_empty() {
        return Err(ModelError::Data(format!(
            "need a positive batch and training pairs (batch {}, pairs {})",
            tc.batch,
            data.len()
        )));
    }
    let steps_per_epoch = (data.len() / tc.batch).max(1) as u64;
    let total = match (tc.steps, tc.epochs) {
        (Some(s), _) => s,
        (None, Some(e)) => e * steps_per_epoch,
        (None, None) => steps_per_epoch,
    };
    std::fs::create_dir_all(run_dir).map_err(|error| ModelError::Io {
        path: run_dir.to_path_buf(),
        error,
    })?;
    let mut run = open_run(run_dir, tc, model_cfg, init)?;
    let resumed_from = (run.step > 0).then_some(run.step);
    truncate_log(run_dir, run.step)?;
    let schedule = NoiseSchedule::cosine(run.cfg.tactile_derender.num_train_timesteps);
    let val = data.validation(tc.batch)?;
    let mut last_ckpt = Instant::now();
    let mut window = (Instant::now(), 0usize);
    let mut last_loss = f32::NAN;
    while run.step < total {
        let s = run.step;
        let b = data.batch(
            s / steps_per_epoch,
            (s % steps_per_epoch) as usize,
            tc.batch,
            tc.seed,
        )?;
        let (input, tf, target) = prepare(&run, &schedule, &b, tc, s)?;
        let weights = (tc.boundary_weight > 0.0)
            .then(|| {
                let w = super::train_data::contact_boundary_weights(
                    &b.target,
                    b.n,
                    b.height,
                    b.width,
                    tc.boundary_px,
                    tc.boundary_weight as f32,
                );
                Tensor::from_vec(w, target.shape(), target.device())
            })
            .transpose()?;
        let (value, grads) = super::kernels::parallel_batch::loss_and_grads(b.n, |r| {
            mean_loss(&run, tc, (&input, &tf, &target), weights.as_ref(), r, true)
        })?;
        if !value.is_finite() {
            return Err(ModelError::NonFinite {
                what: "training loss".into(),
                at_step: Some(s),
            });
        }
        run.adam.step(&grads)?;
        if let (Some(d), Some(ema)) = (tc.ema, run.ema.as_mut()) {
            update_ema(ema, &run.adam.vars, d)?;
        }
        run.step += 1;
        last_loss = value;
        window.1 += b.n;
        let samples_per_s = window.1 as f64 / window.0.elapsed().as_secs_f64().max(1e-9);
        let mut val_loss = None;
        if run.step % tc.log_every.max(1) == 0 || run.step == total {
            if let Some(vb) = &val {
                let (input, tf, target) = prepare(&run, &schedule, vb, tc, u64::MAX)?;
                // Unweighted, so that validation losses compare across --boundary-weight.
                let loss = mean_loss(&run, tc, (&input, &tf, &target), None, 0..vb.n, false)?;
                val_loss = Some(loss.to_scalar::<f32>()?);
            }
            append_log(run_dir, run.step, value, val_loss, samples_per_s)?;
            window = (Instant::now(), 0);
        }
        let keep_going = progress(&TrainProgress {
            step: run.step,
            total,
            loss: value,
            samples_per_s,
            val_loss,
        });
        let due = last_ckpt.elapsed().as_secs_f64() >= tc.checkpoint_every_s
            || (tc.checkpoint_every_steps > 0 && run.step % tc.checkpoint_every_steps == 0);
        if due || run.step == total || !keep_going {
            save_run(run_dir, &run, tc)?;
            last_ckpt = Instant::now();
        }
        if !keep_going {
            return Err(ModelError::Cancelled);
        }
    }
    if resumed_from == Some(total) || total == 0 {
        save_run(run_dir, &run, tc)?;
    }
    Ok(TrainSummary {
        steps: run.step,
        resumed_from,
        last_loss,
        model_path: model_path(run_dir),
    })
}

/// `ema ← d·ema + (1 − d)·w` for every named weight. The result is detached: `w` is a tracked variable, so
/// otherwise every step's EMA would keep the previous one (and its intermediates) alive through the op graph — a leak
/// of 13 MB a step for the default model, which ran a 24 GiB machine out of memory within an hour.
fn update_ema(
    ema: &mut BTreeMap<String, Tensor>,
    vars: &[(String, candle_core::Var)],
    d: f64,
) -> Result<(), ModelError> {
    for (name, var) in vars {
        if let Some(e) = ema.get_mut(name) {
            *e = ((&*e * d)? + (var.as_tensor() * (1.0 - d))?)?.detach();
        }
    }
    Ok(())
}

/// The network input `cat([x_t, imprint])`, the timesteps and the regression target (the model config's
/// `prediction_type`: ε or v) of batch `b` with the randomness of `step` (`u64::MAX`: the fixed validation draw).
fn prepare(
    run: &Run,
    schedule: &NoiseSchedule,
    b: &TrainBatch,
    tc: &TrainConfig,
    step: u64,
) -> Result<(Tensor, Vec<f32>, Tensor), ModelError> {
    let norm = &run.cfg.tactile_derender;
    let (n, h, w) = (b.n, b.height, b.width);
    let s = run.cfg.sample_size;
    if h != s || w != s || b.imprint.len() != n * h * w || b.target.len() != n * h * w {
        return Err(ModelError::Data(format!(
            "batch of {n} {w}x{h} images ({} / {} values) does not fit a {s}x{s} model",
            b.imprint.len(),
            b.target.len()
        )));
    }
    let dev = run.vars.unet.conv_in.weight.device().clone();
    let x0: Vec<f32> = b.target.iter().map(|&v| norm.target.forward(v)).collect();
    let cond: Vec<f32> = b.imprint.iter().map(|&v| norm.imprint.forward(v)).collect();
    let mut rng = ChaCha8Rng::seed_from_u64(tc.seed);
    rng.set_stream(step);
    let t: Vec<usize> = (0..n)
        .map(|_| rng.random_range(0..schedule.len()))
        .collect();
    let eps: Vec<f32> = (0..n * h * w).map(|_| rng.sample(StandardNormal)).collect();
    let x0 = Tensor::from_vec(x0, (n, 1, h, w), &dev)?;
    let cond = Tensor::from_vec(cond, (n, 1, h, w), &dev)?;
    let eps = Tensor::from_vec(eps, (n, 1, h, w), &dev)?;
    let xt = schedule.add_noise(&x0, &eps, &t)?;
    let target = match run.cfg.tactile_derender.prediction_type {
        PredictionType::Epsilon => eps,
        PredictionType::VPrediction => schedule.velocity(&x0, &eps, &t)?,
    };
    let tf: Vec<f32> = t.iter().map(|&t| t as f32).collect();
    Ok((Tensor::cat(&[&xt, &cond], 1)?, tf, target))
}

/// The mean loss (`tc.loss`) of the samples `r` of a prepared batch, each pixel's term scaled by its weight when
/// there are weights (the batch's shape; see [`super::train_data::contact_boundary_weights`]).
fn mean_loss(
    run: &Run,
    tc: &TrainConfig,
    (input, tf, target): (&Tensor, &[f32], &Tensor),
    weights: Option<&Tensor>,
    r: std::ops::Range<usize>,
    train: bool,
) -> candle_core::Result<Tensor> {
    let (start, len) = (r.start, r.len());
    let pred = run
        .vars
        .unet
        .forward_t(&input.narrow(0, start, len)?, &tf[r], train)?;
    let diff = (pred - target.narrow(0, start, len)?)?;
    let per_pixel = match tc.loss {
        Loss::L2 => diff.sqr()?,
        Loss::L1 => diff.abs()?,
    };
    match weights {
        Some(w) => (per_pixel * w.narrow(0, start, len)?)?.mean_all(),
        None => per_pixel.mean_all(),
    }
}

fn open_run(
    run_dir: &Path,
    tc: &TrainConfig,
    model_cfg: &UNet2DConfig,
    init: Option<&Path>,
) -> Result<Run, ModelError> {
    let device = super::device::open_device(&tc.device)?;
    let portable = |mut vars: ModelVars| {
        if !device.is_cpu() {
            vars.unet.set_kernels(super::kernels::Kernels::Portable);
        }
        vars
    };
    let state = state_path(run_dir);
    if state.is_file() {
        let file = read_tensors(&state)?;
        let meta = |k: &str| {
            file.metadata
                .get(k)
                .cloned()
                .ok_or_else(|| ModelError::BadFile {
                    path: state.clone(),
                    message: format!("metadata entry '{k}' is missing"),
                })
        };
        let cfg = UNet2DConfig::from_json(&meta("config")?, &state.display().to_string())?;
        let saved: TrainConfig =
            serde_json::from_str(&meta("train")?).map_err(|e| ModelError::BadFile {
                path: state.clone(),
                message: format!("metadata 'train': {e}"),
            })?;
        let differences = saved.differences(tc);
        if !differences.is_empty() {
            return Err(ModelError::Config {
                source_name: state.display().to_string(),
                message: format!(
                    "this run was started with {}; resume with the same settings or use a new --out",
                    differences.join(", ")
                ),
            });
        }
        let step: u64 = meta("step")?.parse().map_err(|_| ModelError::BadFile {
            path: state.clone(),
            message: "metadata 'step' is not an integer".into(),
        })?;
        let vars = portable(build(&cfg, &device)?);
        assign(&vars.varmap, &file, "param.")?;
        let mut adam = Adam::new(named_vars(&vars.varmap).into_iter().collect(), tc.lr)?;
        adam.t = step;
        for (i, (name, var)) in adam.vars.iter().enumerate() {
            for (prefix, slot) in [("adam_m.", &mut adam.m[i]), ("adam_v.", &mut adam.v[i])] {
                *slot = state_tensor(&file, &format!("{prefix}{name}"), var.dims())?
                    .to_device(&device)?;
            }
        }
        let ema = match tc.ema {
            Some(_) => Some(
                adam.vars
                    .iter()
                    .map(|(n, v)| {
                        Ok((
                            n.clone(),
                            state_tensor(&file, &format!("ema.{n}"), v.dims())?
                                .to_device(&device)?,
                        ))
                    })
                    .collect::<Result<BTreeMap<_, _>, ModelError>>()?,
            ),
            None => None,
        };
        return Ok(Run {
            vars,
            cfg,
            adam,
            ema,
            step,
        });
    }
    let (vars, mut cfg) = match init {
        Some(p) => {
            let (file, cfg) = locate(p)?;
            let vars = portable(build(&cfg, &device)?);
            assign(&vars.varmap, &file, "")?;
            (vars, cfg)
        }
        None => {
            let vars = portable(build(model_cfg, &device)?);
            init_params(&vars.varmap, tc.seed)?;
            (vars, model_cfg.clone())
        }
    };
    if let Some(p) = tc.prediction {
        cfg.tactile_derender.prediction_type = p;
    }
    let adam = Adam::new(named_vars(&vars.varmap).into_iter().collect(), tc.lr)?;
    let ema = tc.ema.map(|_| {
        adam.vars
            .iter()
            .map(|(n, v)| {
                (
                    n.clone(),
                    v.as_tensor()
                        .copy()
                        .unwrap_or_else(|_| v.as_tensor().clone()),
                )
            })
            .collect()
    });
    Ok(Run {
        vars,
        cfg,
        adam,
        ema,
        step: 0,
    })
}

fn state_tensor(
    file: &super::checkpoint::TensorFile,
    key: &str,
    dims: &[usize],
) -> Result<Tensor, ModelError> {
    let t = file
        .tensors
        .get(key)
        .ok_or_else(|| ModelError::MissingTensor {
            path: file.path.clone(),
            key: key.into(),
        })?;
    if t.dims() != dims {
        return Err(ModelError::Shape {
            path: file.path.clone(),
            key: key.into(),
            expected: dims.to_vec(),
            found: t.dims().to_vec(),
        });
    }
    Ok(t.clone())
}

/// Write the state file, then the model file (EMA weights when enabled), both atomically.
fn save_run(run_dir: &Path, run: &Run, tc: &TrainConfig) -> Result<(), ModelError> {
    let mut tensors = BTreeMap::new();
    for (i, (name, var)) in run.adam.vars.iter().enumerate() {
        tensors.insert(format!("param.{name}"), var.as_tensor().clone());
        tensors.insert(format!("adam_m.{name}"), run.adam.m[i].clone());
        tensors.insert(format!("adam_v.{name}"), run.adam.v[i].clone());
    }
    if let Some(ema) = &run.ema {
        for (name, t) in ema {
            tensors.insert(format!("ema.{name}"), t.clone());
        }
    }
    let train_json = serde_json::to_string(tc)?;
    let mut meta = HashMap::from([
        ("config".to_string(), run.cfg.to_json()?),
        ("train".to_string(), train_json.clone()),
        ("step".to_string(), run.step.to_string()),
        (
            "format".to_string(),
            "tactile-derender training state".to_string(),
        ),
    ]);
    write_tensors(&state_path(run_dir), &tensors, meta.clone())?;
    meta.remove("format");
    meta.remove("config");
    let model = model_path(run_dir);
    match &run.ema {
        Some(ema) => {
            // The model file holds the EMA weights under the plain keys.
            let plain: BTreeMap<String, Tensor> = ema.clone();
            let mut m = meta;
            m.insert("config".into(), run.cfg.to_json()?);
            m.insert("weights".into(), "ema".into());
            write_tensors(&model, &plain, m)
        }
        None => save_model(&model, &run.vars.varmap, &run.cfg, meta),
    }
}

#[derive(Serialize, Deserialize)]
struct LogLine {
    step: u64,
    loss: f32,
    val_loss: Option<f32>,
    samples_per_s: f64,
}

fn append_log(
    run_dir: &Path,
    step: u64,
    loss: f32,
    val_loss: Option<f32>,
    sps: f64,
) -> Result<(), ModelError> {
    let path = log_path(run_dir);
    let io = |source| ModelError::Io {
        path: path.clone(),
        error: source,
    };
    let line = serde_json::to_string(&LogLine {
        step,
        loss,
        val_loss,
        samples_per_s: sps,
    })?;
    // Appended, not replaced: checked and recorded as an output's writes are (crate::io::output).
    crate::io::output::before_write(&path).map_err(io)?;
    let mut f = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&path)
        .map_err(io)?;
    writeln!(f, "{line}").map_err(io)
}

/// Drop log lines past the checkpoint we resume from (written by a run that was killed before its next checkpoint).
fn truncate_log(run_dir: &Path, step: u64) -> Result<(), ModelError> {
    let path = log_path(run_dir);
    let Ok(text) = std::fs::read_to_string(&path) else {
        return Ok(());
    };
    let kept: Vec<&str> = text
        .lines()
        .filter(|l| serde_json::from_str::<LogLine>(l).is_ok_and(|x| x.step <= step))
        .collect();
    if kept.len() != text.lines().count() {
        let mut out = kept.join("\n");
        if !out.is_empty() {
            out.push('\n');
        }
        crate::io::write_atomic(&path, out.as_bytes()).map_err(|source| ModelError::Io {
            path,
            error: source,
        })?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{Device, Var};

    #[test]
    fn ema_update_is_the_weighted_mean_and_holds_no_graph() {
        let w = Var::from_slice(&[1.0f32, 3.0], 2, &Device::Cpu).unwrap();
        let vars = vec![("w".to_string(), w)];
        let mut ema = BTreeMap::new();
        ema.insert(
            "w".to_string(),
            Tensor::new(&[0.0f32, 1.0], &Device::Cpu).unwrap(),
        );
        for _ in 0..3 {
            update_ema(&mut ema, &vars, 0.5).unwrap();
        }
        // 0 → 0.5 → 0.75 → 0.875 and 1 → 2 → 2.5 → 2.75.
        let e = &ema["w"];
        assert_eq!(e.to_vec1::<f32>().unwrap(), vec![0.875, 2.75]);
        // A tracked result would chain every previous EMA tensor (the leak this guards against).
        assert!(!e.track_op());
    }
}
