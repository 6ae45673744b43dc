//! **Metrics** of the evaluation (paper V.C Table I, V.D Table II): depth-image metrics of a generated in-contact
//! depth against the true one ([`depth`], [`ssim`]) and pose metrics with the objects' symmetry exclusions
//! ([`pose`]); [`summary`] aggregates them into mean/std rows; [`evaluate`] runs the whole loop over a
//! [`evaluate::PairSource`] ([`sources`]: dataset splits, simulated pairs) with a [`evaluate::Generator`];
//! [`paper_table`] sets runs side by side in the paper's layout and units; [`saved_samples`] keeps each pair's
//! samples for analysis; [`eval_log`] keeps every pair's scores as they come, so that a killed run resumes;
//! [`coverage`] scores and fits the pose posterior, [`reliability_figure`] draws how it forecasts.

pub mod breakdown;
pub mod coverage;
pub mod depth;
pub mod eval_log;
pub mod evaluate;
pub mod model_generator;
pub mod nelder_mead;
pub mod paper_table;
pub mod pose;
pub mod reliability_figure;
pub mod report;
pub mod saved_samples;
pub mod sources;
pub mod ssim;
pub mod summary;

pub use depth::{depth_metrics, DepthMetrics, DepthMetricsConfig};
pub use pose::{chamfer_unidirectional, pose_errors, PoseErrors};
pub use ssim::{ssim, SsimConfig};
pub use summary::{MeanStd, Summary};

/// Errors of the metrics; each names the problem.
#[derive(Debug, thiserror::Error)]
pub enum MetricsError {
    #[error("images differ in size: {a_w}x{a_h} vs {b_w}x{b_h}")]
    SizeMismatch {
        a_w: usize,
        a_h: usize,
        b_w: usize,
        b_h: usize,
    },
    #[error("image is empty (0 pixels)")]
    Empty,
    #[error("data range must be positive and finite, got {0}")]
    DataRange(f64),
    #[error(
        "SSIM needs images of at least {need}x{need} pixels (the Gaussian window), got {w}x{h}"
    )]
    TooSmall { need: usize, w: usize, h: usize },
    #[error("point cloud is empty")]
    EmptyCloud,
}

pub(crate) fn check_same_size(
    a: &crate::image::Image,
    b: &crate::image::Image,
) -> Result<(), MetricsError> {
    if (a.width, a.height) != (b.width, b.height) {
        return Err(MetricsError::SizeMismatch {
            a_w: a.width,
            a_h: a.height,
            b_w: b.width,
            b_h: b.height,
        });
    }
    if a.data.is_empty() {
        return Err(MetricsError::Empty);
    }
    Ok(())
}
