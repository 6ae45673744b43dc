//! Training: the loss falls on a learnable synthetic task, a run killed after a checkpoint resumes to exactly the
//! weights of an uninterrupted run, `init` fine-tunes from a saved model, and the contact-boundary loss weight acts
//! on contact edges only.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::Path;

use tactile_derender::model::checkpoint::read_tensors;
use tactile_derender::model::train::{
    model_path, state_path, train, Loss, TrainBatch, TrainConfig, TrainingData,
};
use tactile_derender::model::{DiffusionModel, ModelError, PredictionType, UNet2DConfig};

/// Synthetic pairs: the target is a disc whose radius is encoded by the imprint's level (a learnable relation).
struct Synthetic {
    pairs: usize,
    size: usize,
}

impl Synthetic {
    fn pair(&self, i: usize) -> (Vec<f32>, Vec<f32>) {
        let s = self.size;
        let r = 1.0 + (i % 3) as f32;
        let mut imprint = vec![0.0; s * s];
        let mut target = vec![0.0; s * s];
        for v in 0..s {
            for u in 0..s {
                let (x, y) = (u as f32 - s as f32 / 2.0, v as f32 - s as f32 / 2.0);
                let inside = x * x + y * y <= r * r;
                imprint[v * s + u] = if inside { 0.004 * r } else { 0.0 };
                target[v * s + u] = if inside { 0.07 } else { 0.0 };
            }
        }
        (imprint, target)
    }
}

impl TrainingData for Synthetic {
    fn len(&self) -> usize {
        self.pairs
    }
    fn batch(
        &mut self,
        epoch: u64,
        index: usize,
        batch: usize,
        seed: u64,
    ) -> Result<TrainBatch, ModelError> {
        let mut b = TrainBatch {
            n: batch,
            width: self.size,
            height: self.size,
            imprint: vec![],
            target: vec![],
        };
        for k in 0..batch {
            let i = (index * batch + k + (epoch as usize) * 7 + seed as usize) % self.pairs;
            let (im, t) = self.pair(i);
            b.imprint.extend(im);
            b.target.extend(t);
        }
        Ok(b)
    }
    fn validation(&mut self, batch: usize) -> Result<Option<TrainBatch>, ModelError> {
        self.batch(0, 0, batch.min(2), 99).map(Some)
    }
}

fn tiny() -> UNet2DConfig {
    UNet2DConfig {
        sample_size: 8,
        block_out_channels: vec![4, 8],
        down_block_types: vec!["DownBlock2D".into(), "AttnDownBlock2D".into()],
        up_block_types: vec!["AttnUpBlock2D".into(), "UpBlock2D".into()],
        layers_per_block: 1,
        norm_num_groups: 2,
        attention_head_dim: Some(4),
        ..UNet2DConfig::default()
    }
}

fn params(path: &Path, prefix: &str) -> Vec<(String, Vec<f32>)> {
    let f = read_tensors(path).unwrap();
    let mut v: Vec<_> = f
        .tensors
        .iter()
        .filter(|(k, _)| k.starts_with(prefix))
        .map(|(k, t)| {
            (
                k.clone(),
                t.flatten_all().unwrap().to_vec1::<f32>().unwrap(),
            )
        })
        .collect();
    v.sort_by(|a, b| a.0.cmp(&b.0));
    v
}

/// Train 60 steps of `tc` on the tiny model and require the last 10 losses to average < 0.7 × the first 10.
fn assert_loss_falls(dir: &Path, tc: &TrainConfig, data: &mut Synthetic) {
    let mut losses = Vec::new();
    train(dir, tc, &tiny(), None, data, &mut |p| {
        losses.push(p.loss);
        true
    })
    .unwrap();
    let first: f32 = losses[..10].iter().sum::<f32>() / 10.0;
    let last: f32 = losses[50..].iter().sum::<f32>() / 10.0;
    assert!(last < 0.7 * first, "loss {first} -> {last}");
}

