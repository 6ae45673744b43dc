//! **The estimate as other tools take it**: a 4x4 homogeneous transform and a ROS
//! `geometry_msgs/PoseWithCovarianceStamped`-shaped message whose covariance comes from the pose posterior
//! ([`super::posterior`]).
//!
//! Frames: `t_world_object` maps points of the object's mesh, in its own frame as loaded and placed in its resting
//! pose (the bounding-box centre over the origin, lowest point on z = 0), into the world frame: the table plane is
//! z = 0, z points up, and the sensor pressed from above. The planar pose fixes z, roll and pitch; their variances
//! in the message are [`FIXED_VARIANCE`].

use serde::{Deserialize, Serialize};

use super::posterior::{reduced_difference, Mat3, PosePosterior};
use crate::objects::Symmetry;
use crate::sensor::Se2;

/// Variance given to z, roll and pitch, which the planar pose fixes (m², rad²): tiny, so that a consumer that
/// inverts the covariance can.
pub const FIXED_VARIANCE: f64 = 1e-12;

/// `t_world_object` as a row-major 4x4 matrix (metres).
pub fn transform_4x4(pose: Se2) -> [[f64; 4]; 4] {
    let (s, c) = pose.theta.sin_cos();
    [
        [c, -s, 0.0, pose.x],
        [s, c, 0.0, pose.y],
        [0.0, 0.0, 1.0, 0.0],
        [0.0, 0.0, 0.0, 1.0],
    ]
}

/// The covariance of `posterior` about `estimate` (x m, y m, θ rad): every mode's spread (core and tail,
/// [`super::posterior::PosteriorMode::spread_cov`]) plus the outer product of its mean's offset from the estimate (θ wrapped by the
/// symmetry period), weighted: a single Gaussian that keeps the other modes' spread. The far components (a pose no
/// hypothesis came near, θ anywhere) are left out: no Gaussian holds them; their share is in pose.json.
/// `None` without modes.
#[allow(clippy::needless_range_loop)] // a matrix's indices read best as indices
pub fn covariance_about(
    posterior: &PosePosterior,
    estimate: Se2,
    symmetry: &Symmetry,
) -> Option<Mat3> {
    if posterior.modes.is_empty() {
        return None;
    }
    let no_axis = Symmetry {
        translation_axis: None,
        ..*symmetry
    };
    let mut cov = [[0.0; 3]; 3];
    for m in &posterior.modes {
        let (e, _) = reduced_difference(m.pose(), estimate, &no_axis);
        let d = [e[0], e[1], e.get(2).copied().unwrap_or(0.0)];
        let spread = m.spread_cov();
        for i in 0..3 {
            for j in 0..=i {
                cov[i][j] += m.weight * (spread[i][j] + d[i] * d[j]);
            }
        }
    }
    super::posterior::mirror_lower(&mut cov);
    Some(cov)
}

/// `std_msgs/Header`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Header {
    pub stamp: Stamp,
    pub frame_id: String,
}

/// `builtin_interfaces/Time`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Stamp {
    pub sec: i64,
    pub nanosec: u32,
}

/// `geometry_msgs/Point`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Point {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}

/// `geometry_msgs/Quaternion`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Quaternion {
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub w: f64,
}

/// `geometry_msgs/Pose`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    pub position: Point,
    pub orientation: Quaternion,
}

/// `geometry_msgs/PoseWithCovariance`: covariance row-major over (x, y, z, rotation about x, y, z).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PoseWithCovariance {
    pub pose: Pose,
    pub covariance: Vec<f64>,
}

/// `geometry_msgs/PoseWithCovarianceStamped`, field for field.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PoseWithCovarianceStamped {
    pub header: Header,
    pub pose: PoseWithCovariance,
}

impl PoseWithCovarianceStamped {
    /// `pose` (`t_world_object`) with covariance `cov` over (x, y, θ), in `frame_id` at `stamp_ns` (nanoseconds).
    pub fn new(pose: Se2, cov: &Mat3, frame_id: &str, stamp_ns: u64) -> Self {
        let half = pose.theta / 2.0;
        let mut covariance = vec![0.0; 36];
        // (x, y, θ) sit at indices 0, 1 and 5 of the 6x6.
        let at = [0usize, 1, 5];
        for (i, &r) in at.iter().enumerate() {
            for (j, &c) in at.iter().enumerate() {
                covariance[r * 6 + c] = cov[i][j];
            }
        }
        for k in [2usize, 3, 4] {
            covariance[k * 6 + k] = FIXED_VARIANCE;
        }
        Self {
            header: Header {
                stamp: Stamp {
                    sec: (stamp_ns / 1_000_000_000) as i64,
                    nanosec: (stamp_ns % 1_000_000_000) as u32,
                },
                frame_id: frame_id.into(),
            },
            pose: PoseWithCovariance {
                pose: Pose {
                    position: Point {
                        x: pose.x,
                        y: pose.y,
                        z: 0.0,
                    },
                    orientation: Quaternion {
                        x: 0.0,
                        y: 0.0,
                        z: half.sin(),
                        w: half.cos(),
                    },
                },
                covariance,
            },
        }
    }
}

