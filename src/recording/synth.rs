//! A **simulated recording**: the simulator run at the camera's native resolution over a press sequence (the sensor
//! lowered onto the object and lifted again), written as an MCAP file the way a ROS 2 Soft Bubble driver records it:
//! a `sensor_msgs/msg/Image` depth topic (`16UC1` millimetres or `32FC1` metres) or a `sensor_msgs/msg/PointCloud2`
//! topic, and the object's pose relative to the sensor as `geometry_msgs/msg/PoseStamped`. For trying the recording
//! tools without a sensor, and for the tests (a recording made here has a known truth per frame).

use std::collections::BTreeMap;
use std::io::Cursor;
use std::path::Path;

use serde::{Deserialize, Serialize};

use super::ros::{self, ImageMsg, PointCloudMsg, PointField};
use super::RecordingError;
use crate::image::Image;
use crate::sensor::{Intrinsics, Scene, Se2};
use crate::sim::{PreparedObject, SimConfig, Simulator};

/// How depth is written.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum DepthEncoding {
    /// `sensor_msgs/Image`, `16UC1`, millimetres (what depth drivers publish).
    #[default]
    Mm16,
    /// `sensor_msgs/Image`, `32FC1`, metres.
    F32,
    /// `sensor_msgs/PointCloud2` with float32 x, y, z in the camera's optical frame.
    Cloud,
}

/// The press sequence to record.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PressSequence {
    /// Object pose relative to the sensor axis (x, y metres, theta radians).
    pub pose: Se2,
    /// Press depth of each frame, metres (negative: the membrane apex above the object's top, no contact).
    pub presses: Vec<f64>,
    /// Time between frames, seconds.
    pub frame_period_s: f64,
    pub encoding: DepthEncoding,
    /// Seed of the measurement noise.
    pub seed: u64,
    /// Depth topic name.
    pub depth_topic: String,
    /// Pose topic name (`None`: no pose topic).
    pub pose_topic: Option<String>,
    /// How `32FC1` frames mark a pixel without a return: NaN (REP 118, the default) or 0. `16UC1` frames always use
    /// 0; point clouds leave the point out.
    #[serde(default)]
    pub missing_as_zero: bool,
    /// How much the membrane's inflation changes from the first frame to the last, linearly, metres (air leaking
    /// out: negative; 0: none, the default). The sensor stays where it is, so the contact's press changes with it.
    #[serde(default)]
    pub drift_m: f64,
}

impl PressSequence {
    /// `rest` frames 2 mm above the object, then down to `max_press` and back up in `2 * ramp` frames, then `rest`
    /// frames above again.
    pub fn down_and_up(pose: Se2, max_press: f64, rest: usize, ramp: usize) -> Self {
        let mut presses = vec![-0.002; rest];
        let ramp = ramp.max(1);
        presses.extend((1..=ramp).map(|i| max_press * i as f64 / ramp as f64));
        presses.extend((1..ramp).rev().map(|i| max_press * i as f64 / ramp as f64));
        presses.extend(std::iter::repeat_n(-0.002, rest));
        Self {
            pose,
            presses,
            frame_period_s: 1.0 / 30.0,
            encoding: DepthEncoding::Mm16,
            seed: 0,
            depth_topic: "/bubble/depth/image_rect_raw".into(),
            pose_topic: Some("/object/pose".into()),
            missing_as_zero: false,
            drift_m: 0.0,
        }
    }
}

