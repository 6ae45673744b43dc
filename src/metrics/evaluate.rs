//! The **evaluation loop** behind the paper's Tables I and II (V.C, V.D): for every pair of a [`PairSource`], a
//! [`Generator`] produces the in-contact depth X̂0 (the model, or the ground truth as the ideal generator), the
//! threshold baseline produces its own from the signature, and both are scored with the depth metrics and — after
//! back-projection and registration from K random starts — the pose metrics.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use glam::{DAffine3, DVec3};
use serde::{Deserialize, Serialize};

use super::depth::{depth_metrics, DepthMetrics, DepthMetricsConfig};
use super::pose::pose_errors;
use super::MetricsError;
use crate::image::Image;
use crate::mesh::{Mesh, RayCaster};
use crate::objects::{ObjectError, ObjectSet, Symmetry};
use crate::pose::from_depth::{anchor_to_signature, consensus_depth, SensorView};
use crate::pose::posterior::PosteriorConfig;
use crate::pose::signature_check::{SignatureCheckConfig, SignatureModel};
use crate::pose::{
    sample_surface, threshold_contact, BaselineConfig, Hypothesis, InitStrategy, PoseError,
    SdfRegistration, SdfRegistrationConfig,
};
use crate::recon::FreeSpaceConfig;
use crate::sensor::{Intrinsics, Se2};

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

/// What every pair of a source shares: the camera, the undeformed membrane depth E (free-space evidence) and the
/// objects.
#[derive(Clone, Debug)]
pub struct EvalContext {
    pub intrinsics: Intrinsics,
    /// E: depth of the undeformed membrane, metres (0 where not seen).
    pub membrane: Image,
    pub objects: ObjectSet,
    /// How a contact becomes a signature on this sensor (the shadow cloak), for the signature check; `None` when
    /// unknown (the check is then skipped).
    pub signature_model: Option<SignatureModel>,
}

impl EvalContext {
    /// The camera and undeformed membrane of `sim`'s sensor, with `objects`.
    pub fn of_simulator(sim: &crate::sim::Simulator, objects: ObjectSet) -> Self {
        Self {
            intrinsics: *sim.intrinsics(),
            membrane: sim.nominal_depth().clone(),
            objects,
            signature_model: Some(SignatureModel::of_simulator(sim)),
        }
    }
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
    fn context(&self) -> &EvalContext;
}

/// Produces in-contact depth images X̂0 for a pair: the model (conditioned on the imprint), or the ground truth.
pub trait Generator: Sync {
    /// Name for reports.
    fn name(&self) -> String;
    /// `n` samples of X̂0 (metres) for `pair` of a source whose sensor is `ctx`, reproducible from `seed`.
    fn generate(
        &self,
        pair: &EvalPair,
        ctx: &EvalContext,
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
        _ctx: &EvalContext,
        n: usize,
        _seed: u64,
    ) -> Result<Vec<Image>, EvalError> {
        Ok(vec![pair.target.clone(); n])
    }
}

/// Settings of the evaluation.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct EvalConfig {
    pub depth: DepthMetricsConfig,
    pub registration: SdfRegistrationConfig,
    pub free_space: FreeSpaceConfig,
    pub baseline: BaselineConfig,
    /// Random starts per registration (default 10, the paper's).
    pub inits: usize,
    /// Random starts are within this distance of the contact centroid, metres (default 10 mm).
    pub init_radius_m: f64,
    /// Points sampled on each object for the Chamfer distance (default 1000).
    pub chamfer_points: usize,
    /// Model samples per pair. With more than 1, the model is also scored on the multi-sample estimate (the
    /// consensus of the samples, [`crate::pose::from_depth::consensus_depth`]; with the signature check, every
    /// sample's hypotheses and, with [`Self::imprint_proposals`], the imprint's, pooled and checked) beside the
    /// first sample alone (default 1: single sample only).
    pub pose_samples: usize,
    /// Fraction of the samples that must mark a pixel as contact for the consensus (default 0.5).
    pub consensus_probability: f64,
    /// Shift every estimate's contact depths onto the measured signature before registering it
    /// ([`crate::pose::from_depth::anchor_to_signature`]; default true). Depth metrics score the estimate as
    /// generated.
    pub anchor_to_signature: bool,
    /// Choose among the registration's hypotheses (and refine the choice) by the signature each one predicts
    /// against the measured one ([`crate::pose::signature_check`]; default true). Needs the pair's signature and
    /// the sensor's signature model.
    pub check_signature: bool,
    /// Settings of the signature check.
    pub signature_check: SignatureCheckConfig,
    /// Give the signature check the threshold baseline's registration hypotheses beside the sample's (the
    /// imprint's own contact as further proposals; default true): where the imprint says more than one sample
    /// (small, shallow contacts) its pose can win. `tnd eval` then scores it as a row of its own.
    pub imprint_proposals: bool,
    /// How the signature check's evidence becomes a pose posterior ([`crate::pose::posterior`]).
    pub posterior: PosteriorConfig,
}

