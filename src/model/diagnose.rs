//! **Denoiser diagnosis** per diffusion timestep: how well a trained model recovers X0 from a single noised copy of
//! the truth, `x_t = √ᾱ_t·x0 + √(1−ᾱ_t)·ε`, at chosen timesteps. The reverse process commits to the contact layout
//! in its first (noisiest) steps, so a model whose one-step x0 estimate marks background as contact there produces
//! samples with contact blobs far from the imprint, whatever the later steps do. `tnd model diagnose` prints this.

use candle_core::{Device, Tensor};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::Serialize;

use super::diffusion::decode_depth;
use super::{DiffusionModel, ModelError};
use crate::image::Image;

/// One-step x0 quality of a model at one timestep, over a set of pairs (model units: the target normalisation).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct StepQuality {
    pub t: usize,
    /// ᾱ_t.
    pub alpha_bar: f32,
    /// Mean squared error of the implied ε (whatever the network predicts).
    pub eps_mse: f64,
    /// Mean squared error of the clipped x0 estimate on background (no-contact) pixels.
    pub x0_mse_background: f64,
    /// Mean squared error of the clipped x0 estimate on in-contact pixels.
    pub x0_mse_contact: f64,
    /// Fraction of background pixels whose x0 estimate decodes as contact.
    pub false_contact: f64,
    /// Fraction of in-contact pixels whose x0 estimate decodes as no contact.
    pub missed_contact: f64,
}

