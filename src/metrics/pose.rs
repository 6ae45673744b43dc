//! **Pose metrics** (paper V.D, Table II) of an estimated SE(2) pose against the true one, with the exclusions that the
//! object's symmetry tags ([`crate::objects::Symmetry`]) call for:
//!
//! * `position_mm`: ‖(x̂, ŷ) − (x, y)‖ in mm. For objects with a translation axis `a` (object frame; lying cylinders
//!   and prisms), the component of the error along the axis in the world, `R(θ) a` with the **true** θ, is removed
//!   first: the position along it is ambiguous.
//! * `theta_rad`: |θ̂ − θ| wrapped to [0, π]; for n-fold symmetry, the distance to the nearest multiple of 2π/n (in
//!   [0, π/n]); `None` (excluded) for continuous rotational symmetry.
//! * `chamfer_m2`: unidirectional Chamfer distance CD(P1, P2) = (1/|P1|) Σ_{p∈P1} min_{q∈P2} ‖p − q‖², in m², with
//!   P1 / P2 one point cloud sampled on the object's surface (object frame) moved by the estimated / true pose. It
//!   needs no symmetry handling: a symmetric object's clouds coincide.

use glam::DVec3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::MetricsError;
use crate::objects::{RotationSymmetry, Symmetry};
use crate::sensor::Se2;

/// Pose errors of one estimate (definitions in the module docs).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PoseErrors {
    /// Position error, mm (component along an ambiguous axis removed).
    pub position_mm: f64,
    /// Whether a translation axis was excluded from `position_mm`.
    pub position_axis_excluded: bool,
    /// Orientation error, rad, modulo the symmetry (`None`: continuous symmetry, excluded).
    pub theta_rad: Option<f64>,
    /// Unidirectional Chamfer distance, m².
    pub chamfer_m2: f64,
}

/// Position error in metres with the symmetry's translation axis removed (see the module docs).
pub fn position_error_m(estimate: Se2, truth: Se2, symmetry: &Symmetry) -> f64 {
    let mut d = glam::DVec2::new(estimate.x - truth.x, estimate.y - truth.y);
    if let Some([ax, ay]) = symmetry.translation_axis {
        let a = glam::DVec2::new(ax, ay);
        if a.length_squared() > 0.0 {
            let a_world = glam::DVec2::from_angle(truth.theta).rotate(a.normalize());
            d -= a_world * d.dot(a_world);
        }
    }
    d.length()
}

/// Orientation error in radians modulo the rotational symmetry; `None` for continuous symmetry.
pub fn theta_error_rad(estimate: Se2, truth: Se2, rotation: RotationSymmetry) -> Option<f64> {
    let period = rotation.period_rad()?;
    let e = (estimate.theta - truth.theta).rem_euclid(period);
    Some(e.min(period - e))
}

/// CD(P1, P2): mean over `p1` of the squared distance to the nearest point of `p2`, m² (brute force, parallel).
pub fn chamfer_unidirectional(p1: &[DVec3], p2: &[DVec3]) -> Result<f64, MetricsError> {
    if p1.is_empty() || p2.is_empty() {
        return Err(MetricsError::EmptyCloud);
    }
    // Nearest distances in parallel, summed in order: a parallel sum's order (and its last bit) would vary from
    // run to run.
    let nearest: Vec<f64> = p1
        .par_iter()
        .map(|p| {
            p2.iter()
                .map(|q| p.distance_squared(*q))
                .fold(f64::INFINITY, f64::min)
        })
        .collect();
    Ok(nearest.iter().sum::<f64>() / p1.len() as f64)
}

/// All pose errors of `estimate` against `truth` for an object with `symmetry` and surface samples `cloud_obj`
/// (object frame, metres; see [`crate::pose::sample_surface`]).
pub fn pose_errors(
    estimate: Se2,
    truth: Se2,
    symmetry: &Symmetry,
    cloud_obj: &[DVec3],
) -> Result<PoseErrors, MetricsError> {
    let t_est = estimate.to_affine();
    let t_true = truth.to_affine();
    let p1: Vec<DVec3> = cloud_obj
        .iter()
        .map(|&p| t_est.transform_point3(p))
        .collect();
    let p2: Vec<DVec3> = cloud_obj
        .iter()
        .map(|&p| t_true.transform_point3(p))
        .collect();
    Ok(PoseErrors {
        position_mm: position_error_m(estimate, truth, symmetry) * 1e3,
        position_axis_excluded: symmetry.translation_axis.is_some(),
        theta_rad: theta_error_rad(estimate, truth, symmetry.rotation),
        chamfer_m2: chamfer_unidirectional(&p1, &p2)?,
    })
}
