//! What the Pose tab shows (paper IV.C registration, V.D uncertainty): the object's top-view outline, the registered
//! hypotheses with their costs, the contact points, and the evaluation stage's [`UncertaintyReport`] (each sample's
//! pose error, the threshold baseline's, the KDE curves). The numbers come from [`crate::pose_job`].

use tactile_derender::pose::Hypothesis;
use tactile_derender::sensor::Se2;
use tactile_derender::uncertainty::UncertaintyReport;

pub use tactile_derender::pose::outline::{outline, placed_mm, Outline};

/// Everything the Pose tab shows for one run.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PoseAnalysis {
    pub object: String,
    /// Top-view outline in the object frame.
    pub outline: Vec<Outline>,
    /// True pose, when known (simulated scenes, dataset pairs).
    pub truth: Option<Se2>,
    /// The sample whose K-start registration gave `hypotheses` (the first with contact).
    pub registered_sample: usize,
    /// Hypotheses of that registration, best first.
    pub hypotheses: Vec<Hypothesis>,
    /// The imprint's proposals the signature check scored beside them
    /// ([`tactile_derender::pipeline::PoseEstimate::imprint_hypotheses`]).
    pub imprint_hypotheses: Vec<Hypothesis>,
    /// The single-sample estimate after the signature check (the hypothesis that best explains the measured
    /// signature, refined); `None` when the check did not run.
    pub checked: Option<Se2>,
    /// The check's pick came from the imprint's threshold contact, not the sample.
    pub checked_from_imprint: bool,
    /// The check's best other pose ([`tactile_derender::pipeline::PoseEstimate::signature_rival`]).
    pub signature_rival: Option<tactile_derender::pose::signature_check::Rival>,
    /// What the signature supports: weighted modes with covariances
    /// ([`tactile_derender::pipeline::PoseEstimate::posterior`]).
    pub posterior: Option<tactile_derender::pose::posterior::PosePosterior>,
    /// The object's symmetry (how the posterior's θ wraps).
    pub symmetry: tactile_derender::objects::Symmetry,
    /// The posterior's smallest region holding the truth, when it is known (≤ p: inside the p region).
    pub truth_region: Option<f64>,
    /// Its contact points (back-projected X̂0), world frame, metres.
    pub contacts: Vec<[f64; 2]>,
    /// Per-sample errors (from the fixed start), baseline errors and KDE curves.
    pub report: UncertaintyReport,
    /// The sample index of each entry of `report.samples` (samples without contact are not registered).
    pub sample_index: Vec<usize>,
    /// Per sample, the depth shift that anchored it onto the signature before registration, metres (empty: none).
    pub anchor_shift_m: Vec<f64>,
    /// What the analysis registered, for exporting its geometry.
    pub inputs: Option<Box<crate::pose_job::PoseRequest>>,
    /// The press found from the samples where it was not known ([`crate::derender::PoseContext::find_press`]),
    /// metres.
    pub press_found_m: Option<f64>,
}

impl PoseAnalysis {
    /// The single-sample estimate: the signature check's pick, else the best hypothesis.
    pub fn single_estimate(&self) -> Option<Se2> {
        self.checked
            .or_else(|| self.hypotheses.first().map(|h| h.pose))
    }

    /// The sample index of `report.samples[k]`.
    pub fn sample_of(&self, k: usize) -> Option<usize> {
        self.sample_index.get(k).copied()
    }
}
