//! Interchange with diffusers in the direction users ask for first: a model saved as a diffusers `save_pretrained`
//! folder, so that `UNet2DModel.from_pretrained(DIR)` and `DDPMScheduler.from_pretrained(DIR)` (or
//! `DDIMScheduler`) open it in one call each. Reading such a folder back is [`super::checkpoint::locate`]'s
//! directory path (every `--model` option takes one).
//!
//! The folder holds `config.json` (the `UNet2DModel` config; our conditioning and normalisation under the key
//! `tactile_derender`, which diffusers ignores), `diffusion_pytorch_model.safetensors` (the state dict, diffusers'
//! key names), `scheduler_config.json` (the cosine schedule with our prediction type, clipping and DDIM spacing) and
//! a README with the conditioning a Python user must reproduce.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

use candle_core::Tensor;
use serde_json::json;

use super::checkpoint::{named_vars, write_tensors};
use super::{DiffusionModel, ModelError, PredictionType};
use crate::io::write_atomic;

/// The diffusers version the files are written for (the one the tests' reference fixtures were made with).
pub const DIFFUSERS_VERSION: &str = "0.42.1";

/// The files of a diffusers folder, as written by [`export`].
pub const FILES: [&str; 4] = [
    "config.json",
    "diffusion_pytorch_model.safetensors",
    "scheduler_config.json",
    "README.md",
];

/// The `scheduler_config.json` of `model`: diffusers' `DDPMScheduler` with the model's schedule (our samplers follow
/// `DDPMScheduler.step` and `DDIMScheduler.step` with these settings; DDIM's `timestep_spacing` is our default).
pub fn scheduler_config(model: &DiffusionModel) -> serde_json::Value {
    let t = &model.config().tactile_derender;
    let prediction = match t.prediction_type {
        PredictionType::Epsilon => "epsilon",
        PredictionType::VPrediction => "v_prediction",
    };
    json!({
        "_class_name": "DDPMScheduler",
        "_diffusers_version": DIFFUSERS_VERSION,
        "num_train_timesteps": t.num_train_timesteps,
        "beta_schedule": t.beta_schedule,
        "beta_start": 0.0001,
        "beta_end": 0.02,
        "trained_betas": null,
        "variance_type": "fixed_small",
        "clip_sample": true,
        "clip_sample_range": 1.0,
        "prediction_type": prediction,
        "thresholding": false,
        "timestep_spacing": "trailing",
        "steps_offset": 0,
        "set_alpha_to_one": true,
        "rescale_betas_zero_snr": false,
    })
}

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> ModelError + '_ {
    move |error| ModelError::Io {
        path: path.to_path_buf(),
        error,
    }
}

/// Write `model` as a diffusers folder `dir`; returns the paths. A folder that holds a model already is replaced
/// whole ([`crate::io::atomic::replace_dir_atomic`]: a kill or a full disk half-way leaves the old model loadable,
/// never a new config beside old weights), as is a new folder; into an existing folder without a model (a user's
/// folder of other things) the files are written one by one, each atomically.
pub fn export(model: &DiffusionModel, dir: &Path) -> Result<Vec<PathBuf>, ModelError> {
    if dir.is_dir() && !dir.join(FILES[1]).exists() {
        return write_files(model, dir);
    }
    let mut failure = None;
    let written = crate::io::atomic::replace_dir_atomic(dir, |tmp| {
        write_files(model, tmp).map_err(|e| {
            let message = e.to_string();
            failure = Some(e);
            std::io::Error::other(message)
        })
    });
    match (written, failure) {
        (Ok(_), _) => Ok(FILES.iter().map(|f| dir.join(f)).collect()),
        (Err(_), Some(e)) => Err(e),
        (Err(error), None) => Err(ModelError::Io {
            path: dir.to_path_buf(),
            error,
        }),
    }
}

fn write_files(model: &DiffusionModel, dir: &Path) -> Result<Vec<PathBuf>, ModelError> {
    std::fs::create_dir_all(dir).map_err(io_err(dir))?;
    let cfg = model.config();
    let mut config: serde_json::Value = serde_json::from_str(&cfg.to_json()?)?;
    if let Some(o) = config.as_object_mut() {
        o.insert("_diffusers_version".into(), DIFFUSERS_VERSION.into());
    }
    let paths: Vec<PathBuf> = FILES.iter().map(|f| dir.join(f)).collect();
    write_atomic(&paths[0], serde_json::to_string_pretty(&config)?.as_bytes())
        .map_err(io_err(&paths[0]))?;
    let tensors: BTreeMap<String, Tensor> = named_vars(&model.vars().varmap)
        .into_iter()
        .map(|(k, v)| (k, v.as_tensor().clone()))
        .collect();
    // "format": "pt" is what torch-side loaders look for in a safetensors header.
    let meta = HashMap::from([("format".to_string(), "pt".to_string())]);
    write_tensors(&paths[1], &tensors, meta)?;
    let scheduler = serde_json::to_string_pretty(&scheduler_config(model))?;
    write_atomic(&paths[2], scheduler.as_bytes()).map_err(io_err(&paths[2]))?;
    write_atomic(&paths[3], readme(model).as_bytes()).map_err(io_err(&paths[3]))?;
    Ok(paths)
}

/// The first line of the README an export writes: how `tnd model export` knows a folder it exported.
pub const README_TITLE: &str = "# tactile-derender model (diffusers folder)";

fn readme(model: &DiffusionModel) -> String {
    let cfg = model.config();
    let t = &cfg.tactile_derender;
    format!(
        "{README_TITLE}\n\n\
         Written by `tnd model export --diffusers` from `{source}`.\n\n\
         ```python\n\
         from diffusers import UNet2DModel, DDIMScheduler\n\
         unet = UNet2DModel.from_pretrained(DIR)\n\
         scheduler = DDIMScheduler.from_pretrained(DIR)  # or DDPMScheduler\n\
         ```\n\n\
         Conditioning: the network's input has {cin} channels, `[x_t, imprint]` in that order — the noisy in-contact \
         depth and the imprint Y, both normalised as in `config.json` → `tactile_derender`: a value v in metres maps \
         to `(v - offset_m) / scale_m`, imprint offset {io} m and scale {is} m, target (0 m = no contact) offset \
         {to} m and scale {ts} m. \
         Resolution {s} x {s} pixels. Prediction type: {pred}; {steps} training steps, cosine schedule. \
         Decoded depths below {cut} m are \"no contact\" (0).\n",
        source = model.source().display(),
        cin = cfg.in_channels,
        io = t.imprint.offset_m,
        is = t.imprint.scale_m,
        to = t.target.offset_m,
        ts = t.target.scale_m,
        s = cfg.sample_size,
        pred = match t.prediction_type {
            super::PredictionType::Epsilon => "epsilon",
            super::PredictionType::VPrediction => "v_prediction",
        },
        steps = t.num_train_timesteps,
        cut = t.contact_min_depth_m,
    )
}
