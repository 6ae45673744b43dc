//! The de-rendering model as used downstream (paper IV.B, V.B): load a checkpoint, then draw N samples of the
//! in-contact depth X0 for one imprint Y in one batched reverse-diffusion run (the uncertainty analysis uses 50).

use std::path::{Path, PathBuf};
use std::sync::Arc;

use candle_core::{Device, Tensor};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

use super::checkpoint::{assign, build, locate, ModelVars};
use super::config::{TactileConfig, UNet2DConfig};
use super::guidance::ImprintGuidance;
use super::sampler::{self, SamplerKind};

/// The most samples one U-Net forward of [`DiffusionModel::sample_guided`] takes (larger requests run in chunks).
pub const FORWARD_CHUNK: usize = 16;
use super::schedule::NoiseSchedule;
use super::unet::UNet2DModel;
use super::ModelError;
use crate::image::Image;

/// A loaded conditional DDPM: U-Net, config (with normalisation) and schedule.
pub struct DiffusionModel {
    vars: ModelVars,
    config: UNet2DConfig,
    schedule: Arc<NoiseSchedule>,
    source: PathBuf,
}

impl DiffusionModel {
    /// Load a checkpoint (our `.safetensors`, a diffusers directory, or weights + config JSON; see
    /// [`super::checkpoint`]).
    pub fn load(path: &Path) -> Result<Self, ModelError> {
        Self::load_on(path, &Device::Cpu)
    }

    /// [`Self::load`] onto `device` ([`super::device::open_device`]); devices other than the CPU run candle's own
    /// tensor ops ([`super::kernels::Kernels::Portable`]). On the CPU the convolution weights are packed once
    /// ([`UNet2DModel::freeze`]): a loaded model's weights do not change.
    pub fn load_on(path: &Path, device: &Device) -> Result<Self, ModelError> {
        let (file, config) = locate(path)?;
        let mut vars = build(&config, device)?;
        assign(&vars.varmap, &file, "")?;
        if device.is_cpu() {
            vars.unet.freeze()?;
        } else {
            vars.unet.set_kernels(super::kernels::Kernels::Portable);
        }
        Ok(Self::from_vars(vars, config, path))
    }

    /// The device the model's parameters live on.
    pub fn device(&self) -> &Device {
        self.vars.unet.conv_in.weight.device()
    }

    /// Wrap already-built parameters (e.g. a model being trained).
    pub fn from_vars(vars: ModelVars, config: UNet2DConfig, source: &Path) -> Self {
        let schedule = Arc::new(NoiseSchedule::cosine(
            config.tactile_derender.num_train_timesteps,
        ));
        Self {
            vars,
            config,
            schedule,
            source: source.to_path_buf(),
        }
    }

    /// Image size `(width, height)` in pixels the model works at.
    pub fn resolution(&self) -> (usize, usize) {
        (self.config.sample_size, self.config.sample_size)
    }

    pub fn config(&self) -> &UNet2DConfig {
        &self.config
    }

    pub fn unet(&self) -> &UNet2DModel {
        &self.vars.unet
    }

    pub fn vars(&self) -> &ModelVars {
        &self.vars
    }

    pub fn schedule(&self) -> &NoiseSchedule {
        &self.schedule
    }

    /// The file or directory the model came from.
    pub fn source(&self) -> &Path {
        &self.source
    }

    /// `n` samples of X0 (metres) for `imprint` (metres), seeded; `progress(step, total)` returning false cancels.
    pub fn sample(
        &self,
        imprint: &Image,
        n: usize,
        kind: SamplerKind,
        seed: u64,
        progress: &mut dyn FnMut(usize, usize) -> bool,
    ) -> Result<Vec<Image>, ModelError> {
        self.sample_guided(imprint, None, n, kind, seed, progress)
    }

