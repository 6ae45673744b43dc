//! The Soft Bubble sensor: its depth camera ([`camera`]), its membrane ([`elastomer`], fitted to a measurement by
//! [`membrane_fit`]), where both are in the world ([`pose`]), and native frames brought to the model resolution
//! ([`resample`]). Frames: `world` (table at z = 0, z up), `sensor` (membrane base at z = 0, dome towards +z, i.e. towards
//! the object), `camera` (OpenCV: x right, y down, z forward), `object` (resting pose, lowest point at z = 0).

pub mod camera;
pub mod elastomer;
pub mod membrane_fit;
pub mod pose;
pub mod resample;

pub use camera::{CameraConfig, Intrinsics};
pub use elastomer::{ElastomerConfig, ElastomerError};
pub use pose::{Scene, Se2, SensorPose, MAX_REACH_M};

/// The frame id of an object pose a recording, a track or pose.json gives (`t_world_object`, in ROS headers): the
/// sensor's. The estimate's world is the table plane z = 0 with the sensor pressing from above at x = y = 0, so
/// its frame is the sensor's frame on the table.
pub const POSE_FRAME_ID: &str = "bubble";
