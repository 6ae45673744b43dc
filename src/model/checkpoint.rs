//! Model checkpoints (paper IV.B model storage), interchangeable with diffusers:
//! * our file: one `.safetensors` with diffusers `UNet2DModel` state-dict keys and the config JSON in the metadata
//!   entry `"config"` (the layout of `../shared/peers/unet_torch.py`'s `unet_ref.safetensors`); a diffusers user
//!   loads it with `UNet2DModel.from_config(json.loads(meta["config"]))` + `load_state_dict(load_file(path))`;
//! * a diffusers `save_pretrained` directory (`config.json` + `diffusion_pytorch_model.safetensors`);
//! * a bare `.safetensors` with its config beside it (`<stem>_config.json` or `config.json`).
//!
//! Every tensor is checked by name and shape against the config, and for NaN/inf, before use.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

use candle_core::{DType, Device, Tensor};
use candle_nn::{VarBuilder, VarMap};

use super::config::{PredictionType, UNet2DConfig};
use super::unet::UNet2DModel;
use super::ModelError;
use crate::io::write_atomic;

/// Tensors and string metadata read from one safetensors file.
pub struct TensorFile {
    pub path: PathBuf,
    pub tensors: HashMap<String, Tensor>,
    pub metadata: HashMap<String, String>,
}

/// Read a safetensors file (any float dtype, converted to f32).
pub fn read_tensors(path: &Path) -> Result<TensorFile, ModelError> {
    let bytes = std::fs::read(path).map_err(|source| ModelError::MissingWeights {
        path: path.to_path_buf(),
        error: source,
    })?;
    parse_tensors(&bytes, path)
}

/// The bundled default model, compiled into the binary so that `tnd` and the workbench find it from any working
/// directory (`assets/models/default.safetensors` at build time; 5.4 MB in f16, 2.71 M parameters).
pub const BUNDLED_MODEL: &[u8] = include_bytes!("../../assets/models/default.safetensors");

/// The name that selects [`BUNDLED_MODEL`] wherever a checkpoint path is asked for (`--model default`).
pub const BUNDLED_MODEL_NAME: &str = "default";

/// The bundled small model (`assets/models/small.safetensors`, 4.3 MB, 1.09 M parameters; the default until session
/// 12): about twice as fast to sample, a little worse depth on real meshes (`assets/models/README.md`).
pub const BUNDLED_SMALL_MODEL: &[u8] = include_bytes!("../../assets/models/small.safetensors");

/// The name that selects [`BUNDLED_SMALL_MODEL`] (`--model small`).
pub const BUNDLED_SMALL_MODEL_NAME: &str = "small";

/// The bundled recording model (`assets/models/recording.safetensors`, 5.4 MB in f16): the default fine-tuned on
/// pairs rendered at a depth camera's native resolution and brought to the model's by the import's crop and area
/// resampling, the way every recorded frame reaches the model. Such imprints are several times quieter than
/// model-resolution pairs, and the default, trained on the latter, de-renders them less well
/// (`assets/models/README.md`).
pub const BUNDLED_RECORDING_MODEL: &[u8] =
    include_bytes!("../../assets/models/recording.safetensors");

/// The name that selects [`BUNDLED_RECORDING_MODEL`] (`--model recording`).
pub const BUNDLED_RECORDING_MODEL_NAME: &str = "recording";

/// The bundled models by name: `(name, bytes)`.
pub const BUNDLED_MODELS: [(&str, &[u8]); 3] = [
    (BUNDLED_MODEL_NAME, BUNDLED_MODEL),
    (BUNDLED_SMALL_MODEL_NAME, BUNDLED_SMALL_MODEL),
    (BUNDLED_RECORDING_MODEL_NAME, BUNDLED_RECORDING_MODEL),
];

/// The name that picks the bundled model matched to how the input's frames reached the model resolution (the
/// commands' default, [`matched_model`]); where nothing decides it, it is the default model.
pub const AUTO_MODEL_NAME: &str = "auto";

/// `model` with [`AUTO_MODEL_NAME`] resolved for an input whose frames were (`resampled`) or were not brought to
/// the model resolution by area resampling from a camera's larger frame: the bundled recording model for such
/// frames (recordings, their exported frames, imported datasets, pairs generated through a depth camera), the
/// bundled default for frames made or given at the model resolution. Any other name or path is returned as it is,
/// and so is `auto` where a file of that name exists.
pub fn matched_model(model: &Path, resampled: bool) -> PathBuf {
    if model.to_str() != Some(AUTO_MODEL_NAME) || model.exists() {
        return model.to_path_buf();
    }
    PathBuf::from(matched_bundled_name(resampled))
}