/// Write the press sequence of `object` as an MCAP file (atomically); returns the number of frames.
pub fn write_press_recording(
    path: &Path,
    sim_config: &SimConfig,
    object: &PreparedObject,
    seq: &PressSequence,
) -> Result<usize, RecordingError> {
    let sim = Simulator::native(sim_config.clone())?;
    let k = *sim.intrinsics();
    let mcap_err = mcap_error(path);
    let mut w = new_mcap(path)?;
    let (depth_channel, pose_channel) = add_press_channels(&mut w, path, seq)?;
    let t0_ns: u64 = 1_700_000_000_000_000_000;
    if seq.drift_m != 0.0 && sim_config.elastomer.mesh_file.is_some() {
        return Err(RecordingError::Frames {
            path: path.to_path_buf(),
            message:
                "a drifting membrane needs the parametric membrane (its inflation), not a mesh file"
                    .into(),
        });
    }
    let last = seq.presses.len().saturating_sub(1).max(1) as f64;
    for (i, &press) in seq.presses.iter().enumerate() {
        // The membrane of this frame: the inflation drifted by its share of `drift_m`.
        let drifted;
        let frame_sim = if seq.drift_m == 0.0 {
            &sim
        } else {
            let mut c = sim_config.clone();
            c.elastomer.inflation += seq.drift_m * i as f64 / last;
            drifted = Simulator::native(c)?;
            &drifted
        };
        let stamp = t0_ns + (i as f64 * seq.frame_period_s * 1e9).round() as u64;
        let scene = Scene {
            object: seq.pose,
            sensor: sim.pressing_pose(object, 0.0, 0.0, 0.0, press),
        };
        let frame_seed = seq.seed.wrapping_add(i as u64);
        let out = frame_sim.simulate(object, &scene, frame_seed);
        // The depth camera's own artefacts (missing returns as 0), on the native frame.
        let s = &sim_config.depth_camera.apply(
            &out.signature,
            sim_config.signature.noise_std,
            frame_seed,
        );
        let data = match seq.encoding {
            DepthEncoding::Mm16 | DepthEncoding::F32 => encode_depth_image(s, &k, seq, stamp),
            DepthEncoding::Cloud => encode_depth_cloud(s, &k, stamp),
        };
        let header = |channel_id| mcap::records::MessageHeader {
            channel_id,
            sequence: i as u32,
            log_time: stamp,
            publish_time: stamp,
        };
        w.write_to_known_channel(&header(depth_channel), &data)
            .map_err(mcap_err)?;
        if let Some(c) = pose_channel {
            let p = &seq.pose;
            let pose =
                ros::encode_pose_stamped(stamp, p.x, p.y, p.theta, crate::sensor::POSE_FRAME_ID);
            w.write_to_known_channel(&header(c), &pose)
                .map_err(mcap_err)?;
        }
    }
    save_mcap(path, w)?;
    Ok(seq.presses.len())
}

/// The schemas and channels of a press recording in `w` (the MCAP file at `path`): the depth topic (an image or a
/// point cloud, as `seq.encoding` says) and, where `seq` names one, the pose topic; returns their channel ids.
fn add_press_channels(
    w: &mut mcap::Writer<Cursor<Vec<u8>>>,
    path: &Path,
    seq: &PressSequence,
) -> Result<(u16, Option<u16>), RecordingError> {
    let mcap_err = mcap_error(path);
    let no_meta = BTreeMap::new();
    let (schema_name, schema_text) = match seq.encoding {
        DepthEncoding::Cloud => ("sensor_msgs/msg/PointCloud2", point_cloud_schema()),
        _ => ("sensor_msgs/msg/Image", image_schema()),
    };
    let depth_schema = w
        .add_schema(schema_name, "ros2msg", schema_text.as_bytes())
        .map_err(mcap_err)?;
    let depth_channel = w
        .add_channel(depth_schema, &seq.depth_topic, "cdr", &no_meta)
        .map_err(mcap_err)?;
    let pose_channel = match &seq.pose_topic {
        Some(topic) => {
            let s = w
                .add_schema(
                    "geometry_msgs/msg/PoseStamped",
                    "ros2msg",
                    pose_stamped_schema().as_bytes(),
                )
                .map_err(mcap_err)?;
            Some(w.add_channel(s, topic, "cdr", &no_meta).map_err(mcap_err)?)
        }
        None => None,
    };
    Ok((depth_channel, pose_channel))
}

/// One frame's depth `s` (metres, native intrinsics `k`) as a CDR `sensor_msgs/Image`: `16UC1` millimetres or
/// `32FC1` metres as `seq.encoding` says, a missing return as 0 or (32FC1 without `missing_as_zero`) NaN.
fn encode_depth_image(s: &Image, k: &Intrinsics, seq: &PressSequence, stamp: u64) -> Vec<u8> {
    let nan = if seq.missing_as_zero { 0.0 } else { f32::NAN };
    let (encoding, bytes_per_px, data): (&str, u32, Vec<u8>) = match seq.encoding {
        DepthEncoding::Mm16 => (
            "16UC1",
            2,
            s.data
                .iter()
                .flat_map(|&d| millimetres(d).to_le_bytes())
                .collect(),
        ),
        _ => (
            "32FC1",
            4,
            s.data
                .iter()
                .flat_map(|&d| if d > 0.0 { d } else { nan }.to_le_bytes())
                .collect(),
        ),
    };
    let m = ImageMsg {
        stamp_ns: stamp,
        height: k.height as u32,
        width: k.width as u32,
        encoding: encoding.into(),
        is_bigendian: false,
        step: bytes_per_px * k.width as u32,
        data,
    };
    ros::encode_image(&m, "bubble_camera")
}