/// [`StepQuality`] of `model` at each of `timesteps` for `(imprint, target)` pairs (metres, the model's
/// resolution), with noise drawn from `seed`. Pairs are run in batches of 16.
pub fn x0_quality(
    model: &DiffusionModel,
    pairs: &[(Image, Image)],
    timesteps: &[usize],
    seed: u64,
) -> Result<Vec<StepQuality>, ModelError> {
    let (w, h) = model.resolution();
    let norm = &model.config().tactile_derender;
    let t_max = model.schedule().len();
    if let Some(&t) = timesteps.iter().find(|&&t| t >= t_max) {
        return Err(ModelError::Input(format!(
            "timestep {t} is outside the model's schedule (0..{t_max})"
        )));
    }
    for (y, x0) in pairs {
        for im in [y, x0] {
            if im.width != w || im.height != h {
                return Err(ModelError::Input(format!(
                    "a {}x{} image for a {w}x{h} model",
                    im.width, im.height
                )));
            }
        }
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let dev = Device::Cpu;
    let mut out = Vec::with_capacity(timesteps.len());
    for &t in timesteps {
        let ab = model.schedule().alpha_bar(t as i64);
        let (sa, sb) = (ab.sqrt(), (1.0 - ab).sqrt());
        let mut q = StepQuality {
            t,
            alpha_bar: ab,
            eps_mse: 0.0,
            x0_mse_background: 0.0,
            x0_mse_contact: 0.0,
            false_contact: 0.0,
            missed_contact: 0.0,
        };
        let (mut n_all, mut n_bg, mut n_fg) = (0usize, 0usize, 0usize);
        for chunk in pairs.chunks(16) {
            let n = chunk.len();
            // Truth: in contact where the target depth is set (metres).
            let in_contact: Vec<bool> = chunk
                .iter()
                .flat_map(|(_, x)| x.data.iter().map(|&v| v > 0.0))
                .collect();
            let x0: Vec<f32> = chunk
                .iter()
                .flat_map(|(_, x)| x.data.iter().map(|&v| norm.target.forward(v)))
                .collect();
            let y: Vec<f32> = chunk
                .iter()
                .flat_map(|(y, _)| y.data.iter().map(|&v| norm.imprint.forward(v)))
                .collect();
            let eps: Vec<f32> = (0..x0.len())
                .map(|_| StandardNormal.sample(&mut rng))
                .collect();
            let xt: Vec<f32> = x0.iter().zip(&eps).map(|(a, e)| sa * a + sb * e).collect();
            let input = Tensor::cat(
                &[
                    &Tensor::from_slice(&xt, (n, 1, h, w), &dev)?,
                    &Tensor::from_slice(&y, (n, 1, h, w), &dev)?,
                ],
                1,
            )?;
            let pred: Vec<f32> = model
                .unet()
                .forward(&input, &vec![t as f32; n])?
                .flatten_all()?
                .to_vec1()?;
            for i in 0..x0.len() {
                let (x0_hat, eps_hat) = norm.prediction_type.x0_eps(pred[i], xt[i], sa, sb);
                let x0_hat = x0_hat.clamp(-1.0, 1.0);
                q.eps_mse += f64::from(eps_hat - eps[i]).powi(2);
                let d = f64::from(x0_hat - x0[i]).powi(2);
                // The sampler's own contact decision.
                let says_contact = decode_depth(norm, x0_hat) > 0.0;
                if in_contact[i] {
                    q.x0_mse_contact += d;
                    q.missed_contact += f64::from(u8::from(!says_contact));
                    n_fg += 1;
                } else {
                    q.x0_mse_background += d;
                    q.false_contact += f64::from(u8::from(says_contact));
                    n_bg += 1;
                }
            }
            n_all += x0.len();
        }
        let per = |v: f64, n: usize| if n > 0 { v / n as f64 } else { f64::NAN };
        q.eps_mse = per(q.eps_mse, n_all);
        q.x0_mse_background = per(q.x0_mse_background, n_bg);
        q.false_contact = per(q.false_contact, n_bg);
        q.x0_mse_contact = per(q.x0_mse_contact, n_fg);
        q.missed_contact = per(q.missed_contact, n_fg);
        out.push(q);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use crate::model::checkpoint::build;
    use crate::model::init::init_params;
    use crate::model::{PredictionType, UNet2DConfig};

    fn tiny(prediction: PredictionType) -> DiffusionModel {
        let mut cfg = UNet2DConfig {
            sample_size: 8,
            block_out_channels: vec![4, 8],
            down_block_types: vec!["DownBlock2D".into(), "AttnDownBlock2D".into()],
            up_block_types: vec!["AttnUpBlock2D".into(), "UpBlock2D".into()],
            norm_num_groups: 2,
            attention_head_dim: Some(4),
            ..UNet2DConfig::default()
        };
        cfg.tactile_derender.prediction_type = prediction;
        let vars = build(&cfg, &Device::Cpu).unwrap();
        init_params(&vars.varmap, 3).unwrap();
        DiffusionModel::from_vars(vars, cfg, std::path::Path::new("tiny"))
    }

    fn pairs() -> Vec<(Image, Image)> {
        (0..3)
            .map(|k| {
                let y = Image::from_vec(8, 8, (0..64).map(|i| (i % 5) as f32 * 0.002).collect());
                // A 3 × 3 contact patch at 80–82 mm, moved per pair.
                let x0 = (0..64)
                    .map(|i| {
                        let (u, v) = (i % 8, i / 8);
                        if (k..k + 3).contains(&u) && (2..5).contains(&v) {
                            0.080 + 0.001 * (u - k) as f32
                        } else {
                            0.0
                        }
                    })
                    .collect();
                (y.unwrap(), Image::from_vec(8, 8, x0).unwrap())
            })
            .collect()
    }

    #[test]
    fn x0_error_is_bounded_by_the_implied_noise_error() {
        // x̂0 − x0 = √(1−ᾱ)/√ᾱ · (ε − ε̂) exactly, and clipping to [−1, 1] (where x0 lies) only shrinks it: the x0
        // error is at most (1−ᾱ)/ᾱ times the ε error, for any network and either prediction type.
        for p in [PredictionType::Epsilon, PredictionType::VPrediction] {
            let q = x0_quality(&tiny(p), &pairs(), &[0, 3, 60, 200], 5).unwrap();
            assert_eq!(q.len(), 4);
            for s in &q {
                let bound = f64::from((1.0 - s.alpha_bar) / s.alpha_bar) * s.eps_mse;
                let n_fg = 27.0;
                let n_bg = 3.0 * 64.0 - n_fg;
                let x0_mse = (s.x0_mse_background * n_bg + s.x0_mse_contact * n_fg) / (n_bg + n_fg);
                assert!(
                    x0_mse <= bound * (1.0 + 1e-4) + 1e-9,
                    "{p:?} t {}: {x0_mse} > {bound}",
                    s.t
                );
                assert!((0.0..=1.0).contains(&s.false_contact));
            }
            // At t = 0 the noise (√(1−ᾱ0) ≈ 0.013) cannot move any pixel across the contact cut (0.5 away).
            assert_eq!((q[0].false_contact, q[0].missed_contact), (0.0, 0.0));
        }
    }

    #[test]
    fn rejects_timesteps_outside_the_schedule_and_wrong_sizes() {
        let m = tiny(PredictionType::Epsilon);
        assert!(x0_quality(&m, &pairs(), &[250], 0).is_err());
        let small = Image::from_vec(4, 4, vec![0.0; 16]).unwrap();
        assert!(x0_quality(&m, &[(small.clone(), small)], &[10], 0).is_err());
    }
}
