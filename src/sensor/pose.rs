//! Where things are: the object's SE(2) pose on the table, the sensor's pose above it, and the camera's mount inside
//! the sensor. Also the helper that places the sensor so its membrane apex presses a given depth into the object.

use glam::{DAffine3, DMat3, DVec3};
use serde::{Deserialize, Serialize};

/// Farthest an object can lie from the sensor axis, metres ([`Se2::unit_slips`]).
pub const MAX_REACH_M: f64 = 0.5;

/// A planar pose on the table: translation `(x, y)` in metres and rotation `theta` about the table normal (z), radians.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Se2 {
    pub x: f64,
    pub y: f64,
    pub theta: f64,
}

impl Se2 {
    pub fn new(x: f64, y: f64, theta: f64) -> Self {
        Self { x, y, theta }
    }

    /// `t_world_object`: the object frame (resting pose) placed on the table.
    pub fn to_affine(&self) -> DAffine3 {
        DAffine3::from_translation(DVec3::new(self.x, self.y, 0.0))
            * DAffine3::from_rotation_z(self.theta)
    }

    /// What makes this a pose no sensor could see, one phrase each: a position beyond [`MAX_REACH_M`] from the
    /// sensor axis (given in millimetres?) or an angle beyond a full turn (given in degrees?); empty when none.
    pub fn unit_slips(&self) -> Vec<String> {
        let mut slips = Vec::new();
        let far = self.x.abs().max(self.y.abs());
        if far > MAX_REACH_M {
            slips.push(format!(
                "{far} m from the sensor axis is beyond any sensor's reach; positions are in metres"
            ));
        }
        if self.theta.abs() > std::f64::consts::TAU {
            slips.push(format!(
                "θ {} is more than a full turn; θ is in radians",
                self.theta
            ));
        }
        slips
    }

    /// Parse `"X,Y,THETA"` (metres, metres, radians).
    pub fn parse(s: &str) -> Result<Self, crate::error::InvalidSetting> {
        let bad = |m: String| crate::error::InvalidSetting::new("pose", m);
        let parts: Vec<f64> = s
            .split(',')
            .map(|p| p.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .map_err(|_| {
                bad(format!(
                    "pose '{s}' must be X,Y,THETA in metres, metres, radians"
                ))
            })?;
        match parts.as_slice() {
            [x, y, t] if parts.iter().all(|v| v.is_finite()) => Ok(Self::new(*x, *y, *t)),
            _ => Err(bad(format!(
                "pose '{s}' must be three finite numbers X,Y,THETA"
            ))),
        }
    }
}

/// Pose of the sensor frame in the world. Untilted, the sensor looks straight down: sensor z = world -z, and at
/// `yaw = 0` sensor x = world x.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct SensorPose {
    /// Origin of the sensor frame (centre of the membrane base) in the world, metres.
    pub position: [f64; 3],
    /// Rotation about the world vertical, radians.
    pub yaw: f64,
    /// Tilt about the sensor's own x and y axes, radians (0 = looking straight down).
    pub tilt: [f64; 2],
}

impl Default for SensorPose {
    fn default() -> Self {
        Self {
            position: [0.0, 0.0, 0.1],
            yaw: 0.0,
            tilt: [0.0, 0.0],
        }
    }
}

impl SensorPose {
    /// Rotation of the sensor frame in the world.
    pub fn rotation(&self) -> DMat3 {
        DMat3::from_rotation_z(self.yaw)
            * DMat3::from_rotation_x(std::f64::consts::PI)
            * DMat3::from_rotation_x(self.tilt[0])
            * DMat3::from_rotation_y(self.tilt[1])
    }

    /// `t_world_sensor`.
    pub fn t_world_sensor(&self) -> DAffine3 {
        DAffine3::from_mat3_translation(self.rotation(), DVec3::from_array(self.position))
    }