impl Default for EvalConfig {
    fn default() -> Self {
        Self {
            depth: DepthMetricsConfig::default(),
            registration: SdfRegistrationConfig::default(),
            free_space: FreeSpaceConfig::default(),
            baseline: BaselineConfig::default(),
            inits: 10,
            init_radius_m: 0.01,
            chamfer_points: 1000,
            pose_samples: 1,
            consensus_probability: 0.5,
            anchor_to_signature: true,
            check_signature: true,
            signature_check: SignatureCheckConfig::default(),
            imprint_proposals: true,
            posterior: PosteriorConfig::default(),
        }
    }
}

/// An object prepared for registration and scoring.
pub struct ObjectModel {
    pub registration: SdfRegistration,
    /// Surface samples (object frame) for the Chamfer distance.
    pub cloud: Vec<DVec3>,
    pub symmetry: Symmetry,
    /// Ray caster of the mesh (object frame) for the signature check.
    pub caster: RayCaster,
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

/// Runs the evaluation; caches one [`ObjectModel`] per object.
pub struct Evaluator {
    pub config: EvalConfig,
    objects: Mutex<HashMap<String, Arc<ObjectModel>>>,
}

impl Evaluator {
    pub fn new(config: EvalConfig) -> Self {
        Self {
            config,
            objects: Mutex::new(HashMap::new()),
        }
    }

    /// The prepared object `name` of `set` (built on first use).
    pub fn object(&self, set: &ObjectSet, name: &str) -> Result<Arc<ObjectModel>, EvalError> {
        if let Some(m) = self.objects.lock().ok().and_then(|m| m.get(name).cloned()) {
            return Ok(m);
        }
        let mesh = set.mesh(name)?;
        let symmetry = set.find(name).map(|e| e.symmetry).unwrap_or_default();
        self.object_from_mesh(name, &mesh, symmetry)
    }

    /// Prepare (and cache under `name`) an object given by its mesh (object frame, resting pose) and symmetry.
    pub fn object_from_mesh(
        &self,
        name: &str,
        mesh: &Mesh,
        symmetry: Symmetry,
    ) -> Result<Arc<ObjectModel>, EvalError> {
        let registration =
            SdfRegistration::new(mesh, self.config.registration.clone()).map_err(|source| {
                EvalError::Pose {
                    object: name.to_string(),
                    source,
                }
            })?;
        let caster = RayCaster::new(mesh)?;
        let model = Arc::new(ObjectModel {
            registration,
            cloud: sample_surface(mesh, self.config.chamfer_points, 0),
            symmetry,
            caster,
        });
        if let Ok(mut m) = self.objects.lock() {
            m.insert(name.to_string(), model.clone());
        }
        Ok(model)
    }