#[test]
fn killed_run_resumes_exactly() {
    let tc = TrainConfig {
        steps: Some(6),
        batch: 3,
        lr: 1e-3,
        seed: 5,
        ema: Some(0.9),
        checkpoint_every_s: 1e9,
        checkpoint_every_steps: 2,
        log_every: 1,
        ..TrainConfig::default()
    };
    let cfg = tiny();
    let straight = tempfile::tempdir().unwrap();
    let mut data = Synthetic { pairs: 7, size: 8 };
    let s = train(straight.path(), &tc, &cfg, None, &mut data, &mut |_| true).unwrap();
    assert_eq!((s.steps, s.resumed_from), (6, None));

    // Killed abruptly during step 5 (after the checkpoint at step 4): simulate with a panic in the callback.
    let killed = tempfile::tempdir().unwrap();
    let r = catch_unwind(AssertUnwindSafe(|| {
        let mut data = Synthetic { pairs: 7, size: 8 };
        train(killed.path(), &tc, &cfg, None, &mut data, &mut |p| {
            assert!(p.step < 5, "kill");
            true
        })
    }));
    assert!(r.is_err());
    let log = std::fs::read_to_string(killed.path().join("log.jsonl")).unwrap();
    assert_eq!(log.lines().count(), 5, "step 5 was logged before the kill");
    // Same command again: resumes from step 4 and finishes.
    let mut data = Synthetic { pairs: 7, size: 8 };
    let s = train(killed.path(), &tc, &cfg, None, &mut data, &mut |_| true).unwrap();
    assert_eq!((s.steps, s.resumed_from), (6, Some(4)));
    let log = std::fs::read_to_string(killed.path().join("log.jsonl")).unwrap();
    assert_eq!(
        log.lines().count(),
        6,
        "the stale step-5 line is dropped on resume"
    );

    for prefix in ["param.", "adam_m.", "adam_v.", "ema."] {
        let a = params(&state_path(straight.path()), prefix);
        let b = params(&state_path(killed.path()), prefix);
        assert_eq!(a.len(), b.len());
        assert!(!a.is_empty());
        for ((ka, va), (_, vb)) in a.iter().zip(&b) {
            assert_eq!(va, vb, "{ka} differs after resume");
        }
    }
    assert_eq!(
        params(&model_path(straight.path()), ""),
        params(&model_path(killed.path()), "")
    );

    // Changing a setting that shapes the run is refused.
    let other = TrainConfig {
        lr: 2e-3,
        ..tc.clone()
    };
    let e = train(killed.path(), &other, &cfg, None, &mut data, &mut |_| true)
        .err()
        .unwrap();
    assert!(matches!(e, ModelError::Config { .. }), "{e}");
}

#[test]
fn loss_falls_and_init_fine_tunes() {
    let tc = TrainConfig {
        steps: Some(60),
        batch: 4,
        lr: 3e-3,
        loss: Loss::L2,
        seed: 1,
        log_every: 10,
        ..TrainConfig::default()
    };
    let dir = tempfile::tempdir().unwrap();
    let mut data = Synthetic { pairs: 12, size: 8 };
    assert_loss_falls(dir.path(), &tc, &mut data);
    // Fine-tune from the trained model into a new run: starts from its weights (not from a fresh init).
    let ft = tempfile::tempdir().unwrap();
    let tc2 = TrainConfig {
        steps: Some(1),
        lr: 0.0,
        ..tc
    };
    train(
        ft.path(),
        &tc2,
        &UNet2DConfig::default(),
        Some(&model_path(dir.path())),
        &mut data,
        &mut |_| true,
    )
    .unwrap();
    assert_eq!(
        params(&model_path(dir.path()), ""),
        params(&model_path(ft.path()), "")
    );
}

