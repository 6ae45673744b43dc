//! [`TrainConfig`]: the settings of one training run (paper V.B: Adam, lr 1e-4, the simplified ε objective), the one
//! definition behind `tnd train`'s flags and the run state's identity (what a resume must keep).

use serde::{Deserialize, Serialize};

use super::config::PredictionType;

/// The per-pixel training loss between predicted and true noise.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Loss {
    /// Mean squared error (Ho et al.'s simplified objective).
    L2,
    /// Mean absolute error.
    L1,
}

/// Settings of one training run; everything but `steps`/`epochs`, `checkpoint_every_s` and `log_every` must stay the
/// same across resumes. The one definition behind `tnd train`'s flags (flattened) and its defaults.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, clap::Args)]
#[serde(default)]
pub struct TrainConfig {
    /// Total optimiser steps (takes precedence over epochs).
    #[arg(long, conflicts_with = "epochs")]
    pub steps: Option<u64>,
    /// Total epochs over the train split (len / batch steps each; 1 when --steps is not given).
    #[arg(long)]
    pub epochs: Option<u64>,
    /// Pairs per optimiser step.
    #[arg(long, default_value_t = TrainConfig::default().batch)]
    pub batch: usize,
    /// Adam learning rate (the paper: 1e-4).
    #[arg(long, default_value_t = TrainConfig::default().lr)]
    pub lr: f64,
    /// Loss on the network's prediction: l2 (the paper's) or l1.
    #[arg(long, value_enum, default_value_t = TrainConfig::default().loss)]
    pub loss: Loss,
    /// Extra loss weight on the contact boundary: pixels within --boundary-px of an edge between the target's
    /// contact and no contact weigh 1 + this (each image's weights scaled to a mean of 1); 0, the default, is the
    /// plain loss. Stresses where real objects' contact masks go wrong (rims, holes, thin limbs).
    #[arg(long, default_value_t = TrainConfig::default().boundary_weight)]
    pub boundary_weight: f64,
    /// Reach of that boundary on either side of the edge, pixels of the model resolution.
    #[arg(long, default_value_t = TrainConfig::default().boundary_px)]
    pub boundary_px: usize,
    /// Seed of initialisation, batch order, timesteps and noise (a run is reproducible from it and the data).
    #[arg(long, default_value_t = TrainConfig::default().seed)]
    pub seed: u64,
    /// EMA decay of the weights (e.g. 0.999; the saved model then holds the EMA weights); none by default.
    #[arg(long)]
    pub ema: Option<f64>,
    /// Wall-clock seconds between checkpoints (a kill loses at most this much work; a checkpoint of the default
    /// model takes well under a second).
    #[arg(long = "checkpoint-every", default_value_t = TrainConfig::default().checkpoint_every_s)]
    pub checkpoint_every_s: f64,
    /// Also checkpoint every this many steps (0: only by time).
    #[arg(long, default_value_t = TrainConfig::default().checkpoint_every_steps)]
    pub checkpoint_every_steps: u64,
    /// Steps between log lines (and validation losses).
    #[arg(long, default_value_t = TrainConfig::default().log_every)]
    pub log_every: u64,
    /// What the network predicts for a new run (from scratch or --init): eps (the noise, the paper's objective) or
    /// v (the velocity √ᾱ·ε − √(1−ᾱ)·x0). Default: the model config's (--config, --init; v for the bundled
    /// default architecture, eps for a config that names none); a fine-tune of an eps model with v re-targets its output layer.
    #[arg(long, value_enum)]
    pub prediction: Option<PredictionType>,
    /// Device that trains: cpu (our fast kernels), cuda, cuda:N or metal (GPU builds: `--features cuda` or `metal`).
    /// Not part of a run's identity: a run may resume on another device.
    #[arg(long, default_value_t = TrainConfig::default().device)]
    pub device: String,
}

impl Default for TrainConfig {
    fn default() -> Self {
        Self {
            steps: None,
            epochs: None,
            batch: 16,
            lr: 1e-4,
            loss: Loss::L2,
            boundary_weight: 0.0,
            boundary_px: 2,
            seed: 0,
            ema: None,
            checkpoint_every_s: 60.0,
            checkpoint_every_steps: 0,
            log_every: 50,
            prediction: None,
            device: "cpu".into(),
        }
    }
}

impl TrainConfig {
    /// The settings of a run's identity in which `other` (a resume) differs from `self` (the run as started), as
    /// `--flag started (now given)`.
    pub(crate) fn differences(&self, other: &Self) -> Vec<String> {
        let mut out = Vec::new();
        let mut check = |flag: &str, a: String, b: String| {
            if a != b {
                out.push(format!("{flag} {a} (now {b})"));
            }
        };
        check("--batch", self.batch.to_string(), other.batch.to_string());
        check("--lr", self.lr.to_string(), other.lr.to_string());
        // The flags' own spelling (eps, v, l2).
        fn name(v: impl clap::ValueEnum) -> String {
            v.to_possible_value()
                .map(|p| p.get_name().to_string())
                .unwrap_or_default()
        }
        check("--loss", name(self.loss), name(other.loss));
        check(
            "--boundary-weight",
            self.boundary_weight.to_string(),
            other.boundary_weight.to_string(),
        );
        check(
            "--boundary-px",
            self.boundary_px.to_string(),
            other.boundary_px.to_string(),
        );
        check("--seed", self.seed.to_string(), other.seed.to_string());
        let opt = |v: Option<String>| v.unwrap_or_else(|| "none".into());
        check(
            "--ema",
            opt(self.ema.map(|e| e.to_string())),
            opt(other.ema.map(|e| e.to_string())),
        );
        check(
            "--prediction",
            opt(self.prediction.map(name)),
            opt(other.prediction.map(name)),
        );
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_resume_names_each_setting_that_differs_in_the_flags_spelling() {
        let started = TrainConfig {
            ema: Some(0.999),
            prediction: Some(PredictionType::VPrediction),
            ..TrainConfig::default()
        };
        // Steps, checkpoints and the device are not part of a run's identity.
        let same = TrainConfig {
            steps: Some(10),
            checkpoint_every_s: 1.0,
            device: "cuda".into(),
            ..started.clone()
        };
        assert!(started.differences(&same).is_empty());
        let resumed = TrainConfig {
            batch: 8,
            ema: None,
            prediction: Some(PredictionType::Epsilon),
            ..started.clone()
        };
        assert_eq!(
            started.differences(&resumed),
            [
                "--batch 16 (now 8)",
                "--ema 0.999 (now none)",
                "--prediction v (now eps)"
            ]
        );
    }
}
