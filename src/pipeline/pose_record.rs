//! **pose.json**: one signature's pose estimate as a typed record — what `tnd pose` writes and prints and the
//! workbench's Pose export writes, field by field the same. Lengths in metres, angles in radians, errors in mm and
//! degrees (as named); poses are `t_world_object` in [`crate::sensor::POSE_FRAME_ID`] (docs/uncertainty.md lists
//! every field).

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::pose::{GeometryFile, PlacedEstimate};
use super::PipelineError;
use crate::objects::Symmetry;
use crate::pose::export::{LocatedEstimate, ObjectTransform, PoseWithCovarianceStamped};
use crate::pose::posterior::PosePosterior;
use crate::pose::signature_check::Rival;
use crate::pose::Hypothesis;
use crate::recording::calibrate::SensorCalibration;
use crate::sensor::Se2;
use crate::uncertainty::{FailedRegistration, PoseMode, SampleError};

/// The reported estimate's error against the true pose.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct EstimateError {
    /// Position error, mm (the symmetry's free translation axis excluded).
    pub position_mm: f64,
    /// θ error, degrees, wrapped to the symmetry period (`None`: θ is free under the symmetry).
    pub theta_deg: Option<f64>,
}

/// Where the estimate came from: what the record alone cannot say.
#[derive(Clone, Debug, Default)]
pub struct RecordSource {
    /// The generator of the samples, in words (a model file and its sampler, or `ground-truth`).
    pub generator: String,
    /// The seed of the sampler and the registrations.
    pub seed: u64,
    /// The calibration the sensor came from, when the input was calibrated from its own reference frames.
    pub calibration: Option<SensorCalibration>,
    /// The folder the outputs went to.
    pub out: PathBuf,
    /// The rerun recording written beside them, if any.
    pub rerun: Option<PathBuf>,
    /// The geometry files written beside them (PLY).
    pub geometry: Vec<GeometryFile>,
}

/// pose.json (module docs).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PoseRecord {
    /// The object's name.
    pub object: String,
    /// [`RecordSource::generator`].
    pub generator: String,
    /// [`RecordSource::rerun`].
    pub rerun: Option<PathBuf>,
    /// Samples registered from the estimate (those with contact that registered).
    pub samples: usize,
    /// [`RecordSource::seed`].
    pub seed: u64,
    /// The press the sensor was placed at (found or given), metres; 0 for a known camera pose.
    pub press_m: f64,
    /// The pose reported: the signature check's pick (the fused posterior's top mode in a track), else the best
    /// hypothesis of the first registration.
    pub estimate: Option<Se2>,
    /// Its error against `truth`, when known.
    pub estimate_error: Option<EstimateError>,
    /// The signature check ran.
    pub signature_checked: bool,
    /// The check's pick came from the imprint's threshold contact, not a sample.
    pub checked_from_imprint: bool,
    /// The first registration's best hypothesis: where every sample's registration starts.
    pub best_hypothesis: Option<Se2>,
    /// The first registration (of sample `registered_sample`) from K starts: every hypothesis, best first, with its
    /// start, cost (registration cost, lower is better) and iterations.
    #[serde(default)]
    pub hypotheses: Vec<Hypothesis>,
    /// The imprint's threshold contact registered from the same starts: the proposals the check scored beside them.
    #[serde(default)]
    pub imprint_hypotheses: Vec<Hypothesis>,
    /// The sample whose registration gave `hypotheses`.
    #[serde(default)]
    pub registered_sample: usize,
    /// The multi-sample estimate's pose (two or more samples).
    pub estimate_multi_sample: Option<Se2>,
    /// The true pose, when given.
    pub truth: Option<Se2>,
    /// The threshold baseline registered from the estimate, with its errors.
    pub baseline: Option<SampleError>,
    /// The multi-sample estimate with its errors.
    pub multi_sample: Option<SampleError>,
    /// Registrations that failed; the rest stands without them.
    pub failed: Vec<FailedRegistration>,
    /// [`RecordSource::geometry`].
    pub geometry: Vec<GeometryFile>,
    /// The samples split between poses the contact cannot tell apart, or the signature explains a rival as well.
    pub ambiguous: bool,
    /// The poses the registered samples fall into, most samples first.
    pub modes: Vec<PoseMode>,
    /// The check's best other pose and how much worse it explains the signature.
    pub signature_rival: Option<Rival>,
    /// Per sample, the depth shift that anchored it onto the signature, metres (empty: not anchored).
    pub anchor_shift_m: Vec<f64>,
    /// Per registered sample, its position error (against the truth, else the first registration's best), mm.
    pub position_err_mm: Vec<f64>,
    /// [`RecordSource::calibration`].
    pub calibration: Option<SensorCalibration>,
    /// [`RecordSource::out`].
    pub out: PathBuf,
    /// The pose posterior: weighted modes with covariances.
    pub posterior: Option<PosePosterior>,
    /// The probability mass of the posterior's smallest region holding the truth, when it is known.
    pub truth_region: Option<f64>,
    /// Half-widths of the central intervals about the estimate's mode holding 68 % of it — x, y (metres), θ
    /// (radians; [`crate::pose::posterior::PosteriorMode::half_widths`]): its spread read as a Gaussian's ±σ, which
    /// heavy tails make far narrower than the covariance's standard deviation.
    #[serde(default)]
    pub half_width_68: Option<[f64; 3]>,
    /// The estimate as a 4x4 transform (with an estimate and a posterior).
    pub transform: Option<ObjectTransform>,
    /// The estimate as a ROS `PoseWithCovarianceStamped`, the covariance the posterior's about it.
    pub pose_with_covariance: Option<PoseWithCovarianceStamped>,
}