/// One frame's depth `s` (metres, native intrinsics `k`) as a CDR `sensor_msgs/PointCloud2`: float32 x, y, z in the
/// camera's optical frame, one point per pixel with a return.
fn encode_depth_cloud(s: &Image, k: &Intrinsics, stamp: u64) -> Vec<u8> {
    let mut data = Vec::with_capacity(12 * s.data.len());
    let mut n = 0u32;
    for v in 0..k.height {
        for u in 0..k.width {
            let d = s.get(u, v);
            if d.is_finite() && d > 0.0 {
                let p = k.back_project(u as f64, v as f64, f64::from(d));
                for c in [p.x, p.y, p.z] {
                    data.extend((c as f32).to_le_bytes());
                }
                n += 1;
            }
        }
    }
    let fields = ["x", "y", "z"]
        .iter()
        .enumerate()
        .map(|(j, name)| PointField {
            name: (*name).into(),
            offset: 4 * j as u32,
            datatype: 7,
            count: 1,
        })
        .collect();
    let m = PointCloudMsg {
        stamp_ns: stamp,
        height: 1,
        width: n,
        fields,
        is_bigendian: false,
        point_step: 12,
        row_step: 12 * n,
        data,
    };
    ros::encode_point_cloud(&m, "bubble_camera")
}

/// The error of writing the MCAP file at `path`.
fn mcap_error(path: &Path) -> impl Fn(mcap::McapError) -> RecordingError + Copy + '_ {
    move |e| RecordingError::Format {
        path: path.to_path_buf(),
        message: format!("writing MCAP: {e}"),
    }
}

/// The library an MCAP file tnd writes names in its header: how `tnd recording simulate` knows a file it may
/// replace ([`written_by_tnd`]).
pub const MCAP_LIBRARY: &str = "tactile-derender";

/// Whether `path` is an MCAP file whose header names [`MCAP_LIBRARY`] (a recording or track tnd wrote).
pub fn written_by_tnd(path: &Path) -> bool {
    use std::io::Read;
    let mut head = [0u8; 256];
    let Ok(n) = std::fs::File::open(path).and_then(|mut f| f.read(&mut head)) else {
        return false;
    };
    let head = &head[..n];
    // Magic, the Header record's opcode and length, then two length-prefixed strings: profile, library.
    let string_at = |at: usize| -> Option<(&[u8], usize)> {
        let len = u32::from_le_bytes(head.get(at..at + 4)?.try_into().ok()?) as usize;
        Some((head.get(at + 4..at + 4 + len)?, at + 4 + len))
    };
    if !head.starts_with(b"\x89MCAP0\r\n") || head.get(8) != Some(&0x01) {
        return false;
    }
    string_at(17)
        .and_then(|(_, next)| string_at(next))
        .is_some_and(|(library, _)| library == MCAP_LIBRARY.as_bytes())
}

/// A ROS 2 MCAP file for `path`, written in memory until [`save_mcap`].
fn new_mcap(path: &Path) -> Result<mcap::Writer<Cursor<Vec<u8>>>, RecordingError> {
    mcap::WriteOptions::new()
        .profile("ros2")
        .library(MCAP_LIBRARY)
        .create(Cursor::new(Vec::new()))
        .map_err(mcap_error(path))
}

/// Finish `w` and write it to `path` atomically.
fn save_mcap(path: &Path, mut w: mcap::Writer<Cursor<Vec<u8>>>) -> Result<(), RecordingError> {
    w.finish().map_err(mcap_error(path))?;
    let bytes = w.into_inner().into_inner();
    crate::io::atomic::write_atomic(path, &bytes).map_err(|e| RecordingError::io(path, e))
}

/// A depth in metres as a 16UC1 value: millimetres, 0 where unmeasured or beyond 65.534 m.
fn millimetres(d: f32) -> u16 {
    let mm = (f64::from(d) * 1000.0).round();
    if d.is_finite() && d > 0.0 && mm < 65535.0 {
        mm as u16
    } else {
        0
    }
}

