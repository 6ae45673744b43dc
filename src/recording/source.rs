//! Opening a recording: an **MCAP file** (ROS 2 / ROS 1 bags; read with the `mcap` crate, chunked and compressed
//! files included) or a **folder of depth frames** (16-bit PNG in millimetres, `.npy`/`.npz` scaled to metres),
//! listing its streams and decoding one depth frame at a time at the camera's own resolution.
//!
//! An MCAP file is streamed once; only the messages of recognised schemas are kept in memory (depth images, point
//! clouds, poses), so other topics of a bag cost nothing.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::ros::{self, Encoding};
use super::RecordingError;
use crate::image::Image;
use crate::io::depth_file;
use crate::sensor::{Intrinsics, Se2};

/// What a stream holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StreamKind {
    /// `sensor_msgs/Image` depth, or a folder's frames.
    DepthImage,
    /// `sensor_msgs/PointCloud2`, projected to a depth image with the camera's intrinsics.
    PointCloud,
    /// `geometry_msgs/PoseStamped` or `geometry_msgs/Pose2D`: the object's SE(2) pose relative to the sensor.
    Pose,
    /// Anything else (listed, not read).
    Other,
}

/// One topic of an MCAP file (or the one stream of a folder).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StreamInfo {
    /// Topic name (a folder: its path).
    pub name: String,
    /// Schema name, e.g. `sensor_msgs/msg/Image`.
    pub schema: String,
    pub kind: StreamKind,
    /// Number of messages (frames).
    pub messages: usize,
}

/// How folder frames are scaled and stamped.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct FolderOptions {
    /// Metres per unit of `.npy`/`.npz` frames (default 1: metres).
    pub npy_scale: f64,
    /// Metres per unit of 16-bit PNG frames (default 0.001: millimetres).
    pub png_scale: f64,
    /// Frame rate for the frames' time stamps, frames per second (default 30).
    pub fps: f64,
}

impl Default for FolderOptions {
    fn default() -> Self {
        Self {
            npy_scale: 1.0,
            png_scale: 0.001,
            fps: 30.0,
        }
    }
}

/// A depth frame at the camera's resolution, metres (0 where the camera measured nothing, whatever way the file or
/// message marked it: [`crate::image::is_measured_depth`]).
#[derive(Clone, Debug, PartialEq)]
pub struct DepthFrame {
    /// Time stamp, nanoseconds (header stamp, or the MCAP log time when the header's is 0).
    pub stamp_ns: u64,
    pub depth: Image,
}

struct Topic {
    encoding: Encoding,
    schema: String,
    kind: StreamKind,
    /// (log time, message bytes).
    messages: Vec<(u64, Vec<u8>)>,
}

enum Data {
    Mcap(BTreeMap<String, Topic>),
    Folder {
        files: Vec<PathBuf>,
        options: FolderOptions,
    },
}

/// An opened recording.
pub struct Recording {
    path: PathBuf,
    streams: Vec<StreamInfo>,
    data: Data,
}

/// Default largest time between a frame and the pose message matched to it, seconds.
pub const DEFAULT_MAX_POSE_GAP_S: f64 = 0.05;

/// Index into `sorted` (ascending) of the stamp nearest to `t`, if it is within `max_gap_ns` (the earlier on a tie).
pub fn nearest_stamp(sorted: &[u64], t: u64, max_gap_ns: u64) -> Option<usize> {
    let k = sorted.partition_point(|&s| s < t);
    [k.checked_sub(1), Some(k)]
        .into_iter()
        .flatten()
        .filter(|&j| j < sorted.len())
        .min_by_key(|&j| sorted[j].abs_diff(t))
        .filter(|&j| sorted[j].abs_diff(t) <= max_gap_ns)
}

/// Largest MCAP record or decompressed chunk read, bytes (512 MiB: chunks of real bags are a few MB).
const MAX_RECORD_BYTES: usize = 512 << 20;

/// Frame file extensions of a folder recording.
pub const FRAME_EXTENSIONS: [&str; 3] = ["png", "npy", "npz"];

fn kind_of(schema: &str) -> StreamKind {
    // ROS 2 names schemas "pkg/msg/Type", ROS 1 "pkg/Type".
    match schema.replace("/msg/", "/").as_str() {
        "sensor_msgs/Image" => StreamKind::DepthImage,
        "sensor_msgs/PointCloud2" => StreamKind::PointCloud,
        "geometry_msgs/PoseStamped" | "geometry_msgs/Pose2D" => StreamKind::Pose,
        _ => StreamKind::Other,
    }
}

impl Recording {
    /// Open an `.mcap` file or a folder of depth frames.
    pub fn open(path: &Path, folder: &FolderOptions) -> Result<Self, RecordingError> {
        if path.is_dir() {
            Self::open_folder(path, folder)
        } else {
            Self::open_mcap(path)
        }
    }

