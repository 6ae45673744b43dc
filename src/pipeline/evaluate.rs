//! The **evaluation loop** behind the paper's Tables I and II (V.C, V.D): for every pair of a
//! [`PairSource`], a [`Generator`] produces the in-contact depth X̂0 (the model, or the ground truth as the ideal
//! generator) and the pose sequence `tnd pose` runs ([`super::estimate_observation`]) estimates the pose from it;
//! the threshold baseline is registered from the imprint alone (the paper's baseline) and with the signature check.
//! Every method is scored with the depth metrics and the pose metrics, so the published tables measure what users
//! run: the same samples, seed and settings give the same estimate and posterior in the eval record as in pose.json.

use std::sync::Arc;

use super::{estimate_observation, Observation, PipelineError, PoseEstimate, PoseInput};
use crate::image::Image;
use crate::metrics::depth::{depth_metrics, DepthMetricsConfig};
use crate::metrics::eval_log::{EvalLog, EvalLogError, LoggedPair};
use crate::metrics::evaluate::{
    pair_seed, EvalConfig, EvalError, EvalPair, EvalReport, FailedPair, Generator, MethodResult,
    PairRecord, PairSource, REGION_DRAWS,
};
use crate::metrics::pose::pose_errors;
use crate::objects::ObjectSet;
use crate::pose::from_depth::consensus_depth;
use crate::pose::posterior::PosePosterior;
use crate::pose::{threshold_contact, Estimator, Hypothesis, ObjectModel, PoseError};
use crate::pose::{PoseConfig, SensorContext};
use crate::sensor::Se2;

/// Runs the evaluation: the pose sequence ([`estimate_observation`], with one [`Estimator`] for every pair) on
/// every pair's samples, and the scores.
pub struct Evaluator {
    /// The pose engine, configured by [`EvalConfig::pose`]: the one copy of the pose settings the evaluation runs
    /// with.
    pub estimator: Estimator,
    depth: DepthMetricsConfig,
    pose_samples: usize,
}

/// One pair's pose scores of one method before the depth metrics are added.
struct Scored {
    estimate: Option<Se2>,
    posterior: Option<PosePosterior>,
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

    fn config(&self) -> &PoseConfig {
        &self.estimator.config
    }

    /// The prepared object `name` of `set` (built on first use; [`Estimator::object`]).
    pub fn object(&self, set: &ObjectSet, name: &str) -> Result<Arc<ObjectModel>, EvalError> {
        self.estimator
            .object(set, name)
            .map_err(|e| pose_error(name, e))
    }

    /// `method`'s scores: its depth metrics and its estimate's errors against the truth.
    fn result(
        &self,
        pair: &EvalPair,
        object: &ObjectModel,
        depth: &Image,
        scored: Scored,
    ) -> Result<MethodResult, EvalError> {
        let depth = depth_metrics(depth, &pair.target, &self.depth)?;
        let pose = scored
            .estimate
            .map(|e| pose_errors(e, pair.object_pose, &object.symmetry, &object.cloud))
            .transpose()?;
        let truth_region = scored
            .posterior
            .as_ref()
            .and_then(|p| p.region_mass(pair.object_pose, &object.symmetry, REGION_DRAWS));
        Ok(MethodResult {
            depth,
            estimate: scored.estimate,
            pose,
            posterior: scored.posterior,
            truth_region,
        })
    }

    /// The pick among `hypotheses` ([`Estimator::choose_with_posterior`]), checked against the pair's signature
    /// when `check`.
    fn choose(
        &self,
        pair: &EvalPair,
        ctx: &SensorContext,
        object: &ObjectModel,
        hypotheses: &[Hypothesis],
        check: bool,
    ) -> Result<Scored, EvalError> {
        let measured = Some((&pair.signature, &pair.imprint)).filter(|_| check);
        let chosen = self
            .estimator
            .choose_with_posterior(object, hypotheses, ctx, &pair.t_world_camera, measured)
            .map_err(|e| pose_error(&pair.object, e))?;
        Ok(match chosen {
            Some((pose, posterior)) => Scored {
                estimate: Some(pose),
                posterior,
            },
            None => Scored {
                estimate: None,
                posterior: None,
            },
        })
    }