/// The `ros2msg` definitions of the messages we write, each followed by every message type it uses (separated as
/// `ros2 bag` and the MCAP ROS 2 tools write them), so that a decoder that knows no ROS types can read them
/// (mcap-ros2-support refuses a definition that leaves out `std_msgs/Header` and the like).
const SEPARATOR: &str =
    "================================================================================\n";
const HEADER_DEPS: &str = "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n";
const TIME_DEPS: &str = "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n";

fn with_deps(fields: &str, deps: &[&str]) -> String {
    let mut s = fields.to_string();
    for d in deps {
        s.push_str(SEPARATOR);
        s.push_str(d);
    }
    s
}

/// `sensor_msgs/msg/Image`.
pub fn image_schema() -> String {
    with_deps(
        "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\nuint8 is_bigendian\nuint32 step\nuint8[] data\n",
        &[HEADER_DEPS, TIME_DEPS],
    )
}

/// `sensor_msgs/msg/PointCloud2`.
pub fn point_cloud_schema() -> String {
    with_deps(
        "std_msgs/Header header\nuint32 height\nuint32 width\nsensor_msgs/PointField[] fields\nbool is_bigendian\n\
         uint32 point_step\nuint32 row_step\nuint8[] data\nbool is_dense\n",
        &[
            HEADER_DEPS,
            TIME_DEPS,
            "MSG: sensor_msgs/PointField\nstring name\nuint32 offset\nuint8 datatype\nuint32 count\n",
        ],
    )
}

/// `geometry_msgs/msg/PoseStamped`.
/// The ros2msg schema of `geometry_msgs/msg/PoseWithCovarianceStamped` with its dependencies.
pub fn pose_with_covariance_stamped_schema() -> String {
    with_deps(
        "std_msgs/Header header\ngeometry_msgs/PoseWithCovariance pose\n",
        &[
            HEADER_DEPS,
            TIME_DEPS,
            "MSG: geometry_msgs/PoseWithCovariance\nPose pose\nfloat64[36] covariance\n",
            "MSG: geometry_msgs/Pose\nPoint position\nQuaternion orientation\n",
            "MSG: geometry_msgs/Point\nfloat64 x\nfloat64 y\nfloat64 z\n",
            "MSG: geometry_msgs/Quaternion\nfloat64 x\nfloat64 y\nfloat64 z\nfloat64 w\n",
        ],
    )
}

/// Write `poses` — (stamp ns, [x, y, θ], covariance) — as `geometry_msgs/msg/PoseWithCovarianceStamped` messages on
/// `topic` in frame `frame_id`, into a new MCAP file at `path` (atomically): a track a ROS user replays or reads
/// with any MCAP tool.
pub fn write_pose_track(
    path: &Path,
    topic: &str,
    frame_id: &str,
    poses: &[(u64, [f64; 3], [f64; 36])],
) -> Result<(), RecordingError> {
    let mcap_err = mcap_error(path);
    let mut w = new_mcap(path)?;
    let schema = w
        .add_schema(
            "geometry_msgs/msg/PoseWithCovarianceStamped",
            "ros2msg",
            pose_with_covariance_stamped_schema().as_bytes(),
        )
        .map_err(mcap_err)?;
    let channel = w
        .add_channel(schema, topic, "cdr", &BTreeMap::new())
        .map_err(mcap_err)?;
    for (sequence, (stamp, pose, cov)) in poses.iter().enumerate() {
        let data = super::ros::encode_pose_with_covariance_stamped(*stamp, frame_id, *pose, cov);
        w.write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id: channel,
                sequence: sequence as u32,
                log_time: *stamp,
                publish_time: *stamp,
            },
            &data,
        )
        .map_err(mcap_err)?;
    }
    save_mcap(path, w)
}

pub fn pose_stamped_schema() -> String {
    with_deps(
        "std_msgs/Header header\ngeometry_msgs/Pose pose\n",
        &[
            HEADER_DEPS,
            TIME_DEPS,
            "MSG: geometry_msgs/Pose\nPoint position\nQuaternion orientation\n",
            "MSG: geometry_msgs/Point\nfloat64 x\nfloat64 y\nfloat64 z\n",
            "MSG: geometry_msgs/Quaternion\nfloat64 x\nfloat64 y\nfloat64 z\nfloat64 w\n",
        ],
    )
}