    fn open_mcap(path: &Path) -> Result<Self, RecordingError> {
        use std::io::{Read, Seek};
        let bad = |message: String| RecordingError::Format {
            path: path.to_path_buf(),
            message,
        };
        // A FIFO would block the open itself, a device never end: only regular files are recordings.
        let meta = std::fs::metadata(path)
            .map_err(|e| RecordingError::io(path, crate::io::input::explained(path, e)))?;
        if let Some(kind) = crate::io::output::file_kind(&meta) {
            return Err(bad(format!("{kind}, not a recording")));
        }
        let mut file = std::fs::File::open(path)
            .map_err(|e| RecordingError::io(path, crate::io::input::explained(path, e)))?;
        let mut magic = [0u8; 5];
        if file.read_exact(&mut magic).is_err() || &magic != b"\x89MCAP" {
            return Err(bad("not an MCAP file (no MCAP magic at the start)".into()));
        }
        file.rewind().map_err(|e| RecordingError::io(path, e))?;
        // A streaming reader with a bound on any one record or decompressed chunk: a corrupt length field is an
        // error, not an allocation of its claimed size (mcap's in-memory MessageStream sets no such bound).
        let options = mcap::sans_io::LinearReaderOptions::default()
            .with_record_length_limit(MAX_RECORD_BYTES);
        let stream =
            mcap::io::MessageReader::new_with_options(std::io::BufReader::new(file), options);
        let mut topics: BTreeMap<String, Topic> = BTreeMap::new();
        let mut counts: BTreeMap<String, (String, usize)> = BTreeMap::new();
        for message in stream {
            let m = message.map_err(|e| bad(format!("truncated or corrupt MCAP: {e}")))?;
            let schema = m
                .channel
                .schema
                .as_ref()
                .map(|s| s.name.clone())
                .unwrap_or_default();
            let topic = m.channel.topic.clone();
            let entry = counts.entry(topic.clone()).or_insert((schema.clone(), 0));
            entry.1 += 1;
            let kind = kind_of(&schema);
            let Some(encoding) = Encoding::from_mcap(&m.channel.message_encoding) else {
                continue;
            };
            if kind == StreamKind::Other {
                continue;
            }
            topics
                .entry(topic)
                .or_insert_with(|| Topic {
                    encoding,
                    schema,
                    kind,
                    messages: Vec::new(),
                })
                .messages
                .push((m.log_time, m.data.into_owned()));
        }
        let streams = counts
            .into_iter()
            .map(|(name, (schema, messages))| StreamInfo {
                kind: topics.get(&name).map_or(StreamKind::Other, |t| t.kind),
                name,
                schema,
                messages,
            })
            .collect();
        Ok(Self {
            path: path.to_path_buf(),
            streams,
            data: Data::Mcap(topics),
        })
    }

    fn open_folder(path: &Path, options: &FolderOptions) -> Result<Self, RecordingError> {
        if !(options.fps.is_finite() && options.fps > 0.0) {
            return Err(RecordingError::Format {
                path: path.to_path_buf(),
                message: format!("frame rate {} must be positive", options.fps),
            });
        }
        let entries = std::fs::read_dir(path).map_err(|e| RecordingError::io(path, e))?;
        let mut files = Vec::new();
        for e in entries {
            let p = e.map_err(|e| RecordingError::io(path, e))?.path();
            let ext = p
                .extension()
                .and_then(|e| e.to_str())
                .map(str::to_ascii_lowercase);
            let is_frame = ext.is_some_and(|e| FRAME_EXTENSIONS.contains(&e.as_str()));
            let name = p.file_name().and_then(|n| n.to_str()).unwrap_or_default();
            // A reference frame (`reference.npy`, `reference_000012.npy` as `tnd recording frames` writes them) or
            // a pair table beside the frames is not a frame.
            if is_frame
                && p.is_file()
                && !name.starts_with("reference.")
                && !name.starts_with("reference_")
            {
                files.push(p);
            }
        }
        if files.is_empty() {
            return Err(RecordingError::Format {
                path: path.to_path_buf(),
                message: "no depth frames (.png, .npy, .npz) in this folder".into(),
            });
        }
        files.sort_by(|a, b| natural_cmp(&a.to_string_lossy(), &b.to_string_lossy()));
        let streams = vec![StreamInfo {
            name: path.display().to_string(),
            schema: "depth frames".into(),
            kind: StreamKind::DepthImage,
            messages: files.len(),
        }];
        Ok(Self {
            path: path.to_path_buf(),
            streams,
            data: Data::Folder {
                files,
                options: options.clone(),
            },
        })
    }

    /// The file or folder.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Every stream, sorted by name.
    pub fn streams(&self) -> &[StreamInfo] {
        &self.streams
    }

