//! What the **evaluation loop** behind the paper's Tables I and II (V.C, V.D) works on: pairs from a [`PairSource`],
//! a [`Generator`] of the in-contact depth X̂0 (the model, or the ground truth as the ideal generator), the settings
//! ([`EvalConfig`]) and the records. The loop itself, which runs the pose sequence `tnd pose` runs on every pair, is
//! `pipeline::evaluate::Evaluator` (it sits above the pose use case).

use glam::DAffine3;
use serde::{Deserialize, Serialize};

use super::depth::DepthMetricsConfig;
use super::MetricsError;
use crate::image::Image;
use crate::objects::ObjectError;
use crate::pose::{PoseConfig, PoseError, SensorContext};
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

/// The seed of pair `i` of a source (its sampler and registration starts) in a run seeded with `seed`: a pair scores
/// the same whichever pairs are scored beside it, so a resumed run equals an uninterrupted one.
pub fn pair_seed(seed: u64, i: usize) -> u64 {
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
    }
}