/// The bundled model `auto` stands for: [`BUNDLED_RECORDING_MODEL_NAME`] for `resampled` frames,
/// [`BUNDLED_MODEL_NAME`] otherwise ([`matched_model`]).
pub fn matched_bundled_name(resampled: bool) -> &'static str {
    if resampled {
        BUNDLED_RECORDING_MODEL_NAME
    } else {
        BUNDLED_MODEL_NAME
    }
}

/// The bundled model that `path` names ([`BUNDLED_MODELS`]; `auto` where no input decides is the default): a bare
/// name such as `small` that is not also an existing file (a file of that name wins).
pub fn bundled_name(path: &Path) -> Option<(&'static str, &'static [u8])> {
    if path.exists() {
        return None;
    }
    let name = match path.to_str()? {
        AUTO_MODEL_NAME => BUNDLED_MODEL_NAME,
        name => name,
    };
    BUNDLED_MODELS.iter().find(|(n, _)| *n == name).copied()
}

fn parse_bundled(name: &str, bytes: &[u8]) -> Result<(TensorFile, UNet2DConfig), ModelError> {
    let label = format!("<bundled {name} model>");
    let file = parse_tensors(bytes, Path::new(&label))?;
    let text = file
        .metadata
        .get("config")
        .ok_or_else(|| ModelError::Config {
            source_name: label.clone(),
            message: "no \"config\" metadata entry".into(),
        })?;
    let cfg = UNet2DConfig::from_json(text, &label)?;
    Ok((file, cfg))
}

/// Parse safetensors bytes read from `path` (named in errors).
fn parse_tensors(bytes: &[u8], path: &Path) -> Result<TensorFile, ModelError> {
    let bad = |message: String| ModelError::BadFile {
        path: path.to_path_buf(),
        message,
    };
    let (_, meta) =
        safetensors::SafeTensors::read_metadata(bytes).map_err(|e| bad(e.to_string()))?;
    let metadata = meta.metadata().clone().unwrap_or_default();
    let raw = candle_core::safetensors::load_buffer(bytes, &Device::Cpu)
        .map_err(|e| bad(e.to_string()))?;
    let mut tensors = HashMap::with_capacity(raw.len());
    for (k, t) in raw {
        let t = match t.dtype() {
            DType::F32 | DType::I64 | DType::U32 | DType::U8 => t,
            _ => t.to_dtype(DType::F32)?,
        };
        tensors.insert(k, t);
    }
    Ok(TensorFile {
        path: path.to_path_buf(),
        tensors,
        metadata,
    })
}

/// Whether `path` is a checkpoint tnd wrote: a safetensors file whose metadata `config` holds the
/// `tactile_derender` section (read from the header alone).
pub fn written_by_tnd(path: &Path) -> bool {
    use std::io::Read;
    let Ok(mut file) = std::fs::File::open(path) else {
        return false;
    };
    let mut len = [0u8; 8];
    if file.read_exact(&mut len).is_err() {
        return false;
    }
    let len = u64::from_le_bytes(len);
    if len > 100_000_000 {
        return false;
    }
    let mut header = vec![0u8; len as usize];
    if file.read_exact(&mut header).is_err() {
        return false;
    }
    serde_json::from_slice::<serde_json::Value>(&header).is_ok_and(|h| {
        h.pointer("/__metadata__/config")
            .and_then(serde_json::Value::as_str)
            .is_some_and(|c| c.contains("\"tactile_derender\""))
    })
}