    /// The depth stream named `name`, or the only depth stream (images and point clouds) when `name` is `None`.
    pub fn depth_stream(&self, name: Option<&str>) -> Result<&StreamInfo, RecordingError> {
        self.pick(name, "depth", |k| {
            matches!(k, StreamKind::DepthImage | StreamKind::PointCloud)
        })
    }

    /// The pose stream named `name`, or the only one when `name` is `None`.
    pub fn pose_stream(&self, name: Option<&str>) -> Result<&StreamInfo, RecordingError> {
        self.pick(name, "pose", |k| k == StreamKind::Pose)
    }

    fn pick(
        &self,
        name: Option<&str>,
        what: &str,
        accept: impl Fn(StreamKind) -> bool,
    ) -> Result<&StreamInfo, RecordingError> {
        let candidates: Vec<&StreamInfo> = self.streams.iter().filter(|s| accept(s.kind)).collect();
        let names: Vec<&str> = candidates.iter().map(|s| s.name.as_str()).collect();
        let others: Vec<&str> = self.streams.iter().map(|s| s.name.as_str()).collect();
        let elsewhere = if others.is_empty() {
            "the recording holds no messages at all".to_string()
        } else {
            format!("messages only on {}", others.join(", "))
        };
        let found = match name {
            Some(n) => candidates.iter().find(|s| s.name == n).copied(),
            None if candidates.len() == 1 => Some(candidates[0]),
            None => None,
        };
        found.ok_or_else(|| RecordingError::Topic {
            path: self.path.clone(),
            message: match (name, names.is_empty()) {
                (Some(n), true) => format!("topic '{n}' holds no {what} messages ({elsewhere})"),
                (Some(n), false) => format!(
                    "no {what} topic '{n}'; its {what} topics: {}",
                    names.join(", ")
                ),
                (None, true) => format!("it has no {what} topic with messages ({elsewhere})"),
                (None, false) => format!(
                    "choose a {what} topic; its {what} topics: {}",
                    names.join(", ")
                ),
            },
        })
    }

    /// Decode frame `index` of the depth stream `stream` at its own resolution; point clouds are projected with
    /// `native` (the cloud in the camera's optical frame: x right, y down, z forward; nearest point per pixel).
    pub fn depth_frame(
        &self,
        stream: &StreamInfo,
        index: usize,
        native: &Intrinsics,
    ) -> Result<DepthFrame, RecordingError> {
        match &self.data {
            Data::Folder { files, options } => {
                let file = files
                    .get(index)
                    .ok_or_else(|| self.no_frame(stream, index))?;
                // `file` already holds the folder (a relative folder joined twice was looked for inside itself).
                let (dir, name) = (
                    file.parent().unwrap_or(Path::new("")),
                    file.file_name()
                        .map(|n| n.to_string_lossy())
                        .unwrap_or_default(),
                );
                let depth = depth_file::read(dir, &name, options.npy_scale, options.png_scale)
                    .map_err(|e| RecordingError::Format {
                        path: file.clone(),
                        message: e.message,
                    })?;
                // Depths mostly beyond any tactile camera's range are in other units, not missing.
                if let Some(typical) = crate::image::typical_magnitude(&depth.data)
                    .filter(|&t| t > crate::image::MAX_DEPTH_M)
                {
                    return Err(RecordingError::Format {
                        path: file.clone(),
                        message: crate::image::implausible_depth_units(
                            typical,
                            "read .npy/.npz frames with --npy-scale 0.001",
                        ),
                    });
                }
                Ok(DepthFrame {
                    stamp_ns: (index as f64 * 1e9 / options.fps).round() as u64,
                    // NaN, inf, negative and out-of-range pixels have no return: 0, as the MCAP decoders give them.
                    depth: depth.missing_as_zero().0,
                })
            }
            Data::Mcap(topics) => {
                let topic = topics
                    .get(&stream.name)
                    .ok_or_else(|| self.no_frame(stream, index))?;
                let (log_time, bytes) = topic
                    .messages
                    .get(index)
                    .ok_or_else(|| self.no_frame(stream, index))?;
                let at = |message: crate::error::InvalidInput| RecordingError::Message {
                    path: self.path.clone(),
                    topic: stream.name.clone(),
                    index,
                    message: message.into(),
                };
                let (stamp, depth) = match topic.kind {
                    StreamKind::DepthImage => {
                        let m = ros::decode_image(bytes, topic.encoding).map_err(at)?;
                        (m.stamp_ns, super::decode::image_depth(&m).map_err(at)?)
                    }
                    StreamKind::PointCloud => {
                        let m = ros::decode_point_cloud(bytes, topic.encoding).map_err(at)?;
                        (
                            m.stamp_ns,
                            super::decode::cloud_depth(&m, native).map_err(at)?,
                        )
                    }
                    _ => {
                        return Err(at(crate::error::InvalidInput::new(
                            "depth stream",
                            format!("{} is not a depth stream", topic.schema),
                        )))
                    }
                };
                Ok(DepthFrame {
                    stamp_ns: if stamp == 0 { *log_time } else { stamp },
                    depth,
                })
            }
        }
    }

