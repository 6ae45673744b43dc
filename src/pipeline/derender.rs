//! **De-render** one imprint (paper IV.B sampling): N samples of the in-contact depth X0 in one batched
//! reverse-diffusion run, with what every front end shows beside them — the per-pixel mean and standard deviation,
//! the contact probability and the samples' consensus (what the multi-sample pose registers).

use crate::error::InvalidSetting;
use std::time::Instant;

use serde::{Deserialize, Serialize};

use super::{PipelineError, Progress};
use crate::image::Image;
use crate::model::{DiffusionModel, GuidanceConfig, ImprintGuidance, ModelError, SamplerConfig};
use crate::pose::from_depth::{consensus_depth, contact_probability};
use crate::pose::signature_check::SignatureModel;
use crate::sim::Simulator;

/// Samples drawn per imprint unless asked otherwise: enough for the contact probability and the multi-sample pose
/// (the paper's uncertainty KDEs use 50), few enough to stay interactive on a laptop CPU.
pub const DEFAULT_SAMPLES: usize = 16;

/// The most samples one run may draw (they are sampled as one batch).
pub const MAX_SAMPLES: usize = 256;

fn default_samples() -> usize {
    DEFAULT_SAMPLES
}

/// How to de-render: how many samples, which sampler, which seed.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, clap::Args)]
#[serde(default)]
pub struct DerenderConfig {
    /// Samples of the in-contact depth drawn for the imprint (1..=256).
    #[arg(long, alias = "n", default_value_t = default_samples())]
    pub samples: usize,
    #[command(flatten)]
    #[serde(flatten)]
    pub sampler: SamplerConfig,
    /// Seed of the initial noise (and of DDPM's or DDIM η > 0's per-step noise) and of the registration starts:
    /// the same seed gives the same samples and poses.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Device that runs the model: cpu, cuda, cuda:N or metal (GPU builds: `--features cuda` or `metal`).
    #[arg(long, default_value_t = default_device())]
    pub device: String,
    /// Imprint guidance ([`crate::model::guidance`]); applied where the sensor is known.
    #[command(flatten)]
    pub guidance: GuidanceConfig,
}

fn default_device() -> String {
    "cpu".into()
}

impl Default for DerenderConfig {
    fn default() -> Self {
        Self {
            samples: DEFAULT_SAMPLES,
            sampler: SamplerConfig::default(),
            seed: 0,
            device: default_device(),
            guidance: GuidanceConfig::default(),
        }
    }
}

impl DerenderConfig {
    /// Check the numbers (sessions and command lines may carry anything); `train_steps` is the model's T when known.
    pub fn validate(&self, train_steps: Option<usize>) -> Result<(), PipelineError> {
        self.sampler.validate(train_steps)?;
        crate::model::device::check_device_name(&self.device)?;
        self.guidance.validate()?;
        if !(1..=MAX_SAMPLES).contains(&self.samples) {
            return Err(PipelineError::Settings(InvalidSetting::new(
                "samples",
                format!(
                    "number of samples must be 1..={MAX_SAMPLES}, got {}",
                    self.samples
                ),
            )));
        }
        Ok(())
    }
}

/// The result of one de-rendering run (images in metres unless said otherwise).
#[derive(Clone, Debug)]
pub struct Derendered {
    /// X̂0 samples.
    pub samples: Vec<Image>,
    /// Per-pixel mean of the samples.
    pub mean: Image,
    /// Per-pixel (population) standard deviation of the samples.
    pub std: Image,
    /// Per-pixel fraction of the samples in contact, 0..1.
    pub contact_probability: Image,
    /// Pixels at least `consensus_probability` of the samples mark as contact, at their median depth.
    pub consensus: Image,
    /// Sampler wall time, seconds.
    pub seconds: f64,
}

/// Draw `config.samples` samples of X0 for `imprint` (metres, the model's resolution) and summarise them;
/// `consensus_probability` is the share of samples a consensus pixel needs
/// ([`crate::metrics::evaluate::EvalConfig::consensus_probability`]). With `guidance` (for this imprint, e.g.
/// [`imprint_guidance`]) the samples are guided towards it.
pub fn derender(
    model: &DiffusionModel,
    imprint: &Image,
    guidance: Option<&ImprintGuidance>,
    config: &DerenderConfig,
    consensus_probability: f64,
    progress: Progress<'_>,
) -> Result<Derendered, PipelineError> {
    config.validate(Some(model.config().tactile_derender.num_train_timesteps))?;
    let (w, h) = model.resolution();
    if (imprint.width, imprint.height) != (w, h) {
        return Err(PipelineError::Resolution {
            model: model.source().to_path_buf(),
            model_w: w,
            model_h: h,
            w: imprint.width,
            h: imprint.height,
        });
    }
    let t0 = Instant::now();
    let samples = model
        .sample_guided(
            imprint,
            guidance,
            config.samples,
            config.sampler.sampler_kind(),
            config.seed,
            progress,
        )
        .map_err(|e| match e {
            ModelError::Cancelled => PipelineError::Cancelled,
            e => e.into(),
        })?;
    let seconds = t0.elapsed().as_secs_f64();
    let (mean, std) = mean_std(&samples).ok_or_else(|| {
        PipelineError::Settings(InvalidSetting::new(
            "samples",
            "the sampler returned no samples",
        ))
    })?;
    Ok(Derendered {
        contact_probability: contact_probability(&samples)?,
        consensus: consensus_depth(&samples, consensus_probability)?,
        samples,
        mean,
        std,
        seconds,
    })
}

