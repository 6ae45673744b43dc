//! **SE(2) pose estimation** (paper IV.C, V.D): the object signed distance ([`sdf`], [`sdf_grid`]), registration of
//! the object to reconstructed contact points with free-space evidence ([`register`]: the [`Registration`] trait and
//! its driver; [`sdf_register`]: the CHSEL-inspired Gauss–Newton/Levenberg–Marquardt implementation), and the
//! threshold baseline ([`baseline`]); the pose engine that runs them on depth estimates ([`estimator`]: anchoring,
//! registration, hypotheses; [`choose`]: the signature check's pick and the posterior).
//!
//! Poses are [`crate::sensor::Se2`] `t_world_object`: the object's resting frame placed at `(x, y)` with yaw `theta`
//! about the table normal, metres and radians.

pub mod baseline;
pub mod camera_path;
pub mod choose;
pub mod estimator;
pub mod export;
pub mod figure;
pub mod from_depth;
pub mod fusion;
pub mod mat3;
pub mod outline;
pub mod posterior;
pub mod posterior_config;
pub mod register;
pub mod sdf;
pub mod sdf_grid;
pub mod sdf_register;
pub mod signature_check;

pub use crate::mesh::sample_surface;
pub use baseline::{threshold_contact, BaselineConfig};
pub use estimator::{Estimator, ObjectModel, PoseConfig, PosePrior, SensorContext};
pub use register::{
    initial_poses, register, Hypothesis, InitStrategy, Registration, RegistrationProblem,
};

/// Poses this close (position mm, θ degrees, both reduced by the object's symmetry) are one pose: the samples of a
/// signature that register within it form one mode, and the signature check's alternative must lie beyond it.
pub const MODE_POSITION_MM: f64 = 2.0;
/// See [`MODE_POSITION_MM`].
pub const MODE_THETA_DEG: f64 = 15.0;
pub use sdf::{ExactSdf, ObjectSdf};
pub use sdf_grid::{ExactOnGrid, SdfGrid, SdfGridConfig};
pub use sdf_register::{RobustLoss, SdfRegistration, SdfRegistrationConfig};

/// Errors of the pose stage; each says what to change.
#[derive(Debug, thiserror::Error)]
pub enum PoseError {
    #[error("object mesh: {0}")]
    TriMesh(#[from] parry3d::shape::TriMeshBuilderError),
    #[error("{0}")]
    Config(String),
    #[error("no contact points to register (the contact region is empty); nothing to estimate a pose from")]
    NoContact,
    #[error("{what} contains a non-finite value at index {index}")]
    NonFinite { what: &'static str, index: usize },
    #[error(transparent)]
    Object(#[from] crate::objects::ObjectError),
    #[error(transparent)]
    Mesh(#[from] crate::mesh::MeshError),
}

/// Check settings: each of `positive` finite and > 0, each of `non_negative` finite and >= 0; the error names the
/// first that is not, after `prefix` (e.g. `"signature check: "`).
pub(crate) fn check_settings(
    prefix: &str,
    positive: &[(&str, f64)],
    non_negative: &[(&str, f64)],
) -> Result<(), PoseError> {
    for &(name, v) in positive {
        if !(v.is_finite() && v > 0.0) {
            return Err(PoseError::Config(format!(
                "{prefix}{name} must be positive, got {v}"
            )));
        }
    }
    for &(name, v) in non_negative {
        if !(v.is_finite() && v >= 0.0) {
            return Err(PoseError::Config(format!(
                "{prefix}{name} must be >= 0, got {v}"
            )));
        }
    }
    Ok(())
}
