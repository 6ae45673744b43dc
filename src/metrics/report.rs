//! **What the evaluation reports**: each method's scores on one pair ([`MethodResult`], with its pose posterior),
//! a pair's record of every method ([`PairRecord`], one line of `tnd eval --records`), the pairs that failed, and the
//! Table I / II rows of a whole source ([`MethodSummary`], [`EvalReport`]) with its breakdown.

use serde::{Deserialize, Serialize};

use super::depth::DepthMetrics;
use super::pose::PoseErrors;
use super::summary::MeanStd;
use crate::objects::Symmetry;
use crate::pose::posterior::PosePosterior;
use crate::sensor::Se2;

/// Scores of one method on one pair.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MethodResult {
    pub depth: DepthMetrics,
    /// Best registered pose; `None` when the method found no contact.
    pub estimate: Option<Se2>,
    /// Pose errors of `estimate`.
    pub pose: Option<PoseErrors>,
    /// The pose posterior where the signature check ran ([`crate::pose::posterior`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub posterior: Option<PosePosterior>,
    /// The probability mass of the posterior's smallest region holding the truth
    /// ([`PosePosterior::region_mass`]): the truth is inside the reported p region when this is ≤ p.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub truth_region: Option<f64>,
}

/// Draws of the Monte Carlo integral of [`PosePosterior::region_mass`] in the evaluation (±0.5 % at 90 %).
pub const REGION_DRAWS: usize = 4000;

/// Both methods on one pair.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PairRecord {
    pub name: String,
    pub object: String,
    pub truth: Se2,
    /// Pixels in contact in the true X0 (the contact-size bins of the breakdown).
    #[serde(default)]
    pub contact_pixels: usize,
    /// The object's symmetry (how its pose errors and posterior regions are reduced).
    #[serde(default)]
    pub symmetry: Symmetry,
    /// The model's first sample.
    pub model: MethodResult,
    /// The model's multi-sample estimate (with [`EvalConfig::pose_samples`](super::evaluate::EvalConfig::pose_samples) > 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model_multi: Option<MethodResult>,
    /// The model's first sample with the threshold baseline's hypotheses as further proposals, chosen by the
    /// signature check ([`EvalConfig::check_signature`](super::evaluate::EvalConfig::check_signature)): where the imprint alone says more than the sample
    /// (small, shallow contacts) its pose can win. `None` without the check.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model_combined: Option<MethodResult>,
    /// The threshold baseline as the paper defines it (no signature check).
    pub baseline: MethodResult,
    /// The threshold baseline's registration with the signature check ([`EvalConfig::check_signature`](super::evaluate::EvalConfig::check_signature)), so that
    /// what the check alone gives is in every report.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub baseline_checked: Option<MethodResult>,
}

/// A pair that could not be scored, and why; the evaluation goes on without it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FailedPair {
    /// Pair name (or its index in the source when even reading it failed).
    pub name: String,
    /// Object name, when known.
    pub object: String,
    /// The error, said once.
    pub reason: String,
}

/// Table I and Table II rows of one method (mean ± population std), with exclusion counts.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MethodSummary {
    pub l1_mm: MeanStd,
    pub l1_union_mm: MeanStd,
    pub psnr_db: MeanStd,
    pub ssim: MeanStd,
    pub position_mm: MeanStd,
    pub theta_rad: MeanStd,
    pub chamfer_m2: MeanStd,
    /// Pairs where the method found no contact (no pose: excluded from Table II).
    pub no_contact: usize,
    /// Pairs whose θ error is excluded (continuous rotational symmetry).
    pub theta_excluded_symmetry: usize,
    /// Pairs whose position error excludes a translation axis (lying cylinders, prisms).
    pub position_axis_excluded: usize,
    /// How often the truth lies inside the posterior's regions ([`super::coverage`]), where the method has one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub coverage: Option<super::coverage::Coverage>,
}

impl MethodSummary {
    /// Aggregate per-pair results.
    pub fn of<'a>(results: impl Iterator<Item = &'a MethodResult> + Clone) -> Self {
        let poses = results.clone().filter_map(|r| r.pose);
        Self {
            l1_mm: MeanStd::of(results.clone().map(|r| Some(r.depth.l1_mm))),
            l1_union_mm: MeanStd::of(results.clone().map(|r| r.depth.l1_union_mm)),
            psnr_db: MeanStd::of(results.clone().map(|r| Some(r.depth.psnr_db))),
            ssim: MeanStd::of(results.clone().map(|r| Some(r.depth.ssim))),
            position_mm: MeanStd::of(results.clone().map(|r| r.pose.map(|p| p.position_mm))),
            theta_rad: MeanStd::of(results.clone().map(|r| r.pose.and_then(|p| p.theta_rad))),
            chamfer_m2: MeanStd::of(results.clone().map(|r| r.pose.map(|p| p.chamfer_m2))),
            no_contact: results.clone().filter(|r| r.pose.is_none()).count(),
            theta_excluded_symmetry: poses.clone().filter(|p| p.theta_rad.is_none()).count(),
            position_axis_excluded: poses.filter(|p| p.position_axis_excluded).count(),
            coverage: super::coverage::Coverage::of(
                results.filter_map(|r| Some((r.truth_region?, r.pose?.position_mm))),
            ),
        }
    }
}

/// The evaluation of one source.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EvalReport {
    pub generator: String,
    /// Pairs scored (failed pairs are not counted here).
    pub pairs: usize,
    pub model: MethodSummary,
    /// The multi-sample estimate's rows (with [`EvalConfig::pose_samples`](super::evaluate::EvalConfig::pose_samples) > 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model_multi: Option<MethodSummary>,
    /// The model with the baseline's proposals (when the check ran; [`PairRecord::model_combined`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model_combined: Option<MethodSummary>,
    pub baseline: MethodSummary,
    /// The baseline with the signature check (when it ran).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub baseline_checked: Option<MethodSummary>,
    /// Model / baseline mean position error and its 95 % paired bootstrap interval (`None` under 2 pairs with
    /// poses); the same for the multi-sample estimate.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub position_ratio_ci95: Option<[f64; 2]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub position_ratio_multi_ci95: Option<[f64; 2]>,
    /// The same for the model with the baseline's proposals.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub position_ratio_combined_ci95: Option<[f64; 2]>,
    /// Per contact-size bin and per object.
    #[serde(default)]
    pub breakdown: super::breakdown::Breakdown,
    pub records: Vec<PairRecord>,
    /// Pairs that could not be scored.
    #[serde(default)]
    pub failed: Vec<FailedPair>,
}

impl EvalReport {
    /// Summarise scored records and failures.
    pub fn new(generator: String, records: Vec<PairRecord>, failed: Vec<FailedPair>) -> Self {
        // All pairs as one group: the same rows as each group of the breakdown.
        let all: Vec<&PairRecord> = records.iter().collect();
        let rows = super::breakdown::GroupSummary::of(String::new(), &all);
        Self {
            generator,
            pairs: records.len(),
            model: rows.model,
            model_multi: rows.model_multi,
            model_combined: rows.model_combined,
            baseline: rows.baseline,
            baseline_checked: rows.baseline_checked,
            position_ratio_ci95: rows.position_ratio_ci95,
            position_ratio_multi_ci95: rows.position_ratio_multi_ci95,
            position_ratio_combined_ci95: rows.position_ratio_combined_ci95,
            breakdown: super::breakdown::Breakdown::of(&records),
            records,
            failed,
        }
    }
}
