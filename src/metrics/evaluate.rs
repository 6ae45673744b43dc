//! The **evaluation loop** behind the paper's Tables I and II (V.C, V.D): for every pair of a [`PairSource`], a
//! [`Generator`] produces the in-contact depth X̂0 (the model, or the ground truth as the ideal generator), the
//! threshold baseline produces its own from the signature, and both are scored with the depth metrics and — after
//! back-projection and registration from K random starts — the pose metrics.

use std::sync::Arc;

use glam::DAffine3;
use serde::{Deserialize, Serialize};

use super::depth::{depth_metrics, DepthMetrics, DepthMetricsConfig};
use super::pose::pose_errors;
use super::MetricsError;
use crate::image::Image;
use crate::objects::{ObjectError, ObjectSet};
use crate::pose::from_depth::consensus_depth;
use crate::pose::{
    threshold_contact, Estimator, Hypothesis, ObjectModel, PoseConfig, PoseError, SensorContext,
};
use crate::sensor::Se2;

/// Errors of the evaluation; each names its source.
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    #[error("pair source: {0}")]
    Source(String),
    #[error("generator: {0}")]
    Generator(String),
    #[error("object '{object}': {source}")]
    Pose {
        object: String,
        #[source]
        source: PoseError,
    },
    #[error(transparent)]
    Object(#[from] ObjectError),
    #[error(transparent)]
    Metrics(#[from] MetricsError),
    #[error(transparent)]
    Dataset(#[from] crate::dataset::DatasetError),
    #[error(transparent)]
    Mesh(#[from] crate::mesh::MeshError),
    #[error("generator {}: {source}", model.display())]
    Model {
        model: std::path::PathBuf,
        #[source]
        source: Box<crate::model::ModelError>,
    },
    #[error("{}: sensor configuration: {source}", dir.display())]
    Sensor {
        dir: std::path::PathBuf,
        #[source]
        source: crate::sim::SimError,
    },
    #[error("{}: {message}", path.display())]
    Write {
        path: std::path::PathBuf,
        message: String,
    },
    #[error("cancelled")]
    Cancelled,
}

/// One evaluation pair: the images the methods see and the truth they are scored against (metres).
#[derive(Clone, Debug)]
pub struct EvalPair {
    /// Display name, e.g. `unseen_poses/12`.
    pub name: String,
    /// Object name in the source's object set.
    pub object: String,
    /// True pose `t_world_object`.
    pub object_pose: Se2,
    /// `t_world_camera` of the sensor camera.
    pub t_world_camera: DAffine3,
    /// X0, the true in-contact depth.
    pub target: Image,
    /// S, the signature.
    pub signature: Image,
    /// Y, the imprint (the model's condition).
    pub imprint: Image,
}

/// A source of evaluation pairs (a dataset split, or pairs simulated on the fly).
pub trait PairSource: Sync {
    /// Number of pairs.
    fn len(&self) -> usize;
    /// True when there are no pairs.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Pair `index` (< len).
    fn pair(&self, index: usize) -> Result<EvalPair, EvalError>;
    /// Camera, membrane and objects.
    fn context(&self) -> &SensorContext;
}

/// Produces in-contact depth images X̂0 for a pair: the model (conditioned on the imprint), or the ground truth.
pub trait Generator: Sync {
    /// Name for reports.
    fn name(&self) -> String;
    /// `n` samples of X̂0 (metres) for `pair` of a source whose sensor is `ctx`, reproducible from `seed`.
    fn generate(
        &self,
        pair: &EvalPair,
        ctx: &SensorContext,
        n: usize,
        seed: u64,
    ) -> Result<Vec<Image>, EvalError>;
}

/// The ideal generator: returns the true X0 (tests the rest of the pipeline; Table I becomes trivially perfect).
pub struct GroundTruthGenerator;

impl Generator for GroundTruthGenerator {
    fn name(&self) -> String {
        "ground-truth".into()
    }
    fn generate(
        &self,
        pair: &EvalPair,
        _ctx: &SensorContext,
        n: usize,
        _seed: u64,
    ) -> Result<Vec<Image>, EvalError> {
        Ok(vec![pair.target.clone(); n])
    }
}

/// Settings of the evaluation: the pose engine's ([`PoseConfig`], stored flat) and the scoring's.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct EvalConfig {
    /// The pose engine, as `tnd pose` runs it.
    #[serde(flatten)]
    pub pose: PoseConfig,
    pub depth: DepthMetricsConfig,
    /// Points sampled on each object for the Chamfer distance (default 1000).
    pub chamfer_points: usize,
    /// Model samples per pair. With more than 1, the model is also scored on the multi-sample estimate (the
    /// consensus of the samples, [`crate::pose::from_depth::consensus_depth`]; with the signature check, every
    /// sample's hypotheses and, with [`PoseConfig::imprint_proposals`], the imprint's, pooled and checked) beside the
    /// first sample alone (default 1: single sample only).
    pub pose_samples: usize,
}

impl Default for EvalConfig {
    fn default() -> Self {
        Self {
            pose: PoseConfig::default(),
            depth: DepthMetricsConfig::default(),
            chamfer_points: crate::pose::estimator::DEFAULT_SURFACE_POINTS,
            pose_samples: 1,
        }
    }
}

pub use super::report::{
    EvalReport, FailedPair, MethodResult, MethodSummary, PairRecord, REGION_DRAWS,
};

/// One registration of a pair's estimates: the depth metrics and every pooled hypothesis.
struct Registered {
    depth: DepthMetrics,
    object: Arc<ObjectModel>,
    hypotheses: Vec<Hypothesis>,
}

/// Runs the evaluation: the pose engine ([`Estimator`]) on every pair's estimates, and the scores.
pub struct Evaluator {
    /// The pose engine, configured by [`EvalConfig::pose`]: the one copy of the pose settings the evaluation runs
    /// with.
    pub estimator: Estimator,
    depth: DepthMetricsConfig,
    pose_samples: usize,
}

impl Evaluator {
    pub fn new(config: EvalConfig) -> Self {
        let EvalConfig {
            pose,
            depth,
            chamfer_points,
            pose_samples,
        } = config;
        Self {
            estimator: Estimator::new(pose).with_surface_points(chamfer_points),
            depth,
            pose_samples,
        }
    }

    /// The prepared object `name` of `set` (built on first use; [`Estimator::object`]).
    pub fn object(&self, set: &ObjectSet, name: &str) -> Result<Arc<ObjectModel>, EvalError> {
        self.estimator.object(set, name).map_err(|e| match e {
            PoseError::Object(e) => EvalError::Object(e),
            PoseError::Mesh(e) => EvalError::Mesh(e),
            source => EvalError::Pose {
                object: name.to_string(),
                source,
            },
        })
    }

    /// The depth metrics of `depth` and the hypotheses of registering every image of `registered` (each anchored as
    /// [`Estimator::anchor`]), pooled in that order.
    fn register_pair(
        &self,
        pair: &EvalPair,
        depth: &Image,
        registered: &[Image],
        ctx: &SensorContext,
        seed: u64,
    ) -> Result<Registered, EvalError> {
        let depth = depth_metrics(depth, &pair.target, &self.depth)?;
        let object = self.object(&ctx.objects, &pair.object)?;
        let strategy = self.estimator.random_starts(seed);
        let hypotheses = self
            .estimator
            .pooled_hypotheses(
                &object,
                registered,
                ctx,
                &pair.t_world_camera,
                Some((&pair.signature, &pair.imprint)),
                &strategy,
            )
            .map_err(|source| EvalError::Pose {
                object: pair.object.clone(),
                source,
            })?;
        Ok(Registered {
            depth,
            object,
            hypotheses,
        })
    }

    /// The scores of a registration: its pose chosen by [`Estimator::choose`], with the signature check only when `check`
    /// (and [`PoseConfig::check_signature`]) allow it, and the pose errors against the truth.
    fn pose_result(
        &self,
        pair: &EvalPair,
        ctx: &SensorContext,
        r: &Registered,
        check: bool,
    ) -> Result<MethodResult, EvalError> {
        let measured = Some((&pair.signature, &pair.imprint)).filter(|_| check);
        let chosen = self
            .estimator
            .choose_with_posterior(
                &r.object,
                &r.hypotheses,
                ctx,
                &pair.t_world_camera,
                measured,
            )
            .map_err(|source| EvalError::Pose {
                object: pair.object.clone(),
                source,
            })?;
        let (estimate, posterior) = match chosen {
            Some((pose, posterior)) => (Some(pose), posterior),
            None => (None, None),
        };
        let pose = estimate
            .map(|e| pose_errors(e, pair.object_pose, &r.object.symmetry, &r.object.cloud))
            .transpose()?;
        let truth_region = posterior
            .as_ref()
            .and_then(|p| p.region_mass(pair.object_pose, &r.object.symmetry, REGION_DRAWS));
        Ok(MethodResult {
            depth: r.depth,
            estimate,
            pose,
            posterior,
            truth_region,
        })
    }

    /// Score both methods on pair `i` of `source`.
    pub(crate) fn evaluate_pair(
        &self,
        source: &dyn PairSource,
        generator: &dyn Generator,
        i: usize,
        pair_seed: u64,
        observe: &mut dyn FnMut(usize, &EvalPair, &[Image]),
    ) -> Result<PairRecord, FailedPair> {
        let pair = source.pair(i).map_err(|e| FailedPair {
            name: format!("#{i}"),
            object: String::new(),
            reason: crate::error::render(&e),
        })?;
        let object = pair.object.clone();
        let fail = |e: EvalError| FailedPair {
            name: pair.name.clone(),
            object: pair.object.clone(),
            reason: crate::error::render(&e),
        };
        let ctx = source.context();
        let n = self.pose_samples.max(1);
        let samples = generator.generate(&pair, ctx, n, pair_seed).map_err(fail)?;
        let first = samples
            .first()
            .ok_or_else(|| fail(EvalError::Generator("returned no sample".into())))?;
        observe(i, &pair, &samples);
        // The pose steps claim no free space where the frame has no return (the generator above guides with the
        // whole membrane and leaves those pixels out itself).
        let observed = ctx.observing(Some(&pair.signature));
        let ctx = observed.as_ref();
        let model_reg = self
            .register_pair(&pair, first, std::slice::from_ref(first), ctx, pair_seed)
            .map_err(fail)?;
        let model = self
            .pose_result(&pair, ctx, &model_reg, true)
            .map_err(fail)?;
        // The baseline as the paper defines it (its registration's best hypothesis), and with the signature check.
        let base_x0 = threshold_contact(
            &pair.signature,
            &pair.imprint,
            &self.estimator.config.baseline,
        );
        let base = self
            .register_pair(
                &pair,
                &base_x0,
                std::slice::from_ref(&base_x0),
                ctx,
                pair_seed,
            )
            .map_err(fail)?;
        let model_multi = if samples.len() > 1 {
            let consensus = consensus_depth(&samples, self.estimator.config.consensus_probability)
                .map_err(|source| {
                    fail(EvalError::Pose {
                        object: object.clone(),
                        source,
                    })
                })?;
            let mut registered = vec![consensus.clone()];
            if self.estimator.config.check_signature {
                registered.extend(samples.iter().cloned());
            }
            let mut pooled = self
                .register_pair(&pair, &consensus, &registered, ctx, pair_seed)
                .map_err(fail)?;
            // The imprint's hypotheses as registered for the baseline (same starts, same seed) close the pool.
            if self.estimator.config.check_signature && self.estimator.config.imprint_proposals {
                pooled.hypotheses.extend_from_slice(&base.hypotheses);
            }
            Some(self.pose_result(&pair, ctx, &pooled, true).map_err(fail)?)
        } else {
            None
        };
        let baseline = self.pose_result(&pair, ctx, &base, false).map_err(fail)?;
        let checks = self.estimator.config.check_signature && ctx.signature_model.is_some();
        let combine = checks && self.estimator.config.imprint_proposals;
        let baseline_checked = checks
            .then(|| self.pose_result(&pair, ctx, &base, true))
            .transpose()
            .map_err(fail)?;
        // The sample's hypotheses first, the imprint's after: the check scores them all alike.
        let model_combined = combine
            .then(|| {
                let pooled = Registered {
                    depth: model_reg.depth,
                    object: model_reg.object.clone(),
                    hypotheses: [model_reg.hypotheses.as_slice(), &base.hypotheses].concat(),
                };
                self.pose_result(&pair, ctx, &pooled, true)
            })
            .transpose()
            .map_err(fail)?;
        Ok(PairRecord {
            name: pair.name.clone(),
            object: pair.object.clone(),
            truth: pair.object_pose,
            contact_pixels: pair.target.count_nonzero(),
            symmetry: model_reg.object.symmetry,
            model,
            model_multi,
            model_combined,
            baseline,
            baseline_checked,
        })
    }

    /// Evaluate every pair of `source` with `generator` and the baseline. A pair that cannot be read or scored (an
    /// object whose mesh cannot be prepared, a generator error) is recorded in [`EvalReport::failed`] with its reason
    /// and the evaluation goes on. `progress(done, total)` returns false to cancel.
    pub fn evaluate(
        &self,
        source: &dyn PairSource,
        generator: &dyn Generator,
        seed: u64,
        progress: &mut dyn FnMut(usize, usize) -> bool,
    ) -> Result<EvalReport, EvalError> {
        self.evaluate_observed(source, generator, seed, progress, &mut |_, _, _| {})
    }

    /// [`Self::evaluate`], showing `observe(i, pair, samples)` every pair the generator produced samples for (e.g. to
    /// log or save them; the first is the one the single-sample rows score).
    pub fn evaluate_observed(
        &self,
        source: &dyn PairSource,
        generator: &dyn Generator,
        seed: u64,
        progress: &mut dyn FnMut(usize, usize) -> bool,
        observe: &mut dyn FnMut(usize, &EvalPair, &[Image]),
    ) -> Result<EvalReport, EvalError> {
        let mut records = Vec::with_capacity(source.len());
        let mut failed = Vec::new();
        for i in 0..source.len() {
            match self.evaluate_pair(source, generator, i, pair_seed(seed, i), observe) {
                Ok(r) => records.push(r),
                Err(f) => failed.push(f),
            }
            if !progress(i + 1, source.len()) {
                return Err(EvalError::Cancelled);
            }
        }
        Ok(EvalReport::new(generator.name(), records, failed))
    }
}

/// The seed of pair `i` of a source (its sampler and registration starts) in a run seeded with `seed`: a pair scores
/// the same whichever pairs are scored beside it, so a resumed run equals an uninterrupted one.
pub(crate) fn pair_seed(seed: u64, i: usize) -> u64 {
    seed.wrapping_mul(0x9E37_79B9_7F4A_7C15)
        .wrapping_add(i as u64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_pose_settings_are_stored_flat_beside_the_scoring_ones() {
        // The JSON shape of settings written before the pose engine had its own config (records, reports) is kept.
        let config = EvalConfig {
            pose: PoseConfig {
                check_signature: false,
                inits: 7,
                ..PoseConfig::default()
            },
            pose_samples: 4,
            ..EvalConfig::default()
        };
        let json = serde_json::to_value(&config).unwrap();
        assert_eq!(json["check_signature"], false);
        assert_eq!(json["inits"], 7);
        assert_eq!(json["pose_samples"], 4);
        assert!(json.get("pose").is_none());
        let back: EvalConfig = serde_json::from_value(json).unwrap();
        assert_eq!(back, config);
        // The evaluator's engine runs with the config's pose settings.
        let evaluator = Evaluator::new(config.clone());
        assert_eq!(evaluator.estimator.config, config.pose);
    }
}