    /// [`Self::sample`], with each sample's x̂0 corrected towards the measured imprint by `guidance` at the steps
    /// it guides ([`super::guidance`]); `None` samples as [`Self::sample`] does.
    pub fn sample_guided(
        &self,
        imprint: &Image,
        guidance: Option<&ImprintGuidance>,
        n: usize,
        kind: SamplerKind,
        seed: u64,
        progress: &mut dyn FnMut(usize, usize) -> bool,
    ) -> Result<Vec<Image>, ModelError> {
        let (w, h) = self.resolution();
        if imprint.width != w || imprint.height != h || imprint.data.len() != w * h {
            return Err(ModelError::Input(format!(
                "imprint is {}x{}, the model needs {w}x{h}",
                imprint.width, imprint.height
            )));
        }
        if let Some(i) = imprint.data.iter().position(|v| !v.is_finite()) {
            return Err(ModelError::NonFinite {
                what: format!("imprint (pixel {i})"),
                at_step: None,
            });
        }
        if n == 0 {
            return Ok(Vec::new());
        }
        let norm = &self.config.tactile_derender;
        let cond: Vec<f32> = imprint
            .data
            .iter()
            .map(|&v| norm.imprint.forward(v))
            .collect();
        let c_out = self.config.out_channels;
        let c_cond = self.config.in_channels - c_out;
        if guidance.is_some() && c_out != 1 {
            return Err(ModelError::Input(format!(
                "imprint guidance needs a model with one output channel, {} has {c_out}",
                self.source.display()
            )));
        }
        let device = self.device().clone();
        let cond =
            Tensor::from_vec(cond, (1, 1, h, w), &device)?.broadcast_as((n, c_cond, h, w))?;
        let sampler = sampler::make(kind, self.schedule.clone(), norm.prediction_type)?;
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let len = n * c_out * h * w;
        let normal = |rng: &mut ChaCha8Rng| -> Vec<f32> {
            (0..len).map(|_| StandardNormal.sample(rng)).collect()
        };
        let mut x = normal(&mut rng);
        let total = sampler.timesteps().len();
        let per_sample = c_out * h * w;
        for (i, &t) in sampler.timesteps().iter().enumerate() {
            // The U-Net runs on chunks of at most FORWARD_CHUNK samples (every sample is independent of the
            // others): the activations of 256 samples would take ~16x the memory of 16, for no more samples per
            // second (`tnd bench unet --batches 16,50`: 76 against 74–77 samples/s on a 2-core Xeon).
            let mut out: Vec<f32> = Vec::with_capacity(x.len());
            for start in (0..n).step_by(FORWARD_CHUNK) {
                let m = FORWARD_CHUNK.min(n - start);
                let xt = Tensor::from_slice(
                    &x[start * per_sample..(start + m) * per_sample],
                    (m, c_out, h, w),
                    &device,
                )?;
                let input = Tensor::cat(&[&xt, &cond.narrow(0, 0, m)?], 1)?;
                out.extend(
                    self.vars
                        .unet
                        .forward(&input, &[t as f32])?
                        .flatten_all()?
                        .to_vec1::<f32>()?,
                );
            }
            let (mut x0, eps) = sampler.predict(&out, t, &x)?;
            if let Some(g) = guidance.filter(|g| g.guides(t, norm.num_train_timesteps)) {
                g.correct(&mut x0, norm)?;
            }
            let noise = sampler.needs_noise(t).then(|| normal(&mut rng));
            x = sampler.advance(&x0, &eps, t, &x, noise.as_deref())?;
            if !progress(i + 1, total) {
                return Err(ModelError::Cancelled);
            }
        }
        if x.iter().any(|v| !v.is_finite()) {
            return Err(ModelError::NonFinite {
                what: format!("samples of {}", self.source.display()),
                at_step: None,
            });
        }
        Ok(x.chunks(per_sample)
            .map(|s| Image {
                width: w,
                height: h,
                data: s[..h * w].iter().map(|&v| decode_depth(norm, v)).collect(),
            })
            .collect())
    }
}

/// A model output (model units) as an in-contact depth in metres: the target normalisation inverted, and 0 (no
/// contact) below `contact_min_depth_m`.
pub fn decode_depth(cfg: &TactileConfig, model: f32) -> f32 {
    let d = cfg.target.inverse(model);
    if d < cfg.contact_min_depth_m {
        0.0
    } else {
        d
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decoding_maps_the_no_contact_side_to_zero() {
        let cfg = TactileConfig::default();
        // The no-contact code and values near it: exactly 0 m.
        for v in [-1.0f32, -0.86, -0.2, -0.001] {
            assert_eq!(decode_depth(&cfg, v), 0.0, "{v}");
        }
        // In-contact codes decode through the normalisation: (v · 0.05 + 0.05) m.
        for (v, m) in [(0.0f32, 0.05f32), (0.52, 0.076), (0.8, 0.09)] {
            assert!((decode_depth(&cfg, v) - m).abs() < 1e-6, "{v}");
        }
    }
}