/// Write named f32 tensors (sorted by name) with string metadata, atomically.
pub fn write_tensors(
    path: &Path,
    tensors: &BTreeMap<String, Tensor>,
    metadata: HashMap<String, String>,
) -> Result<(), ModelError> {
    let mut views = Vec::with_capacity(tensors.len());
    for (name, t) in tensors {
        let data: Vec<f32> = t.to_dtype(DType::F32)?.flatten_all()?.to_vec1()?;
        let bytes: Vec<u8> = data.iter().flat_map(|v| v.to_le_bytes()).collect();
        views.push((name.clone(), t.dims().to_vec(), bytes));
    }
    let mut list = Vec::with_capacity(views.len());
    for (name, shape, bytes) in &views {
        let view =
            safetensors::tensor::TensorView::new(safetensors::Dtype::F32, shape.clone(), bytes)
                .map_err(|e| ModelError::BadFile {
                    path: path.to_path_buf(),
                    message: e.to_string(),
                })?;
        list.push((name.clone(), view));
    }
    let bytes = safetensors::serialize(list, Some(metadata)).map_err(|e| ModelError::BadFile {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    write_atomic(path, &bytes).map_err(|source| ModelError::Io {
        path: path.to_path_buf(),
        error: source,
    })
}

/// The weights file a model `path` names: the file itself, or a diffusers directory's
/// `diffusion_pytorch_model.safetensors`.
pub fn weights_file(path: &Path) -> std::path::PathBuf {
    if path.is_dir() {
        path.join("diffusion_pytorch_model.safetensors")
    } else {
        path.to_path_buf()
    }
}

/// Locate weights and config for `path` (file or diffusers directory) and parse the config. The names `default`,
/// `small` and `recording` (when no such file exists) are the bundled models ([`BUNDLED_MODELS`]).
pub fn locate(path: &Path) -> Result<(TensorFile, UNet2DConfig), ModelError> {
    if let Some((name, bytes)) = bundled_name(path) {
        return parse_bundled(name, bytes);
    }
    let weights = weights_file(path);
    if path.is_dir() && path.join("model.safetensors").is_file() && !weights.exists() {
        // A `tnd train` run directory, not a diffusers folder.
        return Err(ModelError::TrainingRun {
            run: path.to_path_buf(),
        });
    }
    if path.is_dir() && !weights.exists() {
        let bin = path.join("diffusion_pytorch_model.bin");
        return Err(ModelError::Config {
            source_name: path.display().to_string(),
            message: if bin.is_file() {
                "holds diffusion_pytorch_model.bin (a PyTorch pickle, which tnd does not read); save it as \
                 safetensors: UNet2DModel.from_pretrained(DIR).save_pretrained(DIR, safe_serialization=True)"
                    .into()
            } else {
                "not a model folder: no diffusion_pytorch_model.safetensors (a diffusers folder) or \
                 model.safetensors (a tnd train run) in it"
                    .into()
            },
        });
    }
    let file = read_tensors(&weights)?;
    if let Some(text) = file.metadata.get("config") {
        let cfg = UNet2DConfig::from_json(
            text,
            &format!("{} (metadata \"config\")", weights.display()),
        )?;
        return Ok((file, cfg));
    }
    let dir = weights.parent().unwrap_or(Path::new("."));
    let stem = weights
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    for candidate in [
        dir.join(format!("{stem}_config.json")),
        dir.join("config.json"),
    ] {
        if candidate.is_file() {
            let text = std::fs::read_to_string(&candidate).map_err(|source| ModelError::Io {
                path: candidate.clone(),
                error: source,
            })?;
            let mut cfg = UNet2DConfig::from_json(&text, &candidate.display().to_string())?;
            let scheduler = dir.join("scheduler_config.json");
            if candidate.ends_with("config.json") && scheduler.is_file() {
                apply_scheduler_config(&mut cfg, &text, &candidate, &scheduler)?;
            }
            return Ok((file, cfg));
        }
    }
    Err(ModelError::Config {
        source_name: weights.display().to_string(),
        message: format!(
            "no config: neither a \"config\" metadata entry nor {stem}_config.json / config.json next to it"
        ),
    })
}

/// A diffusers folder's `scheduler_config.json` beside its `config.json`: the prediction type and the training
/// schedule are the model's, so they are taken from it where `config.json` does not say (a folder saved by diffusers
/// has no `tactile_derender` section), and a folder where the two files disagree is refused, naming both; a schedule
/// we do not implement is refused rather than replaced by ours.
fn apply_scheduler_config(
    cfg: &mut UNet2DConfig,
    config_text: &str,
    config_path: &Path,
    scheduler_path: &Path,
) -> Result<(), ModelError> {
    let bad = |message: String| ModelError::Config {
        source_name: scheduler_path.display().to_string(),
        message,
    };
    let text = std::fs::read_to_string(scheduler_path).map_err(|error| ModelError::Io {
        path: scheduler_path.to_path_buf(),
        error,
    })?;
    let scheduler: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| bad(format!("not JSON: {e}")))?;
    let config: serde_json::Value = serde_json::from_str(config_text)?;
    let ours = config.get("tactile_derender");
    let stated = |key: &str| ours.and_then(|o| o.get(key)).is_some();
    if scheduler.get("trained_betas").is_some_and(|b| !b.is_null()) {
        return Err(bad(
            "trained_betas (a custom noise schedule) is not supported; only the cosine schedule"
                .into(),
        ));
    }
    let t = &mut cfg.tactile_derender;
    if let Some(value) = scheduler.get("prediction_type") {
        let found = match value.as_str() {
            Some("epsilon") => PredictionType::Epsilon,
            Some("v_prediction") => PredictionType::VPrediction,
            _ => {
                return Err(bad(format!(
                    "prediction_type {value} is not supported (epsilon or v_prediction)"
                )))
            }
        };
        if stated("prediction_type") && found != t.prediction_type {
            return Err(bad(format!(
                "prediction_type {value} contradicts {}'s tactile_derender.prediction_type {:?}; correct one of them",
                config_path.display(),
                t.prediction_type
            )));
        }
        t.prediction_type = found;
    }
    if let Some(value) = scheduler.get("num_train_timesteps") {
        let found = value
            .as_u64()
            .and_then(|v| usize::try_from(v).ok())
            .ok_or_else(|| bad(format!("num_train_timesteps {value} is not a count")))?;
        if stated("num_train_timesteps") && found != t.num_train_timesteps {
            return Err(bad(format!(
                "num_train_timesteps {found} contradicts {}'s tactile_derender.num_train_timesteps {}; correct \
                 one of them",
                config_path.display(),
                t.num_train_timesteps
            )));
        }
        t.num_train_timesteps = found;
    }
    if let Some(value) = scheduler.get("beta_schedule") {
        let found = value.as_str().unwrap_or_default();
        if found != t.beta_schedule {
            return Err(bad(format!(
                "beta_schedule {value} is not supported: tnd samples with the cosine schedule \
                 (\"squaredcos_cap_v2\") only, and this model was trained with another"
            )));
        }
    }
    cfg.validate(&scheduler_path.display().to_string())
}

/// A U-Net whose parameters live in a [`VarMap`] (trainable; also used for inference).
pub struct ModelVars {
    pub varmap: VarMap,
    pub unet: UNet2DModel,
}

/// Build the U-Net for `cfg` with freshly allocated parameters (values to be set by [`assign`] or
/// [`super::init::init_params`]).
pub fn build(cfg: &UNet2DConfig, device: &Device) -> Result<ModelVars, ModelError> {
    cfg.validate("config")?;
    let varmap = VarMap::new();
    let vb = VarBuilder::from_varmap(&varmap, DType::F32, device);
    let unet = UNet2DModel::new(vb, cfg)?;
    Ok(ModelVars { varmap, unet })
}

/// All parameters by name, sorted.
pub fn named_vars(varmap: &VarMap) -> BTreeMap<String, candle_core::Var> {
    match varmap.data().lock() {
        Ok(g) => g.iter().map(|(k, v)| (k.clone(), v.clone())).collect(),
        Err(p) => p
            .into_inner()
            .iter()
            .map(|(k, v)| (k.clone(), v.clone()))
            .collect(),
    }
}

/// Copy `file`'s tensors (keys prefixed by `prefix`) into the parameters, checking that the key sets match, every
/// shape equals the config's, and no value is NaN/inf.
pub fn assign(varmap: &VarMap, file: &TensorFile, prefix: &str) -> Result<(), ModelError> {
    let vars = named_vars(varmap);
    for (name, var) in &vars {
        let key = format!("{prefix}{name}");
        let t = file
            .tensors
            .get(&key)
            .ok_or_else(|| ModelError::MissingTensor {
                path: file.path.clone(),
                key: key.clone(),
            })?;
        if t.dims() != var.dims() {
            return Err(ModelError::Shape {
                path: file.path.clone(),
                key,
                expected: var.dims().to_vec(),
                found: t.dims().to_vec(),
            });
        }
        let t = t.to_dtype(DType::F32)?;
        let finite = t
            .flatten_all()?
            .to_vec1::<f32>()?
            .iter()
            .all(|v| v.is_finite());
        if !finite {
            return Err(ModelError::NonFinite {
                what: format!("{}: tensor '{key}'", file.path.display()),
                at_step: None,
            });
        }
        var.set(&t.to_device(var.device())?)?;
    }
    if let Some(extra) = file
        .tensors
        .keys()
        .filter(|k| k.starts_with(prefix))
        .find(|k| !vars.contains_key(&k[prefix.len()..]))
    {
        return Err(ModelError::UnexpectedTensor {
            path: file.path.clone(),
            key: extra.clone(),
        });
    }
    Ok(())
}

/// Save the model parameters with the config in the metadata (our checkpoint format), plus `extra` metadata.
pub fn save_model(
    path: &Path,
    varmap: &VarMap,
    cfg: &UNet2DConfig,
    extra: HashMap<String, String>,
) -> Result<(), ModelError> {
    let tensors: BTreeMap<String, Tensor> = named_vars(varmap)
        .into_iter()
        .map(|(k, v)| (k, v.as_tensor().clone()))
        .collect();
    let mut meta = extra;
    meta.insert("config".into(), cfg.to_json()?);
    meta.insert(
        "format".into(),
        "tactile-derender UNet2DModel (diffusers keys)".into(),
    );
    write_tensors(path, &tensors, meta)
}
