//! **Real sensor recordings** in: a Soft Bubble's depth stream recorded as an MCAP file (ROS 2 bags; ROS 1 messages
//! too) or as a folder of depth frames, turned into one imprint Y = R − S per frame exactly as the simulator and
//! `tnd dataset import` do (crop and area-resample with the sensor's intrinsics, [`crate::sensor::resample`]), with
//! the no-contact reference frame R picked by the user or detected.
//!
//! | module | what |
//! | --- | --- |
//! | [`ros`] | CDR / ROS 1 decoding of `sensor_msgs/Image`, `PointCloud2`, `geometry_msgs/PoseStamped`, `Pose2D` |
//! | [`decode`] | depth images from those messages (16UC1 mm, 32FC1 m, projected clouds) |
//! | [`source`] | opening an MCAP file or a frame folder, listing streams, reading a frame |
//! | [`read`] | how a recording is read (topic, reference, contact threshold, a folder's units): one config for every front end |
//! | [`process`] | reference detection, imprint and contact area per frame |
//! | [`drift`] | the membrane's drift between no-contact stretches; each contact's reference from the one before it |
//! | [`frames_out`] | a recording's frames as native `.npy` files (NaN where no return) with `frames.csv` |
//! | [`calibrate`] | the sensor (membrane, camera position, noise) fitted to the no-contact frames |
//! | [`camera_fit`] | the depth camera's artefacts (missing returns, noise growing with depth, fixed pattern) from them |
//! | [`measured_membrane`] | a membrane mesh made of those frames, where the parametric dome cannot explain them |
//! | [`synth`] | writing a simulated press sequence as an MCAP recording (demos and tests) |
//!
//! Turning a recording into scored pairs (X0 simulated from a known object pose) is
//! [`crate::dataset::import_recording`].

pub mod calibrate;
pub mod camera_fit;
pub mod decode;
pub mod drift;
pub mod frames_out;
pub mod measured_membrane;
pub mod process;
pub mod read;
pub mod ros;
pub mod source;
pub mod synth;

use std::path::{Path, PathBuf};

pub use process::{process, ProcessConfig, ProcessedRecording, ReferenceChoice};
pub use read::ReadConfig;
pub use source::{DepthFrame, FolderOptions, Recording, StreamInfo, StreamKind};

/// Everything that can go wrong reading a recording; each names the file.
#[derive(Debug, thiserror::Error)]
pub enum RecordingError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// Not a recording, or a damaged one.
    #[error("{path}: {message}")]
    Format { path: PathBuf, message: String },
    /// No such topic or frame.
    #[error("{path}: {message}")]
    Topic { path: PathBuf, message: String },
    /// One message cannot be decoded.
    #[error("{path}: {topic}, message {index}: {message}")]
    Message {
        path: PathBuf,
        topic: String,
        index: usize,
        message: String,
    },
    /// Frames that do not fit the camera (size), or a processing choice that cannot be met.
    #[error("{path}: {message}")]
    Frames { path: PathBuf, message: String },
    #[error("cancelled")]
    Cancelled,
    #[error(transparent)]
    Sim(#[from] crate::sim::SimError),
}

impl RecordingError {
    pub(crate) fn io(path: &Path, source: std::io::Error) -> Self {
        RecordingError::Io {
            path: path.to_path_buf(),
            source,
        }
    }
}