    /// Score every method on pair `i` of `source`: the model's estimate as `tnd pose` makes it (the pose sequence
    /// on its samples, the camera known), the same from the sample's hypotheses alone when the imprint proposes
    /// too, the multi-sample estimate, and the threshold baseline with and without the signature check.
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
        let fail = |e: EvalError| FailedPair {
            name: pair.name.clone(),
            object: pair.object.clone(),
            reason: crate::error::render(&e),
        };
        let sensor = source.context();
        let n = self.pose_samples.max(1);
        let samples = generator
            .generate(&pair, sensor, n, pair_seed)
            .map_err(fail)?;
        let first = samples
            .first()
            .ok_or_else(|| fail(EvalError::Generator("returned no sample".into())))?;
        observe(i, &pair, &samples);
        let object = self.object(&sensor.objects, &pair.object).map_err(fail)?;
        let estimate = self
            .estimate(&pair, sensor, &object, &samples, pair_seed)
            .map_err(fail)?;
        // The scoring steps below claim no free space where the frame has no return, as the sequence did.
        let observed = sensor.observing(Some(&pair.signature));
        let ctx = observed.as_ref();
        let config = self.config();
        let checks = config.check_signature && ctx.signature_model.is_some();
        let combine = checks && config.imprint_proposals;
        // The baseline as the paper defines it: its registration's best hypothesis. Its hypotheses are the imprint
        // proposals the sequence registered (same starts, same seed), or registered here when it made none.
        let base_x0 = threshold_contact(&pair.signature, &pair.imprint, &config.baseline);
        let base_hypotheses = match &estimate {
            Some(e) if combine => e.imprint_hypotheses.clone(),
            _ => self
                .estimator
                .pooled_hypotheses(
                    &object,
                    std::slice::from_ref(&base_x0),
                    ctx,
                    &pair.t_world_camera,
                    Some((&pair.signature, &pair.imprint)),
                    &self.estimator.random_starts(pair_seed),
                )
                .map_err(|e| fail(pose_error(&pair.object, e)))?,
        };
        let reported = |e: &PoseEstimate| Scored {
            estimate: e.best(),
            posterior: e.posterior.clone(),
        };
        let none = || Scored {
            estimate: None,
            posterior: None,
        };
        // The estimate `tnd pose` reports: with the imprint's proposals it is the combined row, and the model row
        // is the sample's hypotheses alone (the ablation); without them it is the model row.
        let (model, model_combined) = match (&estimate, combine) {
            (Some(e), true) => (
                self.choose(&pair, ctx, &object, &e.hypotheses, true)
                    .map_err(fail)?,
                Some(reported(e)),
            ),
            (Some(e), false) => (reported(e), None),
            (None, true) => (none(), Some(none())),
            (None, false) => (none(), None),
        };
        let model = self.result(&pair, &object, first, model).map_err(fail)?;
        let model_combined = model_combined
            .map(|s| self.result(&pair, &object, first, s))
            .transpose()
            .map_err(fail)?;
        let model_multi = if samples.len() > 1 {
            let consensus = consensus_depth(&samples, config.consensus_probability)
                .map_err(|e| fail(pose_error(&pair.object, e)))?;
            let multi = estimate.as_ref().map_or_else(none, |e| Scored {
                estimate: e.report.multi_sample.map(|m| m.pose),
                posterior: e.report.multi_sample_posterior.clone(),
            });
            Some(
                self.result(&pair, &object, &consensus, multi)
                    .map_err(fail)?,
            )
        } else {
            None
        };
        let baseline = self
            .choose(&pair, ctx, &object, &base_hypotheses, false)
            .and_then(|s| self.result(&pair, &object, &base_x0, s))
            .map_err(fail)?;
        let baseline_checked = checks
            .then(|| {
                self.choose(&pair, ctx, &object, &base_hypotheses, true)
                    .and_then(|s| self.result(&pair, &object, &base_x0, s))
            })
            .transpose()
            .map_err(fail)?;
        Ok(PairRecord {
            name: pair.name.clone(),
            object: pair.object.clone(),
            truth: pair.object_pose,
            contact_pixels: pair.target.count_nonzero(),
            symmetry: object.symmetry,
            model,
            model_multi,
            model_combined,
            baseline,
            baseline_checked,
        })
    }

    /// The pose sequence on `samples` of `pair` (the camera known, the truth given); `None` when no sample has
    /// contact.
    fn estimate(
        &self,
        pair: &EvalPair,
        sensor: &SensorContext,
        object: &ObjectModel,
        samples: &[Image],
        seed: u64,
    ) -> Result<Option<PoseEstimate>, EvalError> {
        let input = PoseInput {
            t_world_camera: pair.t_world_camera,
            observation: Observation {
                samples,
                imprint: &pair.imprint,
                signature: Some(&pair.signature),
                truth: Some(pair.object_pose),
                prior: None,
                camera_path: sensor.camera_path.as_ref(),
            },
        };
        match estimate_observation(
            &self.estimator,
            &pair.object,
            object,
            sensor,
            &input,
            seed,
            &mut |_, _| true,
        ) {
            Ok(e) => Ok(Some(e)),
            Err(PipelineError::NoContact) => Ok(None),
            Err(PipelineError::Pose(e)) => Err(pose_error(&pair.object, e)),
            Err(PipelineError::Eval(e)) => Err(e),
            Err(e) => Err(EvalError::Generator(crate::error::render(&e))),
        }
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
    /// log or save them; the first is the one the single-sample rows' depth metrics score).
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

    /// [`Evaluator::evaluate_observed`] into `log`: pair `i` of `source` is pair `first_index + i` of `split` in the
    /// log (`first_index`: the pairs the source skips). Pairs the log holds scored are taken from it (neither
    /// generated nor observed again); every other pair is scored and logged at once. The report covers every pair
    /// of `source` alike.
    #[allow(clippy::too_many_arguments)]
    pub fn evaluate_logged(
        &self,
        source: &dyn PairSource,
        generator: &dyn Generator,
        seed: u64,
        log: &mut EvalLog,
        split: &str,
        first_index: usize,
        progress: &mut dyn FnMut(usize, usize) -> bool,
        observe: &mut dyn FnMut(usize, &EvalPair, &[Image]),
    ) -> Result<EvalReport, EvalLogError> {
        let mut records = Vec::with_capacity(source.len());
        let mut failed = Vec::new();
        for i in 0..source.len() {
            let index = first_index + i;
            if let Some(r) = log.record(split, index) {
                records.push(r.clone());
            } else {
                let outcome = self.evaluate_pair(source, generator, i, pair_seed(seed, i), observe);
                let logged = match &outcome {
                    Ok(r) => LoggedPair::Record(Box::new(r.clone())),
                    Err(f) => LoggedPair::Failed(f.clone()),
                };
                log.insert(split, index, logged)?;
                match outcome {
                    Ok(r) => records.push(r),
                    Err(f) => failed.push(f),
                }
            }
            if !progress(i + 1, source.len()) {
                return Err(EvalError::Cancelled.into());
            }
        }
        Ok(EvalReport::new(generator.name(), records, failed))
    }
}

/// A pose engine error on `object` as the evaluation reports it.
fn pose_error(object: &str, e: PoseError) -> EvalError {
    match e {
        PoseError::Object(e) => EvalError::Object(e),
        PoseError::Mesh(e) => EvalError::Mesh(e),
        source => EvalError::Pose {
            object: object.to_string(),
            source,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_evaluators_engine_runs_with_the_configs_pose_settings() {
        let config = EvalConfig {
            pose: PoseConfig {
                check_signature: false,
                inits: 7,
                ..PoseConfig::default()
            },
            ..EvalConfig::default()
        };
        let evaluator = Evaluator::new(config.clone());
        assert_eq!(evaluator.estimator.config, config.pose);
    }
}