impl PoseRecord {
    /// The record of `placed` for an object of `symmetry` with the true pose `truth` (when known).
    pub fn new(
        placed: &PlacedEstimate,
        truth: Option<Se2>,
        symmetry: &Symmetry,
        source: RecordSource,
    ) -> Self {
        let estimate = &placed.estimate;
        let report = &estimate.report;
        let best = estimate.best();
        let located = LocatedEstimate::new(best, estimate.posterior.as_ref(), symmetry, 0);
        let (transform, pose_with_covariance) = match located {
            Some(l) => (Some(l.transform), Some(l.ros)),
            None => (None, None),
        };
        // The other estimates as the symmetric equivalents nearest the estimate (the same poses; no 90° jump
        // between a 4-fold object's estimate and its multi-sample estimate).
        let beside = |e: Option<SampleError>| {
            e.map(|mut e| {
                if let Some(b) = best {
                    e.pose = symmetry.nearest_equivalent(e.pose, b.theta);
                }
                e
            })
        };
        let (multi_sample, baseline) = (beside(report.multi_sample), beside(report.baseline));
        Self {
            object: estimate.object.clone(),
            generator: source.generator,
            rerun: source.rerun,
            samples: report.samples.len(),
            seed: source.seed,
            press_m: placed.press_m.unwrap_or_default(),
            estimate: best,
            estimate_error: truth.zip(best).map(|(t, b)| {
                let e = SampleError::new(b, 0.0, t, symmetry);
                EstimateError {
                    position_mm: e.position_mm,
                    theta_deg: e.theta_deg,
                }
            }),
            signature_checked: estimate.checked.is_some(),
            checked_from_imprint: estimate.checked_from_imprint,
            best_hypothesis: estimate.hypotheses.first().map(|h| h.pose),
            hypotheses: estimate.hypotheses.clone(),
            imprint_hypotheses: estimate.imprint_hypotheses.clone(),
            registered_sample: estimate.registered_sample,
            estimate_multi_sample: multi_sample.map(|m| m.pose),
            truth,
            baseline,
            multi_sample,
            failed: report.failed.clone(),
            geometry: source.geometry,
            ambiguous: report.ambiguous() || estimate.signature_ambiguous(),
            modes: report.major_modes(),
            signature_rival: estimate.signature_rival,
            anchor_shift_m: estimate.anchor_shift_m.clone(),
            position_err_mm: report.samples.iter().map(|s| s.position_mm).collect(),
            calibration: source.calibration,
            out: source.out,
            posterior: estimate.posterior.clone(),
            truth_region: estimate.truth_region,
            half_width_68: best
                .zip(estimate.posterior.as_ref())
                .and_then(|(b, p)| p.estimate_half_widths(b, symmetry)),
            transform,
            pose_with_covariance,
        }
    }

    /// The ROS message alone (`pose_with_covariance.json`).
    pub fn located(&self) -> Option<&PoseWithCovarianceStamped> {
        self.pose_with_covariance.as_ref()
    }

    /// Write the record to `path` as pretty JSON, atomically.
    pub fn write(&self, path: &Path) -> Result<(), PipelineError> {
        let text = serde_json::to_string_pretty(self).map_err(|e| PipelineError::Write {
            path: path.to_path_buf(),
            source: std::io::Error::other(e),
        })?;
        crate::io::write_atomic(path, text.as_bytes()).map_err(|source| PipelineError::Write {
            path: path.to_path_buf(),
            source,
        })
    }

    /// Read a record `tnd pose` wrote; a file that is not one is named with the problem.
    pub fn read(path: &Path) -> Result<Self, PipelineError> {
        let text = std::fs::read_to_string(path).map_err(|source| PipelineError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        serde_json::from_str(&text).map_err(|e| PipelineError::Format {
            path: path.to_path_buf(),
            problem: format!("not a pose.json record: {e}"),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_file_that_is_not_a_record_is_named_with_the_problem() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("pose.json");
        std::fs::write(&path, r#"{"object": "cube"}"#).unwrap();
        let e = crate::error::render(&PoseRecord::read(&path).unwrap_err());
        assert!(
            e.contains("pose.json")
                && e.contains("not a pose.json record")
                && e.contains("missing field"),
            "{e}"
        );
        let missing = dir.path().join("missing.json");
        let e = crate::error::render(&PoseRecord::read(&missing).unwrap_err());
        assert!(
            e.contains("missing.json") && e.contains("cannot read"),
            "{e}"
        );
    }
}
