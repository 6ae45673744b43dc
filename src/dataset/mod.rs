//! The **dataset** stage (paper V.A): synthetic pairs for pre-training (24 000 random contacts) and imported real
//! pairs, split into seen objects / seen poses (`train`), seen objects / unseen poses (`unseen_poses`, 9:1 against
//! train) and unseen objects (`unseen_objects`, all poses).
//!
//! On disk a dataset is a directory that numpy users can open without our code:
//!
//! ```text
//! DIR/manifest.json             format version, full SimConfig + generation config, object set, counts, shard list
//! DIR/objects/                  the object set (objects.json + OBJ meshes in metres, resting pose)
//! DIR/shards/<split>-<chunk>.npz uncompressed npz: float32 images (N, H, W) in metres + per-pair metadata arrays
//! ```
//!
//! Files, one per concern: [`config`] (generation parameters), [`split`] (pair seeds, object choice and the split
//! rule, all pure functions of the seed and the pair index), [`sample`] (random contacts with the rejection rule),
//! [`gen`] (parallel, resumable generation), [`npz`] (uncompressed `.npz` files), [`shard`] (the arrays of a shard), [`manifest`] (`manifest.json` and its
//! validation), [`reader`] ([`Dataset`]: random access and shuffled mini-batches), [`import`] and [`resample`] (real
//! sensor data), [`stats`] (summaries for `tnd dataset stats`).

pub mod camera_pass;
pub mod config;
pub mod gen;
pub mod import;
pub mod import_recording;
pub mod manifest;
pub mod npz;
pub mod reader;
/// Native camera frames to the model's resolution (moved to the sensor, which the recording stage shares).
pub use crate::sensor::resample;
pub mod sample;
pub mod sensor_variation;
pub mod shadow_fit;
pub mod shard;
pub mod split;
pub mod stats;

mod error;

pub use config::GenConfig;
pub use error::DatasetError;
pub use gen::{generate, GenReport};
pub use manifest::{DatasetManifest, ShardEntry, FORMAT_VERSION};
pub use reader::{Batch, Batches, Dataset};

use serde::{Deserialize, Serialize};

use crate::image::Image;
use crate::sensor::{Se2, SensorPose};

/// The paper's evaluation splits.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SplitName {
    /// Seen objects, seen poses: training pairs.
    Train,
    /// Seen objects, unseen poses: 1 in 10 of the seen objects' pairs, held out of training.
    UnseenPoses,
    /// Unseen objects, all their poses.
    UnseenObjects,
}

impl SplitName {
    /// All splits in storage order.
    pub const ALL: [SplitName; 3] = [
        SplitName::Train,
        SplitName::UnseenPoses,
        SplitName::UnseenObjects,
    ];

    /// The serialised name (`train`, `unseen_poses`, `unseen_objects`), also the shard file prefix.
    pub fn as_str(self) -> &'static str {
        match self {
            SplitName::Train => "train",
            SplitName::UnseenPoses => "unseen_poses",
            SplitName::UnseenObjects => "unseen_objects",
        }
    }

    /// Position in [`SplitName::ALL`].
    pub fn code(self) -> usize {
        match self {
            SplitName::Train => 0,
            SplitName::UnseenPoses => 1,
            SplitName::UnseenObjects => 2,
        }
    }
}

impl std::fmt::Display for SplitName {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

impl std::str::FromStr for SplitName {
    type Err = crate::error::InvalidSetting;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        crate::error::InvalidSetting::wrap("split", || {
            SplitName::ALL
                .into_iter()
                .find(|x| x.as_str() == s.trim())
                .ok_or_else(|| {
                    format!("unknown split '{s}' (use train, unseen_poses or unseen_objects)")
                })
        })
    }
}

/// Everything known about one pair besides its images.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PairMeta {
    /// Object name (an entry of the dataset's object set).
    pub object: String,
    /// Object pose on the table in the world frame, which is the sensor's `(x, y, yaw = 0)` frame: the sensor axis
    /// passes through world `(0, 0)`. Metres, metres, radians.
    pub object_pose: Se2,
    /// Sensor pose in the world (position metres, yaw/tilt radians). For imported pairs without a press depth the
    /// height `position[2]` is NaN (unknown).
    pub sensor: SensorPose,
    /// Press depth of the membrane apex below the object's top, metres (NaN = unknown, imported data).
    pub press: f64,
    /// The pair seed: with the dataset's configuration it reproduces the pair (see [`split::pair_seed`]); 0 for
    /// imported real pairs.
    pub seed: u64,
    /// The split this pair belongs to.
    pub split: SplitName,
    /// Global pair index (generation order over the whole dataset).
    pub index: usize,
    /// Position of the pair within its split (the `index` argument of [`Dataset::pair`]).
    pub split_index: usize,
    /// Number of pixels in contact (mask sum).
    pub contact_pixels: usize,
}

/// One pair: the model's condition (imprint), its target and the images they came from, all at the dataset
/// resolution, metres (mask 0/1).
#[derive(Clone, Debug, PartialEq)]
pub struct Pair {
    /// Y = R − S: the imprint (model condition), metres.
    pub imprint: Image,
    /// X0 = M ⊙ D: the in-contact depth (model target), metres, 0 outside the contact.
    pub target: Image,
    /// S: the signature (measured depth with the object pressed in), metres.
    pub signature: Image,
    /// R: the reference (depth of the undeformed membrane), metres.
    pub reference: Image,
    /// M: contact mask, 0/1.
    pub mask: Image,
    pub meta: PairMeta,
}