    /// Every pose of a pose stream: (time stamp in ns, x, y, theta) in message order.
    pub fn poses(&self, stream: &StreamInfo) -> Result<Vec<(u64, [f64; 3])>, RecordingError> {
        let Data::Mcap(topics) = &self.data else {
            return Ok(Vec::new());
        };
        let Some(topic) = topics.get(&stream.name) else {
            return Ok(Vec::new());
        };
        let stamped = topic.schema.ends_with("PoseStamped");
        topic
            .messages
            .iter()
            .enumerate()
            .map(|(index, (log_time, bytes))| {
                let p = if stamped {
                    ros::decode_pose_stamped(bytes, topic.encoding)
                } else {
                    ros::decode_pose2d(bytes, topic.encoding)
                }
                .map_err(|e| RecordingError::Message {
                    path: self.path.clone(),
                    topic: stream.name.clone(),
                    index,
                    message: e.into(),
                })?;
                let stamp = p.stamp_ns.filter(|&s| s != 0).unwrap_or(*log_time);
                Ok((stamp, [p.x, p.y, p.theta]))
            })
            .collect()
    }

    /// The object's pose at each of `stamps_ns` from the pose stream `stream`: the message nearest in time, if it is
    /// within `max_gap_s`.
    pub fn poses_at(
        &self,
        stream: &StreamInfo,
        stamps_ns: &[u64],
        max_gap_s: f64,
    ) -> Result<Vec<Option<Se2>>, RecordingError> {
        let mut poses = self.poses(stream)?;
        poses.sort_by_key(|p| p.0);
        let sorted: Vec<u64> = poses.iter().map(|p| p.0).collect();
        let gap = (max_gap_s * 1e9) as u64;
        Ok(stamps_ns
            .iter()
            .map(|&t| {
                nearest_stamp(&sorted, t, gap).map(|j| {
                    let [x, y, theta] = poses[j].1;
                    Se2::new(x, y, theta)
                })
            })
            .collect())
    }

    fn no_frame(&self, stream: &StreamInfo, index: usize) -> RecordingError {
        RecordingError::Topic {
            path: self.path.clone(),
            message: format!(
                "{} has {} frames; there is no frame {index}",
                stream.name, stream.messages
            ),
        }
    }
}

/// Compare file names with runs of digits as numbers ("frame2" < "frame10").
fn natural_cmp(a: &str, b: &str) -> std::cmp::Ordering {
    let (mut a, mut b) = (a.as_bytes(), b.as_bytes());
    loop {
        match (a.first(), b.first()) {
            (None, None) => return std::cmp::Ordering::Equal,
            (None, _) => return std::cmp::Ordering::Less,
            (_, None) => return std::cmp::Ordering::Greater,
            (Some(x), Some(y)) if x.is_ascii_digit() && y.is_ascii_digit() => {
                let da = a.iter().take_while(|c| c.is_ascii_digit()).count();
                let db = b.iter().take_while(|c| c.is_ascii_digit()).count();
                let (na, nb) = (&a[..da], &b[..db]);
                let strip = |s: &[u8]| -> usize { s.iter().take_while(|&&c| c == b'0').count() };
                let (na, nb) = (&na[strip(na)..], &nb[strip(nb)..]);
                let ord = na.len().cmp(&nb.len()).then(na.cmp(nb));
                if ord != std::cmp::Ordering::Equal {
                    return ord;
                }
                a = &a[da..];
                b = &b[db..];
            }
            (Some(x), Some(y)) => {
                if x != y {
                    return x.cmp(y);
                }
                a = &a[1..];
                b = &b[1..];
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_stamp_within_the_gap() {
        let s = [10, 20, 40];
        assert_eq!(nearest_stamp(&s, 14, 5), Some(0));
        assert_eq!(nearest_stamp(&s, 15, 5), Some(0)); // a tie goes to the earlier
        assert_eq!(nearest_stamp(&s, 33, 10), Some(2));
        assert_eq!(nearest_stamp(&s, 29, 5), None);
        assert_eq!(nearest_stamp(&s, 100, 1000), Some(2));
        assert_eq!(nearest_stamp(&[], 1, 1000), None);
    }

    #[test]
    fn natural_order_compares_numbers_as_numbers() {
        let mut v = vec!["f10.png", "f2.png", "f1.png", "f02.npy", "g.png"];
        v.sort_by(|a, b| natural_cmp(a, b));
        assert_eq!(v, vec!["f1.png", "f02.npy", "f2.png", "f10.png", "g.png"]);
    }
}