/// The guidance `config` asks for, towards `imprint` (metres) measured on `sim`'s sensor: on the membrane the
/// measurement's reference frame shows when its signature S is known, else on the nominal membrane. `None` when
/// `config.guidance` is off.
pub fn imprint_guidance(
    config: &DerenderConfig,
    sim: &Simulator,
    imprint: &Image,
    signature: Option<&Image>,
) -> Result<Option<ImprintGuidance>, PipelineError> {
    Ok(SignatureModel::of_simulator(sim).guidance(
        &config.guidance,
        sim.nominal_depth(),
        imprint,
        signature,
    )?)
}

/// Per-pixel mean and population standard deviation of the in-contact depth over the samples that mark the pixel as
/// contact (a valid depth), 0 where none does: the depth the samples agree on and how much they disagree about it.
/// Whether a pixel is in contact at all is the contact probability's to say; averaging its zeros in would paint the
/// rim of every contact at half its depth with a standard deviation of half the depth. `None` for an empty list or
/// images of different sizes.
pub fn mean_std(samples: &[Image]) -> Option<(Image, Image)> {
    let first = samples.first()?;
    let (w, h) = (first.width, first.height);
    if samples.iter().any(|s| (s.width, s.height) != (w, h)) {
        return None;
    }
    let mut count = vec![0u32; w * h];
    let mut sum = vec![0.0f64; w * h];
    for s in samples {
        for ((c, m), &v) in count.iter_mut().zip(sum.iter_mut()).zip(&s.data) {
            if crate::recon::is_valid_depth(v) {
                *c += 1;
                *m += f64::from(v);
            }
        }
    }
    let mean: Vec<f64> = sum
        .iter()
        .zip(&count)
        .map(|(&m, &c)| if c > 0 { m / f64::from(c) } else { 0.0 })
        .collect();
    let mut var = vec![0.0f64; w * h];
    for s in samples {
        for (((q, &v), &m), &c) in var.iter_mut().zip(&s.data).zip(&mean).zip(&count) {
            if crate::recon::is_valid_depth(v) {
                let d = f64::from(v) - m;
                *q += d * d / f64::from(c);
            }
        }
    }
    let mean = Image::from_vec(w, h, mean.iter().map(|&v| v as f32).collect())?;
    let std = Image::from_vec(w, h, var.iter().map(|&v| v.sqrt() as f32).collect())?;
    Some((mean, std))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mean_and_std_of_known_images() {
        // Depths 0.09 / 0.07 m (both in contact), 0.08 m / none (one), none / none.
        let a = Image::from_vec(3, 1, vec![0.09, 0.08, 0.0]).unwrap();
        let b = Image::from_vec(3, 1, vec![0.07, 0.0, 0.0]).unwrap();
        let (m, s) = mean_std(&[a.clone(), b]).unwrap();
        let close = |x: &[f32], y: [f32; 3]| x.iter().zip(y).all(|(p, q)| (p - q).abs() < 1e-7);
        assert!(close(&m.data, [0.08, 0.08, 0.0]), "{:?}", m.data);
        assert!(close(&s.data, [0.01, 0.0, 0.0]), "{:?}", s.data);
        assert!(mean_std(&[]).is_none());
        assert!(mean_std(&[a, Image::filled(1, 1, 0.0)]).is_none());
    }

    #[test]
    fn settings_out_of_range_are_refused() {
        let mut c = DerenderConfig::default();
        assert!(c.validate(Some(250)).is_ok());
        c.samples = 0;
        assert!(c.validate(None).is_err());
        c.samples = 4;
        c.sampler.steps = 251;
        assert!(c
            .validate(Some(250))
            .unwrap_err()
            .to_string()
            .contains("1..=250"));
    }

    #[test]
    fn session_fields_stay_flat() {
        let c: DerenderConfig = serde_json::from_str(
            r#"{"samples": 3, "sampler": "ddim", "ddim_steps": 10, "seed": 7}"#,
        )
        .unwrap();
        assert_eq!((c.samples, c.sampler.steps, c.seed), (3, 10, 7));
    }
}