    /// Place the sensor at `(x, y)` with `yaw` and `tilt` so that its membrane apex (at `apex_height` metres along
    /// sensor +z) is `press` metres below `top_z`, the height of the object's highest point.
    pub fn pressing(
        x: f64,
        y: f64,
        yaw: f64,
        tilt: [f64; 2],
        apex_height: f64,
        top_z: f64,
        press: f64,
    ) -> Self {
        let mut pose = Self {
            position: [0.0; 3],
            yaw,
            tilt,
        };
        let apex_offset = pose.rotation() * DVec3::new(0.0, 0.0, apex_height);
        let apex = DVec3::new(x, y, top_z - press);
        pose.position = (apex - apex_offset).to_array();
        pose
    }
}

/// Pose of the camera inside the sensor: the camera looks along sensor +z through the membrane base.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct CameraMount {
    /// Camera optical centre in the sensor frame, metres (default 6 cm behind the membrane base).
    pub position: [f64; 3],
    /// Extra rotation of the camera about sensor x, y, z (applied in that order), radians.
    pub rotation: [f64; 3],
}

impl Default for CameraMount {
    fn default() -> Self {
        Self {
            position: [0.0, 0.0, -0.06],
            rotation: [0.0; 3],
        }
    }
}

impl CameraMount {
    /// `t_sensor_camera`: camera axes equal sensor axes (x right, y down, z forward) up to `rotation`.
    pub fn t_sensor_camera(&self) -> DAffine3 {
        let [rx, ry, rz] = self.rotation;
        let r =
            DMat3::from_rotation_z(rz) * DMat3::from_rotation_y(ry) * DMat3::from_rotation_x(rx);
        DAffine3::from_mat3_translation(r, DVec3::from_array(self.position))
    }
}

/// A contact configuration: the object's pose on the table and the sensor's pose.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Scene {
    pub object: Se2,
    pub sensor: SensorPose,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn poses_survive_a_json_round_trip_bit_for_bit() {
        // serde_json's default float parser lands this x (a pose `tnd pose` printed) one ulp off; sessions, pose.json
        // and the workbench/CLI parity test need the exact number back.
        let pose = Se2::new(
            0.001_931_311_445_386_430_7,
            -0.000_983_520_642_963_476_2,
            -2.790_097_205_347_185_3,
        );
        let back: Se2 = serde_json::from_str(&serde_json::to_string(&pose).unwrap()).unwrap();
        assert_eq!(
            (back.x.to_bits(), back.y.to_bits(), back.theta.to_bits()),
            (pose.x.to_bits(), pose.y.to_bits(), pose.theta.to_bits())
        );
    }

    #[test]
    fn untilted_sensor_looks_down_and_press_places_apex() {
        let pose = SensorPose::pressing(0.01, -0.02, 0.3, [0.0, 0.0], 0.03, 0.04, 0.005);
        let t = pose.t_world_sensor();
        let apex = t.transform_point3(DVec3::new(0.0, 0.0, 0.03));
        assert!((apex - DVec3::new(0.01, -0.02, 0.035)).length() < 1e-12);
        let z = t.transform_vector3(DVec3::Z);
        assert!((z - DVec3::new(0.0, 0.0, -1.0)).length() < 1e-12);
        // With a tilt the apex still lands where asked.
        let pose = SensorPose::pressing(0.0, 0.0, 0.0, [0.1, -0.05], 0.03, 0.04, 0.005);
        let apex = pose
            .t_world_sensor()
            .transform_point3(DVec3::new(0.0, 0.0, 0.03));
        assert!((apex - DVec3::new(0.0, 0.0, 0.035)).length() < 1e-12);
    }

    #[test]
    fn se2_parse_and_transform() {
        let p = Se2::parse("0.01, 0.02, 1.5707963267948966").unwrap();
        let q = p.to_affine().transform_point3(DVec3::new(0.01, 0.0, 0.0));
        assert!((q - DVec3::new(0.01, 0.03, 0.0)).length() < 1e-12);
        assert!(Se2::parse("1,2").is_err());
        assert!(Se2::parse("1,nan,2").is_err());
    }
}