pub use crate::sensor::POSE_FRAME_ID;

/// `t_world_object` as a 4x4 matrix, with its convention in words.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ObjectTransform {
    /// Row-major 4x4 (metres).
    pub t_world_object: [[f64; 4]; 4],
    /// What the matrix maps, in words.
    pub convention: String,
}

/// An estimate placed for other tools: its 4x4 transform with the frame convention named, and the
/// `PoseWithCovarianceStamped` message with the posterior's covariance about it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LocatedEstimate {
    pub transform: ObjectTransform,
    pub ros: PoseWithCovarianceStamped,
}

impl LocatedEstimate {
    /// `estimate` with the covariance of `posterior` about it ([`covariance_about`]), in [`POSE_FRAME_ID`] at
    /// `stamp_ns`; `None` without an estimate or a posterior.
    pub fn new(
        estimate: Option<Se2>,
        posterior: Option<&PosePosterior>,
        symmetry: &Symmetry,
        stamp_ns: u64,
    ) -> Option<Self> {
        let estimate = estimate?;
        let cov = covariance_about(posterior?, estimate, symmetry)?;
        Some(Self {
            transform: ObjectTransform {
                t_world_object: transform_4x4(estimate),
                convention: "row-major 4x4; maps points of the object's mesh (its own frame, in its resting pose: \
                    bounding-box centre over the origin, lowest point at z = 0) to the world frame (the table at z = 0, \
                    z up, the sensor over x = y = 0), metres"
                    .into(),
            },
            ros: PoseWithCovarianceStamped::new(estimate, &cov, POSE_FRAME_ID, stamp_ns),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pose::posterior::PosteriorMode;

    #[test]
    fn the_transform_and_the_quaternion_are_the_same_rotation() {
        // Invariant: the 4x4 maps the object point (1, 0, 0) to the pose's position plus (cos θ, sin θ, 0), and the
        // quaternion (0, 0, sin θ/2, cos θ/2) rotates (1, 0, 0) the same way; glam's affine is the independent truth.
        let pose = Se2::new(0.01, -0.02, 2.5);
        let t = transform_4x4(pose);
        let p = glam::DVec3::X;
        let want = pose.to_affine().transform_point3(p);
        for i in 0..3 {
            let got = t[i][0] * p.x + t[i][1] * p.y + t[i][2] * p.z + t[i][3];
            assert!((got - want[i]).abs() < 1e-12);
        }
        let m = PoseWithCovarianceStamped::new(pose, &[[0.0; 3]; 3], "world", 1_500_000_000);
        let q = m.pose.pose.orientation;
        let rotated = glam::DQuat::from_xyzw(q.x, q.y, q.z, q.w) * p;
        assert!((rotated - (want - glam::DVec3::new(pose.x, pose.y, 0.0))).length() < 1e-12);
        assert_eq!(
            (m.header.stamp.sec, m.header.stamp.nanosec),
            (1, 500_000_000)
        );
    }

    #[test]
    fn the_covariance_sits_at_x_y_and_yaw_and_keeps_the_other_modes_spread() {
        // Two equal modes 2 cm apart in x with covariance c each: about the first, var x = c + ½·(0.02)².
        let c = 1e-6;
        let cov = [[c, 0.0, 0.0], [0.0, c, 0.0], [0.0, 0.0, 1e-3]];
        let mode = |x: f64| PosteriorMode {
            weight: 0.5,
            mean: [x, 0.0, 0.0],
            cov,
            nats: 0.0,
            hessian: cov,
            tails: Default::default(),
        };
        let post = PosePosterior {
            modes: vec![mode(0.0), mode(0.02)],
            contact_px: 300,
            predicted_contact_px: None,
            noise: None,
            distinct_nats: Vec::new(),
        };
        let about = covariance_about(&post, Se2::default(), &Symmetry::default()).unwrap();
        assert!((about[0][0] - (c + 0.5 * 0.02 * 0.02)).abs() < 1e-15);
        assert!((about[1][1] - c).abs() < 1e-15);
        let m = PoseWithCovarianceStamped::new(Se2::default(), &about, "world", 0);
        assert_eq!(m.pose.covariance[0], about[0][0]);
        assert_eq!(m.pose.covariance[35], 1e-3);
        assert_eq!(m.pose.covariance[2 * 6 + 2], FIXED_VARIANCE);
        assert_eq!(m.pose.covariance[5], 0.0);
    }
}
