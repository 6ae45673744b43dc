//! Errors of the dataset stage: every variant names the file and says how to fix the problem.

use std::path::PathBuf;

use crate::objects::ObjectError;
use crate::sim::SimError;

/// Everything that can go wrong generating, importing or reading a dataset.
#[derive(Debug, thiserror::Error)]
pub enum DatasetError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: not a dataset: {message}")]
    NotADataset { path: PathBuf, message: String },
    /// A new dataset's output folder holds a finished one.
    #[error("{path}: holds a finished dataset already ({}); choose a new --out, or delete the folder to make it again", super::manifest::MANIFEST_FILE)]
    Exists { path: PathBuf },
    #[error("{path}: malformed manifest: {message}")]
    Manifest { path: PathBuf, message: String },
    #[error("{path}: unsupported dataset format version {found} (this build reads version {supported}; regenerate the dataset or use a matching tnd)")]
    UnsupportedVersion {
        path: PathBuf,
        found: u32,
        supported: u32,
    },
    #[error("{path}: shard is {found} bytes but the manifest says {expected}: truncated or incomplete (re-run the same `tnd dataset gen` command to resume)")]
    Truncated {
        path: PathBuf,
        found: u64,
        expected: u64,
    },
    #[error("{path}: sha256 {found} does not match the manifest's {expected}: the shard was modified or corrupted (re-run the same `tnd dataset gen` command to regenerate it)")]
    Checksum {
        path: PathBuf,
        found: String,
        expected: String,
    },
    #[error("{path}: array '{array}' has dtype '{found}', expected '{expected}'")]
    Dtype {
        path: PathBuf,
        array: String,
        found: String,
        expected: String,
    },
    #[error("{path}: array '{array}' has shape {found:?}, expected {expected:?}")]
    Shape {
        path: PathBuf,
        array: String,
        found: Vec<usize>,
        expected: Vec<usize>,
    },
    #[error("{path}: not a valid uncompressed .npz shard: {message}")]
    Npz { path: PathBuf, message: String },
    #[error("{path}: {message}")]
    BadValue { path: PathBuf, message: String },
    #[error("{path}: the existing dataset was made with a different configuration ({field} differs: {}); use the same command to resume, or another --out directory", differing.join("; "))]
    ConfigMismatch {
        path: PathBuf,
        field: String,
        /// What differs, `name: then -> now`.
        differing: Vec<String>,
    },
    #[error("split {split} has {len} pairs; index {index} is out of range")]
    IndexOutOfRange {
        split: super::SplitName,
        index: usize,
        len: usize,
    },
    #[error("settings: {0}")]
    Config(String),
    #[error("no object of the set makes a contact of at least {min_pixels} pixels in {attempts} draws of pose and press; lower --min-contact or widen --press")]
    NoPressableObject { min_pixels: usize, attempts: usize },
    #[error("pair {index} (object '{object}'): no contact of at least {min_pixels} pixels in {attempts} draws; lower --min-contact or widen --press")]
    NoContact {
        index: usize,
        object: String,
        min_pixels: usize,
        attempts: usize,
    },
    #[error("{path}: import: {message}")]
    Import { path: PathBuf, message: String },
    #[error(transparent)]
    Recording(#[from] crate::recording::RecordingError),
    #[error("cannot serialise {what}: {source}")]
    Serialize {
        what: &'static str,
        #[source]
        source: serde_json::Error,
    },
    #[error(transparent)]
    Objects(#[from] ObjectError),
    #[error(transparent)]
    Sim(#[from] SimError),
    #[error(transparent)]
    Mesh(#[from] crate::mesh::MeshError),
}

impl DatasetError {
    /// An I/O error on `path`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Self::Io {
            path: path.into(),
            source,
        }
    }
}