    /// Register `object` to an in-contact depth image: every hypothesis, best first; `None` without contact
    /// ([`crate::pose::from_depth::register_depth`] with this evaluator's free-space settings).
    pub fn register_depth(
        &self,
        object: &ObjectModel,
        x0: &Image,
        ctx: &EvalContext,
        t_world_camera: &DAffine3,
        strategy: &InitStrategy,
        seed: u64,
    ) -> Result<Option<Vec<Hypothesis>>, PoseError> {
        let view = SensorView {
            intrinsics: &ctx.intrinsics,
            membrane: &ctx.membrane,
            t_world_camera,
        };
        crate::pose::from_depth::register_depth(
            &object.registration,
            x0,
            &view,
            &self.config.free_space,
            strategy,
            seed,
        )
    }

    /// The estimates `samples` as registered: with [`EvalConfig::anchor_to_signature`] and a signature, each one's
    /// contact depths moved onto it where the imprint says contact ([`anchor_to_signature`]), with the shifts (metres); otherwise unchanged, with
    /// no shifts.
    pub fn anchor(
        &self,
        samples: &[Image],
        signature: Option<&Image>,
        imprint: &Image,
    ) -> Result<(Vec<Image>, Vec<f64>), PoseError> {
        match signature {
            Some(s) if self.config.anchor_to_signature => samples
                .iter()
                .map(|x| anchor_to_signature(x, s, imprint))
                .collect(),
            _ => Ok((samples.to_vec(), Vec::new())),
        }
    }

    /// The depth metrics of `depth` and the hypotheses of registering every image of `registered` (each anchored as
    /// [`Self::anchor`]), pooled in that order.
    fn register_pair(
        &self,
        pair: &EvalPair,
        depth: &Image,
        registered: &[Image],
        ctx: &EvalContext,
        seed: u64,
    ) -> Result<Registered, EvalError> {
        let depth = depth_metrics(depth, &pair.target, &self.config.depth)?;
        let object = self.object(&ctx.objects, &pair.object)?;
        let strategy = self.random_starts(seed);
        let hypotheses = self
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

    /// The scores of a registration: its pose chosen by [`Self::choose`], with the signature check only when `check`
    /// (and [`EvalConfig::check_signature`]) allow it, and the pose errors against the truth.
    fn pose_result(
        &self,
        pair: &EvalPair,
        ctx: &EvalContext,
        r: &Registered,
        check: bool,
    ) -> Result<MethodResult, EvalError> {
        let measured = Some((&pair.signature, &pair.imprint)).filter(|_| check);
        let chosen = self
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
        let n = self.config.pose_samples.max(1);
        let samples = generator.generate(&pair, ctx, n, pair_seed).map_err(fail)?;
        let first = samples
            .first()
            .ok_or_else(|| fail(EvalError::Generator("returned no sample".into())))?;
        observe(i, &pair, &samples);
        let model_reg = self
            .register_pair(&pair, first, std::slice::from_ref(first), ctx, pair_seed)
            .map_err(fail)?;
        let model = self
            .pose_result(&pair, ctx, &model_reg, true)
            .map_err(fail)?;
        // The baseline as the paper defines it (its registration's best hypothesis), and with the signature check.
        let base_x0 = threshold_contact(&pair.signature, &pair.imprint, &self.config.baseline);
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
            let consensus =
                consensus_depth(&samples, self.config.consensus_probability).map_err(|source| {
                    fail(EvalError::Pose {
                        object: object.clone(),
                        source,
                    })
                })?;
            let mut registered = vec![consensus.clone()];
            if self.config.check_signature {
                registered.extend(samples.iter().cloned());
            }
            let mut pooled = self
                .register_pair(&pair, &consensus, &registered, ctx, pair_seed)
                .map_err(fail)?;
            // The imprint's hypotheses as registered for the baseline (same starts, same seed) close the pool.
            if self.config.check_signature && self.config.imprint_proposals {
                pooled.hypotheses.extend_from_slice(&base.hypotheses);
            }
            Some(self.pose_result(&pair, ctx, &pooled, true).map_err(fail)?)
        } else {
            None
        };
        let baseline = self.pose_result(&pair, ctx, &base, false).map_err(fail)?;
        let checks = self.config.check_signature && ctx.signature_model.is_some();
        let combine = checks && self.config.imprint_proposals;
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