#[test]
fn v_prediction_trains_and_is_saved_with_the_model() {
    // From scratch with v-prediction: the loss falls, and the checkpoint says what the network predicts.
    let tc = TrainConfig {
        steps: Some(60),
        batch: 4,
        lr: 3e-3,
        seed: 1,
        log_every: 10,
        prediction: Some(PredictionType::VPrediction),
        ..TrainConfig::default()
    };
    let dir = tempfile::tempdir().unwrap();
    let mut data = Synthetic { pairs: 12, size: 8 };
    assert_loss_falls(dir.path(), &tc, &mut data);
    let m = DiffusionModel::load(&model_path(dir.path())).unwrap();
    assert_eq!(
        m.config().tactile_derender.prediction_type,
        PredictionType::VPrediction
    );

    // An ε checkpoint fine-tuned with the override becomes a v model; without it, it stays ε.
    let eps_run = tempfile::tempdir().unwrap();
    let tc_eps = TrainConfig {
        steps: Some(1),
        prediction: None,
        ..tc.clone()
    };
    train(
        eps_run.path(),
        &tc_eps,
        &tiny(),
        None,
        &mut data,
        &mut |_| true,
    )
    .unwrap();
    let eps = DiffusionModel::load(&model_path(eps_run.path())).unwrap();
    assert_eq!(
        eps.config().tactile_derender.prediction_type,
        PredictionType::Epsilon
    );
    let ft = tempfile::tempdir().unwrap();
    let tc_ft = TrainConfig {
        steps: Some(1),
        ..tc.clone()
    };
    let init = model_path(eps_run.path());
    train(
        ft.path(),
        &tc_ft,
        &tiny(),
        Some(&init),
        &mut data,
        &mut |_| true,
    )
    .unwrap();
    let ft_model = DiffusionModel::load(&model_path(ft.path())).unwrap();
    assert_eq!(
        ft_model.config().tactile_derender.prediction_type,
        PredictionType::VPrediction
    );

    // Resuming a v run as an ε run is refused (the target would silently change).
    let more = TrainConfig {
        steps: Some(61),
        prediction: None,
        ..tc
    };
    let e = train(dir.path(), &more, &tiny(), None, &mut data, &mut |_| true)
        .err()
        .unwrap();
    assert!(matches!(e, ModelError::Config { .. }), "{e}");
}

/// `TrainingData` of `Synthetic` with every target emptied (no contact anywhere).
struct NoContact(Synthetic);

impl TrainingData for NoContact {
    fn len(&self) -> usize {
        self.0.len()
    }
    fn batch(&mut self, e: u64, i: usize, n: usize, seed: u64) -> Result<TrainBatch, ModelError> {
        let mut b = self.0.batch(e, i, n, seed)?;
        b.target.iter_mut().for_each(|v| *v = 0.0);
        Ok(b)
    }
    fn validation(&mut self, batch: usize) -> Result<Option<TrainBatch>, ModelError> {
        self.0.validation(batch)
    }
}

#[test]
fn boundary_weight_acts_on_contact_edges_only_and_still_trains() {
    let first_loss = |w: f64, data: &mut dyn TrainingData| {
        let tc = TrainConfig {
            steps: Some(1),
            batch: 4,
            seed: 2,
            boundary_weight: w,
            ..TrainConfig::default()
        };
        let dir = tempfile::tempdir().unwrap();
        let mut loss = f32::NAN;
        train(dir.path(), &tc, &tiny(), None, data, &mut |p| {
            loss = p.loss;
            true
        })
        .unwrap();
        loss
    };
    // Without contact there is no edge: every weight is 1 and the loss is the plain one, bit for bit.
    let mut empty = NoContact(Synthetic { pairs: 6, size: 8 });
    assert_eq!(first_loss(0.0, &mut empty), first_loss(4.0, &mut empty));
    // With the discs' edges the same draw gives another loss.
    let mut discs = Synthetic { pairs: 6, size: 8 };
    assert_ne!(first_loss(0.0, &mut discs), first_loss(4.0, &mut discs));
    // And the weighted objective is still learnable; a resume with another weight is refused, naming it.
    let tc = TrainConfig {
        steps: Some(60),
        batch: 4,
        lr: 3e-3,
        seed: 1,
        log_every: 10,
        boundary_weight: 4.0,
        ..TrainConfig::default()
    };
    let dir = tempfile::tempdir().unwrap();
    assert_loss_falls(dir.path(), &tc, &mut Synthetic { pairs: 12, size: 8 });
    let other = TrainConfig {
        steps: Some(61),
        boundary_weight: 2.0,
        ..tc
    };
    let err = train(dir.path(), &other, &tiny(), None, &mut discs, &mut |_| true).unwrap_err();
    assert!(
        err.to_string().contains("--boundary-weight 4 (now 2)"),
        "{err}"
    );
}
